#!/usr/bin/env bash
# Set up balltrack on this machine; safe to run again (quiet when everything is there).
#
#   1. the Debian packages MuJoCo's EGL renderer needs (libegl1 libgl1 libegl-mesa0
#      libgl1-mesa-dri), iproute2 (network namespaces for the multi-host tests) and chromium
#      (headless, the Rerun viewer's screenshot test), installed
#      with apt-get only when missing (sudo when not root);
#   2. a virtual environment .venv at the repository root (Python >= 3.11);
#   3. pip install -e '.[test,train]' into it (train: torch's CPU build, for the learned
#      detector's training and its tests), again only when pyproject.toml changed since the last
#      install or a dependency cannot be found;
#   4. the detector's compiled functions compiled into numba's cache (services/detector/jit.py).
#
# Environment: PYTHON=/path/to/python3.11 chooses the interpreter for a new .venv.
set -euo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$REPO"
say() { echo "setup: $*" >&2; }

as_root() {
    if [ "$(id -u)" -eq 0 ]; then "$@"; elif command -v sudo >/dev/null 2>&1; then sudo "$@"; else
        say "need root for: $*"; return 1; fi
}

# -- 1. system packages --------------------------------------------------------------------
# iproute2: the multi-host tests make network namespaces with `ip netns`.
# chromium: the Rerun viewer's test opens its web page headless and takes a screenshot.
PACKAGES=(libegl1 libgl1 libegl-mesa0 libgl1-mesa-dri iproute2 chromium)
if command -v dpkg >/dev/null 2>&1; then
    missing=()
    for package in "${PACKAGES[@]}"; do
        dpkg -s "$package" >/dev/null 2>&1 || missing+=("$package")
    done
    if [ "${#missing[@]}" -gt 0 ]; then
        say "installing ${missing[*]}"
        as_root apt-get update -qq
        as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
    fi
elif ! ldconfig -p 2>/dev/null | grep -q 'libEGL\.so'; then
    say "warning: not a Debian system and no libEGL found; install EGL/OpenGL (Mesa) for MuJoCo's renderer"
fi

# -- 2. the virtual environment ------------------------------------------------------------
python_ok() { "$1" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; }
if [ ! -x .venv/bin/python ] || ! python_ok .venv/bin/python; then
    interpreter=""
    for candidate in ${PYTHON:-} python3 python3.13 python3.12 python3.11; do
        if command -v "$candidate" >/dev/null 2>&1 && python_ok "$candidate"; then
            interpreter="$candidate"; break
        fi
    done
    if [ -z "$interpreter" ]; then
        say "Python >= 3.11 is needed (set PYTHON=/path/to/python3.11)"; exit 1
    fi
    say "creating .venv with $("$interpreter" --version 2>&1)"
    rm -rf .venv
    if ! "$interpreter" -m venv .venv 2>/dev/null; then
        # Debian/Ubuntu ship venv separately.
        if command -v dpkg >/dev/null 2>&1; then
            version="$("$interpreter" -c 'import sys; print(f"{sys.version_info[0]}.{sys.version_info[1]}")')"
            say "installing python${version}-venv"
            as_root apt-get update -qq
            as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "python${version}-venv" >/dev/null \
                || as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq python3-venv >/dev/null
            rm -rf .venv
            "$interpreter" -m venv .venv
        else
            say "cannot create a virtual environment with $interpreter"; exit 1
        fi
    fi
fi

# -- 3. the package and its dependencies -----------------------------------------------------
STAMP=.venv/.balltrack-install
wanted="$(sha256sum pyproject.toml | cut -d' ' -f1) $REPO"
installed="$(cat "$STAMP" 2>/dev/null || true)"
importable() {
    .venv/bin/python - <<'PY' 2>/dev/null
import importlib.util, sys
modules = ("zenoh", "cv2", "numpy", "numba", "msgpack", "mujoco", "matplotlib", "tqdm", "pytest", "torch", "onnx", "onnxruntime",
           "pytest_timeout", "xdist", "hypothesis", "importlinter", "balltrack.common", "balltrack.services", "balltrack.deploy")
sys.exit(any(importlib.util.find_spec(name) is None for name in modules))
PY
}
if [ "$installed" != "$wanted" ] || ! importable; then
    say "installing balltrack and its dependencies into .venv (pip install -e '.[test,train]')"
    .venv/bin/python -m pip install -q --disable-pip-version-check -e '.[test,train]'
    echo "$wanted" > "$STAMP"
fi

# -- 4. the detector's compiled functions ----------------------------------------------------
# Compiled here (10-40 s) so that neither a service's first frame nor a test waits for numba;
# from numba's cache beside the sources (after the first run) this takes about a second.
.venv/bin/python - <<'PY'
import sys
from balltrack.services.detector.detector import compile_kernels
seconds = compile_kernels()
if seconds > 3:
    print(f"setup: compiled the detector's kernels in {seconds:.0f} s", file=sys.stderr)
PY
