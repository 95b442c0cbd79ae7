"""The privileged-track MLP baseline (README.md): train.py, serve.py."""
