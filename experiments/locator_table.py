"""Range error of the locator's faithful and exact models against analytic sphere projections.

A tennis ball (radius 0.033 m) is placed at 0.3, 1, 2 and 3.5 m on the rays through the image
centre, a point near the right edge (x = 0.9) and near the corner (x = y = 0.9) of a 640x480
camera with the paper's 1.089 rad horizontal field of view. ``project_sphere`` gives the circle
a detector would report (``--circle-model``, default ``mean``); both models locate the ball from
it. The second table rounds ``radius_px`` to the nearest 0.5 px, the Hough transform's
resolution, to show what pixel quantisation alone costs. Errors are signed for the range
(``(d_estimated - d_true) / d_true``) and unsigned for the 3D position (``|P_est - P_true| / d_true``).

Example::

    python -m balltrack.experiments.locator_table
    python -m balltrack.experiments.locator_table --circle-model enclosing
    python -m balltrack.experiments.locator_table --detector-model enclosing   # locator assumes mean
"""


import numpy as np

from balltrack.common.arguments import ArgumentParser
from balltrack.common.pinhole import Intrinsics
from balltrack.common.terminal import exit_with
from balltrack.services.locator.geometry import faithful_v_fov, locate_exact, locate_faithful
from balltrack.services.locator.projection import CIRCLE_MODELS, project_sphere

WIDTH, HEIGHT = 640, 480
H_FOV = 1.089
BALL_RADIUS = 0.033
DISTANCES = (0.3, 1.0, 2.0, 3.5)
PLACES = (("centre", 0.0, 0.0), ("edge x=0.9", 0.9, 0.0), ("corner 0.9,0.9", 0.9, 0.9))


def ball_on_ray(intrinsics: Intrinsics, x: float, y: float, distance: float) -> np.ndarray:
    """A ball centre at ``distance`` on the ray through normalised image point ``(x, y)``."""
    u = WIDTH / 2 * (1 + x)
    v = HEIGHT / 2 * (1 + y)
    ray = np.array([(u - intrinsics.cx) / intrinsics.fx, (v - intrinsics.cy) / intrinsics.fy, 1.0])
    return distance * ray / np.linalg.norm(ray)


def measure(circle_model: str, radius_step: float | None, detector_model: str | None = None) -> list[dict]:
    """One row per (distance, place): the reported radius and both models' errors.

    ``detector_model`` is what the simulated detector reports (default: ``circle_model``, the
    locator's assumption); giving another one measures the cost of a wrong assumption.
    """
    intrinsics = Intrinsics.from_fov(WIDTH, HEIGHT, H_FOV)
    v_fov = faithful_v_fov(H_FOV, WIDTH, HEIGHT)
    rows = []
    for distance in DISTANCES:
        for name, x, y in PLACES:
            truth = ball_on_ray(intrinsics, x, y, distance)
            u, v, radius_px = project_sphere(truth, BALL_RADIUS, intrinsics, detector_model or circle_model)
            if radius_step:
                radius_px = round(radius_px / radius_step) * radius_step
            faithful = locate_faithful((u - WIDTH / 2) / (WIDTH / 2), (v - HEIGHT / 2) / (HEIGHT / 2),
                                       2 * radius_px / WIDTH, H_FOV, v_fov, BALL_RADIUS)
            exact = locate_exact(u, v, radius_px, intrinsics, BALL_RADIUS, circle_model)
            row = {"distance": distance, "place": name, "radius_px": radius_px}
            for label, estimate in (("faithful", faithful), ("exact", exact)):
                position = np.array([estimate.x, estimate.y, estimate.z])
                row[f"{label}_range"] = 100 * (estimate.distance - distance) / distance
                row[f"{label}_position"] = 100 * float(np.linalg.norm(position - truth)) / distance
            rows.append(row)
    return rows


def _signed(value: float, digits: int) -> str:
    text = f"{value:+.{digits}f}"
    return text.replace("-", "+") if float(text) == 0.0 else text  # no "-0.0000"


def format_table(rows: list[dict]) -> str:
    lines = ["| d (m) | where | r (px) | faithful range % | exact range % | faithful 3D % | exact 3D % |",
             "| ---: | --- | ---: | ---: | ---: | ---: | ---: |"]
    for row in rows:
        lines.append(f"| {row['distance']:.1f} | {row['place']} | {row['radius_px']:.2f} "
                     f"| {_signed(row['faithful_range'], 2)} | {_signed(row['exact_range'], 4)} "
                     f"| {row['faithful_position']:.2f} | {row['exact_position']:.4f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(prog="python -m balltrack.experiments.locator_table",
                            description=__doc__.split("\n\n")[0])
    parser.add_argument("--circle-model", choices=CIRCLE_MODELS, default="mean",
                        help="what the locator assumes the detector's circle measures (default: mean)")
    parser.add_argument("--detector-model", choices=CIRCLE_MODELS, default=None,
                        help="what the simulated detector actually reports (default: --circle-model)")
    args = parser.parse_args(argv)
    focal = Intrinsics.from_fov(WIDTH, HEIGHT, H_FOV).fx
    print(f"{WIDTH}x{HEIGHT}, h_fov {H_FOV} rad (fx = {focal:.1f} px), "
          f"ball radius {BALL_RADIUS} m, circle model {args.circle_model}, "
          f"detector reports {args.detector_model or args.circle_model}\n")
    print("Ideal detector (radius_px exact):\n")
    print(format_table(measure(args.circle_model, None, args.detector_model)))
    print("\nradius_px rounded to the nearest 0.5 px (Hough resolution; centre not rounded):\n")
    print(format_table(measure(args.circle_model, 0.5, args.detector_model)))
    return 0


if __name__ == "__main__":
    exit_with(main)
