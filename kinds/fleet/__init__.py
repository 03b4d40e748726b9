"""The fleet kind: aeossp fleets (kind.py) and the fleet solver, passes coordinated by task prices (config, problem,
pool, prices, coordinator, solve)."""
