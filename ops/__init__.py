"""The operations world of a fleet: ground stations and contacts, clouds and forecasts, requests that arrive during
the day (docs/operations.md)."""
