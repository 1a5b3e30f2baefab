#!/usr/bin/env python3
"""Checks that building any one package asks for the same features as the workspace's test build.

cargo compiles a crate once per feature set. When `maturin develop` (the Python module) or
`cargo build -p fairgrasp-cli` resolves a third-party crate with fewer features than
`cargo test --workspace` did (features that dev-dependencies or another package switch on), it
compiles that crate again, and every crate above it: the suite built the dependency tree twice.
The package crates/workspace-hack (written by `cargo hakari generate`) pins the union; this check
fails when a new dependency or feature breaks it, and says which crates differ.

    python3 scripts/check_features.py
"""

import json
import subprocess
import sys


def resolved(*args):
    """{package with version: its features} as `cargo tree` resolves them for these arguments."""
    done = subprocess.run(
        ["cargo", "tree", "--locked", "--prefix", "none", "--format", "{p}|{f}", *args],
        capture_output=True, text=True,
    )
    if done.returncode != 0:
        sys.exit(f"check_features: cargo tree {' '.join(args)} failed:\n{done.stderr}")
    out = done.stdout
    seen = {}
    for line in out.splitlines():
        line = line.replace(" (*)", "").replace(" (proc-macro)", "").strip()
        if "|" in line:
            package, features = line.rsplit("|", 1)
            seen.setdefault(package, set()).add(features)
    return seen


def main():
    metadata = json.loads(subprocess.run(
        ["cargo", "metadata", "--locked", "--format-version", "1", "--no-deps"],
        check=True, capture_output=True, text=True,
    ).stdout)
    workspace = resolved("--workspace", "-e", "normal,build,dev")
    failures = []
    for package in metadata["packages"]:
        alone = resolved("-p", package["name"], "-e", "normal,build")
        for crate, feature_sets in sorted(alone.items()):
            missing = feature_sets - workspace.get(crate, set())
            for features in sorted(missing):
                failures.append(f"{package['name']}: {crate} with [{features}], "
                                f"the workspace build has {sorted(workspace.get(crate, []))}")
    if failures:
        print("check_features: building these packages alone would compile crates again:")
        print("\n".join("  " + f for f in failures))
        print("Run `cargo hakari generate && cargo hakari manage-deps` (cargo install cargo-hakari).")
        return 1
    print(f"check_features: {len(metadata['packages'])} packages resolve as the workspace does")
    return 0


if __name__ == "__main__":
    sys.exit(main())
