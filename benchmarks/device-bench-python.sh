#!/usr/bin/env bash
# The Python package's figures on the GPU machine (16 cores): streamed expert samples against
# `collect --format lerobot`, and env steps/s against the Rust runner (one env, a vector env of
# 2 and of one per core). Nothing there is fetched: the package and gymnasium travel as wheels.
#
# Here:   mkdir -p target/device/wheels
#         python3 -m maturin build --release --strip -m python/Cargo.toml -o target/device/wheels
#         pip download --python-version 3.12 --only-binary=:all: --no-deps -d target/device/wheels \
#             gymnasium cloudpickle farama-notifications typing-extensions
#         strip -o /tmp/kitchen-r target/release/kitchen-r && xz -c /tmp/kitchen-r > target/device/kitchen-r.xz
# There:  bash benchmarks/device-bench-python.sh      (figures in $OUT, or /tmp/kr-bench)
set -euo pipefail
OUT="${OUT:-/tmp/kr-bench}"
mkdir -p "$OUT"
python3 -m pip install --quiet --no-index --find-links target/device/wheels gym-kitchen-r
python3 -c "import lzma, shutil; shutil.copyfileobj(lzma.open('target/device/kitchen-r.xz'), open('/tmp/kitchen-r', 'wb'))"
chmod +x /tmp/kitchen-r
export KITCHEN_R_ASSETS="$PWD/assets" KITCHEN_R_CONFIGS="$PWD/configs" RUST_LOG=warn
CORES="$(nproc)"
echo "== $CORES cores; $(python3 --version)"
[ "${SAMPLES:-1}" = 0 ] || python3 benchmarks/bench_samples.py --episodes "${SAMPLE_EPISODES:-480}" --workers "$CORES" \
  --collect "${COLLECT_EPISODES:-64}" --bin /tmp/kitchen-r --json "$OUT/samples.json" | tee "$OUT/samples.txt"
python3 benchmarks/bench_python_env.py --episodes 6 --envs 2 --repeat "${REPEAT:-5}" --bin /tmp/kitchen-r | tee "$OUT/env_2.txt"
python3 benchmarks/bench_python_env.py --episodes 6 --envs "$CORES" --bin /tmp/kitchen-r | tee "$OUT/env_$CORES.txt"
