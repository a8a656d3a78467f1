#!/usr/bin/env bash
# Quick start 2: set up (deploy/setup.sh) and run the whole test suite: unit, integration
# (real router and service processes on free ports) and end-to-end (with the simulator).
# Options go to pytest, e.g. ./deploy/test.sh tests/unit -x. Exit status: pytest's; "no tests
# collected" (pytest's 5) is a failure too.
set -euo pipefail
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$REPO/deploy/setup.sh"
cd "$REPO"
export MUJOCO_GL="${MUJOCO_GL:-egl}"
status=0
.venv/bin/python -m pytest -q -p no:cacheprovider -rfEs "$@" || status=$?
if [ "$status" -eq 5 ]; then
    echo "test.sh: pytest collected no tests" >&2
fi
exit "$status"
