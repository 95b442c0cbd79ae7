"""The Kitchen-R baselines (`pip install -e ./starter-kit -e ./starter-kit/baselines[control]`).

- `planner`: the planning baseline (standard library only), `kitchen-r-plan`;
- `privileged`: an MLP on the privileged track's observation, `kitchen-r-train-privileged`,
  `kitchen-r-serve-privileged`;
- `camera`: both cameras through a pretrained EfficientNet-Lite0 on the standard track,
  `kitchen-r-train-camera`, `kitchen-r-serve-camera`, `kitchen-r-diagnose-camera`;
- `diffusion_policy`: the paper's diffusion-policy controller trained on a LeRobot export,
  `kitchen-r-train-diffusion`, `kitchen-r-serve-diffusion`, `kitchen-r-profile-diffusion`;
- `gate`: the learnability gates of any served policy, `kitchen-r-gate`.

Written once for all of them: `common` (the task clock, SR per kind, instruction ranges),
`observation` (a gRPC observation's frames and images as arrays), `batching` (concurrent Act
calls through a network in one batch) and `serving` (a checkpoint's serve command).
"""
