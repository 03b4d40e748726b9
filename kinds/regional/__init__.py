"""The regional_coverage kind: strips over polygons, solved as budgeted maximum coverage (see kind.py)."""
