#!/usr/bin/env python3
"""The workspace's declared `rust-version` (Cargo.toml) against what Cargo.lock pins: every
locked dependency that declares a rust-version must declare one no newer than ours, or a user
on our oldest supported Rust could not build the lock we ship. It reads `cargo metadata`
(nothing is compiled). Our own code's use of newer standard-library APIs is caught by clippy's
`incompatible_msrv` lint (on by default) in CI's lint build, which reads the same rust-version.

    python3 scripts/check-msrv.py
"""

from __future__ import annotations

import json
import subprocess
import sys


def version(v: str) -> tuple[int, ...]:
    """ "1.94" and "1.94.0" are the same version."""
    parts = [int(x) for x in v.split(".")]
    return tuple(parts + [0] * (3 - len(parts)))


def main() -> int:
    meta = json.loads(
        subprocess.run(
            ["cargo", "metadata", "--format-version", "1", "--locked"],
            check=True,
            capture_output=True,
            text=True,
        ).stdout
    )
    ids = set(meta["workspace_members"])
    ours = {p["rust_version"] for p in meta["packages"] if p["id"] in ids}
    if len(ours) != 1 or None in ours:
        print(f"every workspace crate must take rust-version from the workspace; found {sorted(map(str, ours))}")
        return 1
    msrv = ours.pop()
    # Only what a build for Linux can pull in: the resolve's nodes (every target, so a superset).
    used = {n["id"] for n in meta["resolve"]["nodes"]}
    newer = sorted(
        f"{p['name']} {p['version']} needs Rust {p['rust_version']}"
        for p in meta["packages"]
        if p["id"] in used
        and p["id"] not in ids
        and p.get("rust_version")
        and version(p["rust_version"]) > version(msrv)
    )
    if newer:
        print(f"Cargo.lock pins crates newer than the declared rust-version {msrv}:")
        for line in newer:
            print(f"  {line}")
        print(
            "raise rust-version in Cargo.toml (and docs/contributing.md), or pin older versions (cargo update -p NAME --precise V)"
        )
        return 1
    deps = len(used - ids)
    print(f"rust-version {msrv}: every one of the {deps} locked dependencies declares it or older (or none)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
