#!/usr/bin/env bash
# The virtual environment of the LeRobot path's tests: target/lerobot-venv (or
# $KITCHEN_R_LEROBOT_VENV), made from the machine's python3 (3.11: LeRobot 0.4.4, the newest
# release for it). A venv apart from the test venv (scripts/test-venv.sh): LeRobot 0.4.4 pins
# torch<2.11, datasets<5, huggingface-hub<0.36, av<16 and packaging<26, all below the test venv's
# pins. It installs, at the exact versions of scripts/test-requirements-lerobot-constraints.txt:
# - scripts/test-requirements-lerobot.txt (lerobot 0.4.4 with its torch 2.10 from PyPI, CUDA
#   libraries included, about 5 GB: no CPU-only torch is reachable from a package registry here;
#   gRPC for the serve command; pytest);
# - the starter kit's client and the baselines' package, editable and without dependencies, for
#   kitchen-r-serve-lerobot (starter-kit/baselines/lerobot).
# Nothing is done when the venv was made from the same files (a stamp of their hashes). .ci/run
# calls it in the background while cargo compiles; scripts/test.sh installs gym_kitchen_r and the
# env plugin into it after cargo, then runs the LeRobot tests with it.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV="${KITCHEN_R_LEROBOT_VENV:-target/lerobot-venv}"

if [[ ! -x "$VENV/bin/python" ]]; then
  echo "== LeRobot venv: creating $VENV with $(python3 --version 2>&1)"
  if ! python3 -m venv "$VENV"; then
    rm -rf "$VENV"
    apt-get -o DPkg::Lock::Timeout=600 install -y -qq python3-venv >/dev/null \
      || { echo "python3 -m venv failed; install python3-venv" >&2; exit 1; }
    python3 -m venv "$VENV"
  fi
fi
py="$VENV/bin/python"
inputs=(scripts/test-requirements-lerobot.txt scripts/test-requirements-lerobot-constraints.txt
  starter-kit/pyproject.toml starter-kit/baselines/pyproject.toml)
key="$(cat "${inputs[@]}" | sha256sum | cut -d' ' -f1)"
stamp="$VENV/.kitchen-r-requirements"
if [[ "$(cat "$stamp" 2>/dev/null)" != "$key" ]]; then
  echo "== LeRobot venv: installing scripts/test-requirements-lerobot.txt (pinned: scripts/test-requirements-lerobot-constraints.txt)"
  "$py" -m pip install --quiet --disable-pip-version-check \
    -c scripts/test-requirements-lerobot-constraints.txt -r scripts/test-requirements-lerobot.txt
  "$py" -m pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation \
    -e ./starter-kit -e ./starter-kit/baselines
  echo "$key" > "$stamp"
fi
