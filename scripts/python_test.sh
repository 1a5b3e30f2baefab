#!/usr/bin/env bash
# The Python suite: builds the `fairgrasp` package (PyO3, through maturin) into a virtual
# environment, then runs python/tests with pytest, which includes the smoke runs of
# examples/train_sb3.py and examples/ray_tune_sweep.py.
#
#   scripts/python_test.sh [pytest arguments]
#
# The venv is python/.venv (or $FAIRGRASP_VENV); it is created and filled from
# python/requirements-test.txt on first use (a few GB: torch and ray), and the module is rebuilt
# each run (an incremental cargo build). The tests compare against the `fairgrasp` binary
# (target/debug/fairgrasp, built here if missing).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
VENV=${FAIRGRASP_VENV:-$ROOT/python/.venv}
TARGET=${CARGO_TARGET_DIR:-$ROOT/target}

if [[ ! -x $VENV/bin/python ]]; then
    echo "python_test: creating $VENV"
    python3 -m venv "$VENV"
fi
REQUIREMENTS=python/requirements-test.txt
STAMP=$VENV/.requirements-installed
if [[ ! -f $STAMP ]] || ! cmp -s "$REQUIREMENTS" "$STAMP"; then
    echo "python_test: installing $REQUIREMENTS"
    "$VENV/bin/pip" install --quiet --disable-pip-version-check -r "$REQUIREMENTS"
    cp "$REQUIREMENTS" "$STAMP"
fi

echo "python_test: building the fairgrasp module (maturin develop)"
(cd python && VIRTUAL_ENV=$VENV PATH="$VENV/bin:$PATH" "$VENV/bin/maturin" develop --quiet --locked)
if [[ ! -x $TARGET/debug/fairgrasp ]]; then
    cargo build --locked --bin fairgrasp
fi

export FAIRGRASP_BIN=$TARGET/debug/fairgrasp
# Ray: no dashboard, no usage report, and its temporary files under the target directory.
export RAY_USAGE_STATS_ENABLED=0 RAY_DISABLE_DOCKER_CPU_WARNING=1
cd python
exec "$VENV/bin/python" -m pytest -p no:cacheprovider "$@"
