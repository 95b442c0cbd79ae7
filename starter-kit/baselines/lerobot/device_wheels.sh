#!/usr/bin/env bash
# The wheels LeRobot 0.6.1 needs on the GPU machine (Python 3.12, torch 2.11 preinstalled, no
# network there) for the LeRobot path's real run: lerobot-train (ACT and diffusion) on our export,
# lerobot-eval --env.type=kitchen_r, kitchen-r-serve-lerobot. Run here, from the repository root:
#
#   bash starter-kit/baselines/lerobot/device_wheels.sh [OUT]     # default OUT: target/device/lerobot
#
# It downloads, without dependencies, exactly the packages below: LeRobot 0.6.1 and what its core
# and its `dataset`, `training`, `evaluation` and `diffusion` extras need that the device image does
# not hold (/work/.library/device/KINDS.md, "Python packages already there"), resolved for CPython
# 3.12 on manylinux x86_64 by pip's resolver. Left out on purpose:
# - torch, torchvision, numpy, pandas, pyarrow, huggingface-hub, accelerate, safetensors, pillow,
#   opencv, einops, packaging: the image's. LeRobot 0.6.1 declares numpy<2.3 and pandas<3 while the
#   image has numpy 2.5.2; installed with --no-deps it runs on the image's (if it does not, carry
#   numpy==2.2.6 too);
# - wandb (imported only with --wandb.enable=true) and torchcodec (needs FFmpeg's shared libraries,
#   which the image lacks; pass --dataset.video_backend=pyav, PyAV's wheel brings FFmpeg).
# A call to the machine carries at most 64 MiB with the repository (about 38 MB of it), and PyAV's
# wheel alone is 40 MB: so the wheels are also packed into OUT.part-aa, -ab, ... of 20 MB each.
# Carry one part per call to one warm machine, each call starting with
#   cp target/device/lerobot.part-* /tmp/
# and the last one, when /tmp holds every part, installing them:
#   mkdir -p /tmp/lerobot-wheels && cat /tmp/lerobot.part-* | tar -xf - -C /tmp/lerobot-wheels
#   python3 -m pip install -q --no-index --no-deps --no-compile --target /tmp/site /tmp/lerobot-wheels/*.whl
#   export PYTHONPATH=/tmp/site
# (docs/participant/lerobot.md, "On the GPU machine").
set -euo pipefail
OUT="${1:-target/device/lerobot}"
mkdir -p "$OUT"
PACKAGES=(
  lerobot==0.6.1
  av==15.1.0 datasets==4.8.5 diffusers==0.39.0 dill==0.4.1 draccus==0.11.6 farama-notifications==0.0.6
  gymnasium==1.4.0 importlib-metadata==10.2.0 jsonlines==4.0.0 lazy-importer==0.1.0 mergedeep==1.3.4
  multiprocess==0.70.19 termcolor==3.3.0 toml==0.10.2 tzdata==2026.6
)
platforms=()
for p in manylinux_2_28_x86_64 manylinux_2_27_x86_64 manylinux_2_17_x86_64 manylinux2014_x86_64 manylinux1_x86_64 any; do
  platforms+=(--platform "$p")
done
python3 -m pip download --quiet --disable-pip-version-check --no-deps --only-binary=:all: \
  --python-version 3.12 --implementation cp "${platforms[@]}" -d "$OUT" "${PACKAGES[@]}"
rm -f "$OUT".part-*
tar -cf - -C "$OUT" . | split -b 20m - "$OUT.part-"
echo "$(ls "$OUT"/*.whl | wc -l) wheels, $(du -cb "$OUT"/*.whl | tail -1 | cut -f1) bytes in $OUT;" \
  "to carry: $(ls "$OUT".part-* | tr '\n' ' ')"
