"""The diffusion-policy control baseline (README.md): train.py, serve.py, profile_train.py."""
