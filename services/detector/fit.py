"""Circle fitting: least-squares circles through points, robust to points of other edges.

``refine_on_boundary`` is step 6's refinement of a proposal on the colour mask's boundary
pixels; ``robust_circle`` is the outline search's fit (``outline.py``).
"""

import math

import numpy as np

from balltrack.services.detector.geometry import Candidate

# Circle refinement: (tolerance over radius, tolerance floor in pixels) of each fitting round.
REFINE_ROUNDS = ((0.35, 2.0), (0.2, 1.5), (0.12, 1.2))


def solve_symmetric(matrix: tuple[float, float, float, float, float, float],
                    right: tuple[float, float, float]) -> tuple[float, float, float] | None:
    """The solution of a symmetric 3x3 system by Cramer's rule, None when it is singular.
    ``matrix``: its entries (m00, m01, m02, m11, m12, m22). (np.linalg.solve costs more than
    the fits that call this.)"""
    m00, m01, m02, m11, m12, m22 = matrix
    t0, t1, t2 = right
    c00, c01, c02 = m11 * m22 - m12 * m12, m02 * m12 - m01 * m22, m01 * m12 - m02 * m11
    determinant = m00 * c00 + m01 * c01 + m02 * c02
    if abs(determinant) < 1e-9:
        return None
    c11, c12, c22 = m00 * m22 - m02 * m02, m01 * m02 - m00 * m12, m00 * m11 - m01 * m01
    return ((c00 * t0 + c01 * t1 + c02 * t2) / determinant,
            (c01 * t0 + c11 * t1 + c12 * t2) / determinant,
            (c02 * t0 + c12 * t1 + c22 * t2) / determinant)


def fit_circle(dx: np.ndarray, dy: np.ndarray) -> tuple[float, float, float] | None:
    """Algebraic (Kasa) least-squares circle through points given relative to a point near
    their centre: returns its centre (relative to the same point) and radius, or None."""
    return kasa_circle(kasa_rows(dx, dy))


def kasa_rows(dx: np.ndarray, dy: np.ndarray) -> np.ndarray:
    """The rows (dx, dy, 1, dx^2 + dy^2) of points' Kasa fit (see kasa_circle)."""
    rows = np.empty((4, dx.size))
    rows[0], rows[1], rows[2] = dx, dy, 1.0
    np.multiply(dx, dx, out=rows[3])
    rows[3] += dy * dy
    return rows


def kasa_circle(rows: np.ndarray) -> tuple[float, float, float] | None:
    """The Kasa circle of points (their ``kasa_rows``, or some of their columns): centre
    relative to the points' origin and radius, or None."""
    # dx^2 + dy^2 = a dx + b dy + c  ->  centre (a/2, b/2), radius^2 = c + (a^2 + b^2) / 4
    # (the normal equations' sums as one matrix product: one by one they cost more in calls)
    (m00, m01, m02, t0), (_, m11, m12, t1), (_, _, m22, t2), _ = (rows @ rows.T).tolist()
    solved = solve_symmetric((m00, m01, m02, m11, m12, m22), (t0, t1, t2))
    if solved is None:
        return None
    a, b, c = solved
    centre_x, centre_y = a / 2.0, b / 2.0
    radius_squared = c + centre_x * centre_x + centre_y * centre_y
    if not math.isfinite(radius_squared) or radius_squared <= 0:
        return None
    return centre_x, centre_y, math.sqrt(radius_squared)


def geometric_circle(px: np.ndarray, py: np.ndarray, x: float, y: float, radius: float,
                     iterations: int = 3) -> tuple[float, float, float]:
    """Gauss-Newton refinement of a circle on the geometric distances of points to it."""
    for _ in range(iterations):
        dx, dy = px - x, py - y
        distance = np.maximum(np.hypot(dx, dy), 1e-9)
        # normal equations of the Jacobian (-ux, -uy, -1) and the residuals, as one product
        rows = np.empty((4, dx.size))
        np.divide(dx, distance, out=rows[0])
        np.divide(dy, distance, out=rows[1])
        rows[2] = 1.0
        np.subtract(distance, radius, out=rows[3])
        (m00, m01, m02, t0), (_, m11, m12, t1), (_, _, m22, t2), _ = (rows @ rows.T).tolist()
        delta = solve_symmetric((m00, m01, m02, m11, m12, m22), (t0, t1, t2))
        if delta is None:
            break
        shift_x, shift_y, growth = delta
        if not (math.isfinite(shift_x) and math.isfinite(shift_y) and math.isfinite(growth)):
            break
        x, y, radius = x + shift_x, y + shift_y, radius + growth
        if abs(shift_x) + abs(shift_y) + abs(growth) < 1e-3:
            break
    return x, y, radius


def robust_circle(px: np.ndarray, py: np.ndarray, x: float, y: float, radius: float,
                  rounds: tuple, geometric: bool) -> tuple[float, float, float, np.ndarray] | None:
    """Circle through the points near (x, y, radius), in rounds of ever tighter tolerance
    (algebraic fits, then optionally a geometric one); also returns which points lie on it.

    ``rounds``: (tolerance over radius, tolerance floor in pixels) per round. None when fewer
    than 8 points are within a round's tolerance or a fit is degenerate.
    """
    # The points relative to the first centre and their Kasa rows, made once: a round only
    # selects the points near its circle (a Kasa circle is the same from any origin).
    dx, dy = px - x, py - y
    rows = kasa_rows(dx, dy)
    centre_x = centre_y = 0.0
    for tolerance_ratio, tolerance_floor in rounds:
        keep = (np.abs(np.hypot(dx - centre_x, dy - centre_y) - radius)
                < max(tolerance_floor, tolerance_ratio * radius))
        if np.count_nonzero(keep) < 8:
            return None
        fitted = kasa_circle(rows[:, keep])
        if fitted is None:
            return None
        centre_x, centre_y, radius = fitted
    x, y = x + centre_x, y + centre_y
    if geometric:
        x, y, radius = geometric_circle(px[keep], py[keep], x, y, radius)
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(radius) and radius > 0):
            return None
    residual = np.hypot(px - x, py - y) - radius
    return x, y, radius, np.abs(residual) < max(rounds[-1][1], rounds[-1][0] * radius)


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
    xs = xs[near_columns] - x  # relative to the proposal's centre
    ys = ys[near_columns] - y
    # (their Kasa rows made once: a round only selects the pixels near its circle)
    rows = kasa_rows(xs, ys)
    centre_x = centre_y = 0.0
    for tolerance_ratio, tolerance_floor in REFINE_ROUNDS:
        tolerance = max(tolerance_floor, tolerance_ratio * radius)
        dx, dy = xs - centre_x, ys - centre_y
        squared = dx * dx + dy * dy
        near = (squared > max(0.0, radius - tolerance) ** 2) & (squared < (radius + tolerance) ** 2)
        if np.count_nonzero(near) < 6:
            return None
        fitted = kasa_circle(rows[:, near])
        if fitted is None:
            return None
        new_x, new_y, new_radius = fitted
        if not (0.6 * radius <= new_radius <= 1.6 * radius):
            return None
        moved = abs(new_x - centre_x) + abs(new_y - centre_y) + abs(new_radius - radius)
        centre_x, centre_y, radius = new_x, new_y, new_radius
        if moved < 0.05 and tolerance_ratio <= REFINE_ROUNDS[1][0]:
            break  # converged
    # Boundary pixels are the mask's outermost pixels, half a pixel inside its true edge.
    return Candidate(x + centre_x, y + centre_y, radius + 0.5)
