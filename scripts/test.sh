#!/usr/bin/env bash
# The one test command (README): every unit, property and end-to-end test of the workspace.
# It does its own set-up on a fresh machine: every Python test runs in the virtual environment
# scripts/test-venv.sh makes (target/test-venv, packages at the exact versions of
# scripts/test-constraints.txt: the Python readers some end-to-end tests use, grpcio, torch, the
# starter kit's client and baselines), whose bin/ comes first on PATH here, so the end-to-end
# tests' `python3` is the venv's, not whatever python3 the machine has.
set -euo pipefail
cd "$(dirname "$0")/.."
# Each section's header says how long the tests have taken so far.
section() { echo "== $* [$((SECONDS / 60))m$((SECONDS % 60))s]"; }
section "the Python test venv (scripts/test-venv.sh)"
bash scripts/test-venv.sh
VENV="${KITCHEN_R_TEST_VENV:-target/test-venv}"
VIRTUAL_ENV="$(cd "$VENV" && pwd)"
export VIRTUAL_ENV PATH="$VIRTUAL_ENV/bin:$PATH"
hash -r
echo "python3: $(command -v python3) ($(python3 --version 2>&1))"
# LeRobot 0.4.4 is in the test venv (scripts/test-requirements-lerobot.txt), or with torch in
# KITCHEN_R_TORCH_PYTHON's Python when that is set: the LeRobot path's section below runs with it,
# and the export's test (worker/tests/it/lerobot_export.rs) loads the export with LeRobotDataset
# through KITCHEN_R_LEROBOT_PYTHON.
KITCHEN_R_LEROBOT_PYTHON="${KITCHEN_R_TORCH_PYTHON:-$VIRTUAL_ENV/bin/python}"
export KITCHEN_R_LEROBOT_PYTHON
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
# robosuite 1.5.2's robot descriptions (the robosuite arms' tests, docs/twin/robot.md): the PyPI
# wheel unpacked under target/robosuite, never into the repository.
section "robosuite's robot descriptions (scripts/robosuite-assets.sh)"
ROBOSUITE_ASSETS="$(bash scripts/robosuite-assets.sh)"
export ROBOSUITE_ASSETS
# rav1e's assembly (AV1 encoding 2.3x faster, identical bytes) where nasm is installed:
# optional and detected, so a machine with only the Rust toolchain runs the same tests.
features=()
if command -v nasm >/dev/null 2>&1; then
  features=(--features kitchen-r/asm)
fi
section "cargo test --workspace"
cargo test --workspace --locked "${features[@]}" "$@"
# The Python package (python/, docs/participant/python.md): built from source with cargo through maturin, then its
# tests, which compare the expert stepped from Python with the binary the Rust tests just built.
section "the Python package: pip install ./python, then python/tests"
# Built in the dev profile (dependencies optimised, as the tests above): it reuses what
# `cargo test` just compiled instead of building every dependency again for release, minutes
# on a fresh machine. A user's `pip install ./python` builds for release.
MATURIN_PEP517_ARGS="--profile dev" \
  python3 -m pip install --quiet --disable-pip-version-check --no-build-isolation -c scripts/test-constraints.txt ./python
KITCHEN_R_BIN=target/debug/kitchen-r python3 -m pytest -q python/tests
# The LeRobot env plugin (python/lerobot_env_kitchen_r, docs/participant/lerobot.md): pure Python, installed
# offline over the package just built; with LeRobot 0.4.4 in the test venv its tests marked
# `lerobot` run here too (without it, as with KITCHEN_R_TORCH_PYTHON, they are skipped here and run
# with that Python below).
section "the LeRobot env plugin: pip install ./python/lerobot_env_kitchen_r, then its tests"
python3 -m pip install --quiet --disable-pip-version-check --no-build-isolation --no-deps \
  ./python/lerobot_env_kitchen_r
python3 -m pytest -q python/lerobot_env_kitchen_r/tests
# The LeRobot path (docs/participant/lerobot.md) with LeRobot 0.4.4, tiny and on the CPU: our
# export -> lerobot-train (ACT and diffusion, 3 steps) -> kitchen-r-serve-lerobot -> check-policy,
# and lerobot-eval --env.type=kitchen_r for one short episode (starter-kit/baselines/lerobot/tests). In the test
# venv gym_kitchen_r and the plugin are installed above; another Python (KITCHEN_R_TORCH_PYTHON)
# gets them as a wheel of the build above (cargo has nothing left to compile), then runs the
# plugin's tests marked `lerobot`.
section "the LeRobot path: the env plugin and starter-kit/baselines/lerobot/tests with LeRobot 0.4.4"
if [[ "$KITCHEN_R_LEROBOT_PYTHON" != "$VIRTUAL_ENV/bin/python" ]]; then
  rm -rf target/lerobot-wheels
  MATURIN_PEP517_ARGS="--profile dev" \
    python3 -m pip wheel --quiet --disable-pip-version-check --no-deps --no-build-isolation -w target/lerobot-wheels ./python
  "$KITCHEN_R_LEROBOT_PYTHON" -m pip install --quiet --disable-pip-version-check --no-deps --force-reinstall \
    target/lerobot-wheels/gym_kitchen_r-*.whl
  "$KITCHEN_R_LEROBOT_PYTHON" -m pip install --quiet --disable-pip-version-check --no-build-isolation --no-deps \
    ./python/lerobot_env_kitchen_r
  KITCHEN_R_BIN=target/debug/kitchen-r "$KITCHEN_R_LEROBOT_PYTHON" -m pytest -q -m lerobot python/lerobot_env_kitchen_r/tests
fi
KITCHEN_R_BIN=target/debug/kitchen-r "$KITCHEN_R_LEROBOT_PYTHON" -m pytest -q starter-kit/baselines/lerobot/tests
# The control baselines trained from live simulators (docs/measured/baseline-gates.md): a few CPU training steps on
# streamed expert samples each; the privileged checkpoint reloads, serves over gRPC and passes
# check-policy; training and serving compute the same features.
# The planner's and the diffusion policy's own tests run inside cargo's (tests/e2e/baseline_*.rs).
section "the control baselines: starter-kit/baselines/{privileged,camera}/tests"
# One process each, so that each baseline's time shows on a line of its own.
for b in privileged camera; do
  KITCHEN_R_BIN=target/debug/kitchen-r python3 -m pytest -q "starter-kit/baselines/$b/tests"
done
section "all tests passed"
