"""Serving LeRobot checkpoints over the Kitchen-R contract (serve.py, features.py)."""
