"""The detector's compiled functions: ``compiled`` marks a function for numba to compile.

Used where a stage's time was numpy's overhead per call, not the work: the outline search and
the circle fits run dozens of small array operations per ball on a few dozen to a few hundred
values (a ball's outline took ~1.4 ms in ~150 numpy calls on a 2-core machine; compiled
loops do the same in a few tens of microseconds); a candidate's measurements read its rim,
disc and ring in one pass each instead of a dozen calls; a blob outline's concave points
(its convex hull and the hull's defects) come from one loop instead of three OpenCV calls and
the numpy between them, and a circle's rim edges on the frame (a ball in front of another)
from one loop instead of ~45 numpy calls; and a dark frame's clipping pixels are scaled one by
one instead of through numpy's indexing of a large share of the frame.

Each replaces numpy or OpenCV calls to the bit: integer counts and sums, the same float32 or
float64 operations in the same order (numpy's reductions, whose summation order a loop would
not follow, stay in numpy). One choice OpenCV leaves open is fixed instead: which of two visits
of one pixel by an outline is its convex hull's vertex (see ``arcs.convexity_cut``). Arrays are
passed contiguous, so that each function has one compiled signature that ``compile_kernels``
makes before the first frame.

Compiled code is cached on disk beside the sources (``__pycache__``; numba falls back to a
per-user cache when that is not writable). Compiling all of them takes 10-40 s on this project's
2-core machines, loading them from the cache ~0.3 s: ``detector.compile_kernels`` does it
before a service's first frame, and ``deploy/setup.sh`` once per install.
"""

import numba

compiled = numba.njit(cache=True)
