"""The EOS-Bench kind (kind.py): its pass problems, price coordination and bound (solve.py)."""
