"""Why a ball was not found: the detector's view of one place in a frame.

For a place where a ball should be (``balltrack detect --explain U,V``, and each missed ball of
``real_photos --misses``): whether a ball was found there; how the colour there compares with
the colour mask's tests (the usual reason a ball has no candidate at all); and the candidate
circle the detector judged there, with every check it failed (``checks.failed_checks``). What
to change follows from it: a ball whose saturation is below ``s_min``, a candidate whose mean
hue is past ``h_max`` less ``hue_margin``.

Example::

    detector = BallDetector(config)
    result, judged = detector.detect_judged(image)
    print(summary(explain_place(image, result, judged, config, 412, 230)))
"""

import math

import cv2
import numpy as np

from balltrack.services.detector.checks import failed_checks, hue_in_range
from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.detector import DetectionResult, JudgedCandidate
from balltrack.services.detector.geometry import gaussian_blur
from balltrack.services.detector.mask import check_image

# Without a ball's radius, a place's colour is read within this many px of it.
PLACE_REACH = 3.0


def finds(u: float, v: float, ball_u: float, ball_v: float, ball_radius: float) -> bool:
    """Whether a detection centred at (u, v) finds the ball at (ball_u, ball_v): its centre lies
    within half the ball's radius (how the photo sets are scored, ``experiments/real_photos.py``)."""
    return math.hypot(u - ball_u, v - ball_v) <= ball_radius / 2.0


def explain_place(image_bgr: np.ndarray, result: DetectionResult, judged: list[JudgedCandidate],
                  config: DetectorConfig, u: float, v: float, radius: float | None = None) -> dict:
    """The detector's view of the place (u, v) of a frame (pixels of ``image_bgr``), from one
    ``detect_judged`` call's ``result`` and ``judged``; ``radius``: the ball's expected radius
    there, when known (a labelled box).

    A ball is found there when a detection's centre lies within half of ``radius`` of the place
    (as ``real_photos`` scores), or without ``radius`` when the place is inside a detection.
    Returns ``{"u", "v", "found": {u, v, radius_px, score} or None, "covered_by": {u, v,
    radius_px, score, offset_px} or None, "colour": {hue, saturation, value, mask_share, failed},
    "candidate": {u, v, radius_px, score, failed} or None, "around": {u, v, radius_px, score,
    failed, offset_px} or None}``: ``covered_by`` is a detection whose disc holds the place though
    its centre is too far from it to count (when none is found), the candidate is the judged
    circle nearest the place, one that passed first, and ``around`` (when there is no such
    candidate) the judged circle whose disc holds the place with its centre nearest it: a circle
    the mask's blob gave that is off the ball (around the ball and a neighbour, or a blob that
    lacks part of the ball).
    """
    image_bgr = check_image(image_bgr)

    def near(x: float, y: float, own_radius: float) -> bool:
        return finds(x, y, u, v, radius) if radius else math.hypot(x - u, y - v) <= own_radius

    def offset(item) -> float:
        return math.hypot(item.u - u, item.v - v)

    found = [d for d in result.detections if near(d.u, d.v, d.radius_px)]
    covering = [d for d in result.detections if offset(d) <= d.radius_px]
    candidates = [c for c in judged if near(c.u, c.v, c.radius_px)]
    candidates.sort(key=lambda c: (c.score is None, offset(c)))
    around = None if candidates else min((c for c in judged if offset(c) <= c.radius_px), key=offset, default=None)
    best = min(found, key=offset) if found else None
    cover = min(covering, key=offset) if covering and best is None else None
    return {
        "u": u, "v": v,
        "found": None if best is None else {"u": round(best.u, 1), "v": round(best.v, 1),
                                            "radius_px": round(best.radius_px, 1), "score": best.score},
        # (without a radius a detection holding the place is a find, so only with one)
        "covered_by": None if cover is None else {
            "u": round(cover.u, 1), "v": round(cover.v, 1), "radius_px": round(cover.radius_px, 1),
            "score": cover.score, "offset_px": round(offset(cover), 1)},
        "colour": colour_at(image_bgr, result.mask, config, u, v, radius / 2.0 if radius else PLACE_REACH),
        "candidate": None if not candidates else {
            "u": round(candidates[0].u, 1), "v": round(candidates[0].v, 1),
            "radius_px": round(candidates[0].radius_px, 1), "score": candidates[0].score,
            "failed": failed_checks(candidates[0].metrics, config)},
        "around": None if around is None else {
            "u": round(around.u, 1), "v": round(around.v, 1), "radius_px": round(around.radius_px, 1),
            "score": around.score, "failed": failed_checks(around.metrics, config),
            "offset_px": round(offset(around), 1)},
    }


def colour_at(image_bgr: np.ndarray, mask: np.ndarray, config: DetectorConfig, u: float, v: float,
              reach: float) -> dict:
    """The median colour within ``reach`` px of (u, v) after the mask's blur, the share of
    colour-mask pixels there, and the colour tests that median fails (hue, saturation and the
    chroma floor; the value test reads the locally equalised brightness, which is not shown)."""
    height, width = image_bgr.shape[:2]
    reach = max(1.0, reach)
    left, right = max(0, int(u - reach)), min(width, int(u + reach) + 1)
    top, bottom = max(0, int(v - reach)), min(height, int(v + reach) + 1)
    if left >= right or top >= bottom:
        return {"hue": None, "saturation": None, "value": None, "mask_share": 0.0,
                "failed": ["the place is outside the frame"]}
    # (the blur needs the kernel's reach around the window)
    margin = config.blur_kernel
    outer = (slice(max(0, top - margin), bottom + margin), slice(max(0, left - margin), right + margin))
    patch = gaussian_blur(image_bgr[outer], config.blur_kernel)
    rows, columns = np.mgrid[top:bottom, left:right]
    inside = (columns - u) ** 2 + (rows - v) ** 2 <= reach * reach
    if not inside.any():
        inside[:] = True
    window = patch[top - outer[0].start:bottom - outer[0].start, left - outer[1].start:right - outer[1].start]
    pixels = window[inside]
    hsv = cv2.cvtColor(pixels.reshape(-1, 1, 3), cv2.COLOR_BGR2HSV).reshape(-1, 3)
    hue, saturation, value = (float(np.median(hsv[:, channel])) for channel in range(3))
    chroma = float(np.median(pixels.max(axis=1).astype(int) - pixels.min(axis=1)))
    failed = []
    if not hue_in_range(hue, config, 0.0):
        failed.append(f"hue {hue:.0f} is outside h_min-h_max ({config.h_min}-{config.h_max})")
    if not config.s_min <= saturation <= config.s_max:
        failed.append(f"saturation {saturation:.0f} is outside s_min-s_max ({config.s_min}-{config.s_max})")
    if chroma < config.min_chroma:
        failed.append(f"chroma {chroma:.0f} < min_chroma {config.min_chroma:g}")
    share = float(np.count_nonzero(mask[top:bottom, left:right][inside] == 255)) / int(np.count_nonzero(inside))
    return {"hue": hue, "saturation": saturation, "value": value, "mask_share": round(share, 3),
            "failed": failed}


def summary(explanation: dict) -> str:
    """One line: found; or the first reason it was not: the candidate's failed checks, or when
    there is no candidate, a detection off centre around the place, or the colour's tests."""
    found, colour, candidate = explanation["found"], explanation["colour"], explanation["candidate"]
    if found is not None:
        return f"found at ({found['u']:.0f}, {found['v']:.0f}), radius {found['radius_px']:.1f} px"
    cover = explanation["covered_by"]
    if cover is not None and candidate is None:
        return (f"inside the detection at ({cover['u']:.0f}, {cover['v']:.0f}), radius "
                f"{cover['radius_px']:.1f} px, whose centre is {cover['offset_px']:.0f} px away, more "
                "than half the ball's radius (a circle off the ball: around a neighbour too, or "
                "the neighbour's)")
    if candidate is not None:
        where = f"candidate ({candidate['u']:.0f}, {candidate['v']:.0f}), radius {candidate['radius_px']:.1f} px"
        if candidate["score"] is not None:
            return (f"{where} passed its checks but was not kept (a better candidate overlaps it, "
                    "or its outline was not found)")
        return f"{where}: " + "; ".join(candidate["failed"])
    if colour["hue"] is None:
        return "no candidate; " + "; ".join(colour["failed"])
    colour_figures = f"H {colour['hue']:.0f} S {colour['saturation']:.0f} V {colour['value']:.0f}"
    if colour["failed"]:
        return f"no candidate; the colour here ({colour_figures}) fails: " + "; ".join(colour["failed"])
    passes = (f"no candidate; the colour here ({colour_figures}) passes the hue, saturation and chroma "
              f"tests, colour mask {100 * colour['mask_share']:.0f} % of the place")
    around = explanation.get("around")
    if around is None:
        return passes
    judgement = "; ".join(around["failed"]) if around["failed"] else "passed, not kept"
    return (f"{passes}; the circle judged around it is off centre: ({around['u']:.0f}, {around['v']:.0f}), "
            f"radius {around['radius_px']:.1f} px, {around['offset_px']:.0f} px away: {judgement}")
