"""The detector's compiled functions: ``compiled`` marks a function for numba to compile.

Used where a stage's time was numpy's overhead per call, not the work: the outline search and
the circle fits run dozens of small array operations per ball on a few dozen to a few hundred
values (a ball's outline took ~1.4 ms in ~150 numpy calls on a 2-core machine; compiled
loops do the same in a few tens of microseconds).

Compiled code is cached on disk beside the sources (``__pycache__``; numba falls back to a
per-user cache when that is not writable). Compiling all of them takes 10-40 s on this project's
2-core machines, loading them from the cache ~0.3 s: ``detector.compile_kernels`` does it
before a service's first frame, and ``deploy/setup.sh`` once per install.
"""

import numba

compiled = numba.njit(cache=True)
