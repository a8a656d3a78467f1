#!/usr/bin/env bash
# Quick start 2: set up (deploy/setup.sh) and run the whole test suite: unit, integration
# (real router and service processes on free ports) and end-to-end (with the simulator).
# Options go to pytest, e.g. ./deploy/test.sh tests/unit -x. Exit status: pytest's; "no tests
# collected" (pytest's 5) is a failure too.
#
# ./deploy/test.sh --quick: the tier for daily work, the tests not marked slow (it leaves out the
# end-to-end runs with the simulator and a few long runs that the whole suite, CI's, keeps) in two
# worker processes (pytest-xdist), each taking whole test files so that a module's fixtures are
# made once; its integration tests still start real routers and services. More options follow it.
set -euo pipefail
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$REPO/deploy/setup.sh"
cd "$REPO"
export MUJOCO_GL="${MUJOCO_GL:-egl}"
arguments=("$@")
if [ "${1:-}" = "--quick" ]; then
    arguments=(-m "not slow" -n 2 --dist loadfile "${@:2}")
fi
status=0
.venv/bin/python -m pytest -q -p no:cacheprovider -rfEs "${arguments[@]}" || status=$?
if [ "$status" -eq 5 ]; then
    echo "test.sh: pytest collected no tests" >&2
fi
exit "$status"
