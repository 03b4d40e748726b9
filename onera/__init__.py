"""The ONERA constellation benchmark as data: its model, .pb reader and files (model.py), its checker (check.py)."""
