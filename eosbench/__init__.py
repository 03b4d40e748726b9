"""EOS-Bench scenarios as data: their model (model.py), streaming reader (read.py), schedules (schedules.py),
transition models (transition.py) and checker (check.py)."""
