"""The standard-track camera baseline (README.md): train.py, serve.py, diagnose.py."""
