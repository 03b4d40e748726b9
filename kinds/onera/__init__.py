"""The ONERA kind (kind.py): its greedy and large-neighbourhood search (search.py), its LP bound (bound.py)."""
