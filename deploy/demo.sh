#!/usr/bin/env bash
# Quick start 1: set up (deploy/setup.sh) and run the demo: a router, the simulator, the
# detector, the locator and the follower; the robot chases a tennis ball; a summary, a video
# and figures land in runs/demo-<time>/. Options go to the demo, e.g. --time-limit 90.
# Exit status 0 when the robot reached the ball.
set -euo pipefail
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$REPO/deploy/setup.sh"
cd "$REPO"
export MUJOCO_GL="${MUJOCO_GL:-egl}"
exec .venv/bin/python -m balltrack.deploy.demo "$@"
