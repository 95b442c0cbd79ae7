#!/usr/bin/env bash
# Fetch robosuite 1.5.2's robot, gripper and object descriptions for the tests and for
# `kitchen-r eval --robot configs/robots/robosuite/*.toml` (docs/twin/robot.md): the PyPI wheel is
# downloaded with pip (no dependencies, nothing installed) and unpacked under target/robosuite,
# never into the repository. Prints the directory to export as ROBOSUITE_ASSETS:
#
#   export ROBOSUITE_ASSETS="$(scripts/robosuite-assets.sh)"
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
dir="$root/target/robosuite"
assets="$dir/robosuite/models/assets"
if [ ! -f "$assets/robots/panda/robot.xml" ]; then
    mkdir -p "$dir"
    python3 -m pip download --quiet --no-deps robosuite==1.5.2 -d "$dir/wheel" >&2
    python3 - "$dir" <<'PY'
import pathlib, sys, zipfile
dest = pathlib.Path(sys.argv[1])
wheel = next((dest / "wheel").glob("robosuite-1.5.2-*.whl"))
with zipfile.ZipFile(wheel) as z:
    for name in z.namelist():
        if name.startswith("robosuite/models/assets/") and "/textures/" not in name:
            z.extract(name, dest)
PY
fi
echo "$assets"
