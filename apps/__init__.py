"""The applications on top of softjoint: the report (``python -m apps.report``) and the
demo (``python -m apps.demo``). The only layer that may import every package:
apps -> predictor -> surrogate -> workflow -> fem, all on the contract floor
(tests/test_layers.py)."""
