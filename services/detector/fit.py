"""Circle fitting: least-squares circles through points, robust to points of other edges.

``refine_on_boundary`` is step 6's refinement of a proposal on the colour mask's boundary
pixels; ``robust_circle`` is the crescent's fit (``highlight.py``) and, as its compiled rounds
``robust_rounds``, the outline search's (``outline.py``).

The fits are compiled (see ``jit.py``): each runs in rounds over a few dozen to a few hundred
points, several times per ball, where numpy's overhead per call was most of their time
(~0.12 ms per outline fit in numpy on this project's machines, ~0.02 ms compiled).
"""

import math

import numpy as np

from balltrack.services.detector.geometry import Candidate
from balltrack.services.detector.jit import compiled

# Circle refinement: (tolerance over radius, tolerance floor in pixels) of each fitting round.
REFINE_ROUNDS = ((0.35, 2.0), (0.2, 1.5), (0.12, 1.2))


@compiled
def solve_symmetric(m00, m01, m02, m11, m12, m22, t0, t1, t2):
    """The solution (ok, a, b, c) of the symmetric 3x3 system (m00 m01 m02; m01 m11 m12;
    m02 m12 m22) (a b c) = (t0 t1 t2) by Cramer's rule; ok False when it is singular."""
    c00, c01, c02 = m11 * m22 - m12 * m12, m02 * m12 - m01 * m22, m01 * m12 - m02 * m11
    determinant = m00 * c00 + m01 * c01 + m02 * c02
    if abs(determinant) < 1e-9:
        return False, 0.0, 0.0, 0.0
    c11, c12, c22 = m00 * m22 - m02 * m02, m01 * m02 - m00 * m12, m00 * m11 - m01 * m01
    return (True, (c00 * t0 + c01 * t1 + c02 * t2) / determinant,
            (c01 * t0 + c11 * t1 + c12 * t2) / determinant,
            (c02 * t0 + c12 * t1 + c22 * t2) / determinant)


@compiled
def least_squares(first, second, target, keep):
    """The least-squares (a, b, c) of target = a first + b second + c over the points where
    ``keep``, from its normal equations: (ok, a, b, c), ok False when they are singular."""
    m00 = m01 = m02 = m11 = m12 = m22 = t0 = t1 = t2 = 0.0
    for i in range(first.size):
        if keep[i]:
            u, v, w = first[i], second[i], target[i]
            m00 += u * u
            m01 += u * v
            m02 += u
            m11 += v * v
            m12 += v
            m22 += 1.0
            t0 += u * w
            t1 += v * w
            t2 += w
    return solve_symmetric(m00, m01, m02, m11, m12, m22, t0, t1, t2)


@compiled
def kasa(dx, dy, keep):
    """Algebraic (Kasa) least-squares circle through the points (``dx``, ``dy``) where
    ``keep``: (ok, centre x, centre y, radius), the centre relative to the points' origin.
    A Kasa circle is the same from any origin, so rounds of a fit select points by ``keep``
    instead of moving them to each round's centre."""
    # dx^2 + dy^2 = a dx + b dy + c  ->  centre (a/2, b/2), radius^2 = c + (a^2 + b^2) / 4
    ok, a, b, c = least_squares(dx, dy, dx * dx + dy * dy, keep)
    if not ok:
        return False, 0.0, 0.0, 0.0
    centre_x, centre_y = a / 2.0, b / 2.0
    radius_squared = c + centre_x * centre_x + centre_y * centre_y
    if not math.isfinite(radius_squared) or radius_squared <= 0:
        return False, 0.0, 0.0, 0.0
    return True, centre_x, centre_y, math.sqrt(radius_squared)


@compiled
def geometric_steps(px, py, keep, x, y, radius, iterations):
    """Gauss-Newton refinement of a circle on the geometric distances to it of the points
    where ``keep``."""
    for _ in range(iterations):
        # the least-squares step of the Jacobian (-ux, -uy, -1) against the residuals
        dx, dy = px - x, py - y
        distance = np.maximum(np.hypot(dx, dy), 1e-9)
        ok, shift_x, shift_y, growth = least_squares(dx / distance, dy / distance, distance - radius,
                                                     keep)
        if not (ok and math.isfinite(shift_x) and math.isfinite(shift_y) and math.isfinite(growth)):
            break
        x, y, radius = x + shift_x, y + shift_y, radius + growth
        if abs(shift_x) + abs(shift_y) + abs(growth) < 1e-3:
            break
    return x, y, radius


@compiled
def robust_rounds(px, py, x, y, radius, rounds, geometric):
    """robust_circle's rounds (``rounds``: rows of tolerance over radius, floor in px):
    (ok, x, y, radius, which points lie on the circle)."""
    count = px.size
    dx, dy = px - x, py - y
    keep = np.zeros(count, np.bool_)
    centre_x = centre_y = 0.0
    for round_index in range(rounds.shape[0]):
        tolerance = max(rounds[round_index, 1], rounds[round_index, 0] * radius)
        kept = 0
        for i in range(count):
            keep[i] = abs(math.hypot(dx[i] - centre_x, dy[i] - centre_y) - radius) < tolerance
            kept += keep[i]
        if kept < 8:
            return False, x, y, radius, keep
        ok, centre_x, centre_y, radius = kasa(dx, dy, keep)
        if not ok:
            return False, x, y, radius, keep
    x, y = x + centre_x, y + centre_y
    if geometric:
        x, y, radius = geometric_steps(px, py, keep, x, y, radius, 3)
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(radius) and radius > 0):
            return False, x, y, radius, keep
    last = rounds.shape[0] - 1
    tolerance = max(rounds[last, 1], rounds[last, 0] * radius)
    on_circle = np.empty(count, np.bool_)
    for i in range(count):
        on_circle[i] = abs(math.hypot(px[i] - x, py[i] - y) - radius) < tolerance
    return True, x, y, radius, on_circle


def robust_circle(px: np.ndarray, py: np.ndarray, x: float, y: float, radius: float,
                  rounds: tuple, geometric: bool) -> tuple[float, float, float, np.ndarray] | None:
    """Circle through the points near (x, y, radius), in rounds of ever tighter tolerance
    (algebraic fits, then optionally a geometric one); also returns which points lie on it.

    ``rounds``: (tolerance over radius, tolerance floor in pixels) per round. None when fewer
    than 8 points are within a round's tolerance or a fit is degenerate.
    """
    ok, x, y, radius, on_circle = robust_rounds(
        np.asarray(px, np.float64), np.asarray(py, np.float64), float(x), float(y), float(radius),
        np.array(rounds, np.float64).reshape(-1, 2), bool(geometric))
    return (x, y, radius, on_circle) if ok else None


@compiled
def refine_rounds(xs, ys, radius, rounds):
    """refine_on_boundary's rounds on the pixels (``xs``, ``ys``, relative to the proposal's
    centre): (ok, centre x, centre y, radius)."""
    count = xs.size
    near = np.zeros(count, np.bool_)
    centre_x = centre_y = 0.0
    for round_index in range(rounds.shape[0]):
        tolerance_ratio = rounds[round_index, 0]
        tolerance = max(rounds[round_index, 1], tolerance_ratio * radius)
        inner, outer = max(0.0, radius - tolerance) ** 2, (radius + tolerance) ** 2
        kept = 0
        for i in range(count):
            dx, dy = xs[i] - centre_x, ys[i] - centre_y
            squared = dx * dx + dy * dy
            near[i] = inner < squared < outer
            kept += near[i]
        if kept < 6:
            return False, 0.0, 0.0, 0.0
        ok, new_x, new_y, new_radius = kasa(xs, ys, near)
        if not ok or not (0.6 * radius <= new_radius <= 1.6 * radius):
            return False, 0.0, 0.0, 0.0
        moved = abs(new_x - centre_x) + abs(new_y - centre_y) + abs(new_radius - radius)
        centre_x, centre_y, radius = new_x, new_y, new_radius
        if moved < 0.05 and tolerance_ratio <= rounds[1, 0]:
            break  # converged
    return True, centre_x, centre_y, radius


_REFINE_TABLE = np.array(REFINE_ROUNDS, np.float64)


def refine_on_boundary(proposal: Candidate, boundary_x: np.ndarray,
                       boundary_y: np.ndarray) -> Candidate | None:
    """Fit a circle to the mask boundary pixels near the proposal, in rounds that keep only
    the pixels ever closer to the current circle (robust to other edges nearby).

    ``boundary_x``/``boundary_y``: the mask's boundary pixels sorted by row. None when too few
    pixels lie near the circle or the fit moves the radius out of 0.6-1.6 times its own.
    """
    x, y, radius = proposal.x, proposal.y, proposal.radius
    reach = 1.6 * radius + 3
    # The boundary pixels are sorted by row: the rows in reach are one slice.
    first, last = np.searchsorted(boundary_y, (y - reach, y + reach))
    xs, ys = boundary_x[first:last], boundary_y[first:last]
    near_columns = (xs > x - reach) & (xs < x + reach)
    if np.count_nonzero(near_columns) < 6:
        return None
    # (relative to the proposal's centre; the boundary's float64 stays float64)
    ok, centre_x, centre_y, radius = refine_rounds(xs[near_columns] - x, ys[near_columns] - y,
                                                   float(radius), _REFINE_TABLE)
    if not ok:
        return None
    # Boundary pixels are the mask's outermost pixels, half a pixel inside its true edge.
    return Candidate(x + centre_x, y + centre_y, radius + 0.5)
