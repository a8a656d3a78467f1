"""Candidates of the colour mask's blobs: steps 5-6 of the detector (see ``detector.py``).

Each blob proposes circles (its enclosing circle; unless that is a clean isolated ball, Hough's
circles in its box, the circles of its outline's long arcs, the crescent of a washed-out
highlight, the members of a cluster of touching balls and a ball in front of another), and
each circle is refined on the mask's boundary and measured (``measure.py``) before step 7
judges it.
"""

import dataclasses
import math

import cv2
import numpy as np

from balltrack.services.detector.arcs import arc_proposals
from balltrack.services.detector.checks import CandidateMetrics, judge
from balltrack.services.detector.measure import colour_stats, measure_mask
from balltrack.services.detector.clusters import CLUSTER_MIN_SIZE, CLUSTER_SPREAD, Measured, cluster_candidates
from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.fit import refine_on_boundary
from balltrack.services.detector.front import front_balls
from balltrack.services.detector.geometry import Candidate
from balltrack.services.detector.highlight import crescent_candidates, highlight_metrics, needs_highlight
from balltrack.services.detector.occlusion import measured_in_view
from balltrack.services.detector.proposals import FrameSearch, blob_image, blob_proposals, hough_proposals

# A candidate's colour may be a lit cap down to this share of min_radius (a ball under a light
# with no ambient: its dark side is found by the outline search, or it is dropped).
LIT_CAP_SHARE = 0.6


def contour_candidates(contour: np.ndarray, search: FrameSearch, mask: np.ndarray,
                       config: DetectorConfig) -> list[Measured]:
    """Every candidate of one blob of ``mask``, measured on it: its enclosing circle and,
    unless that is a clean isolated ball, Hough's circles, its outline arcs' circles and
    the members of the cluster of balls it may be."""
    proposals = blob_proposals(contour, search, mask, config)
    if proposals is None:
        return []  # the blob cannot be or hold a ball
    found = measure_proposals(proposals, search, mask, config)
    if any(metrics.clean for _, metrics in found):
        return found  # one isolated round blob: nothing for Hough to split
    in_blob = measure_proposals(hough_proposals(cv2.boundingRect(contour), search, config), search, mask, config)
    in_blob.extend(crescent_candidates(contour, mask, search.planes, search.small_radius,
                                       search.max_radius, config))
    blob, left, top = blob_image(contour, mask)
    arcs = arc_proposals(blob, left, top, CLUSTER_MIN_SIZE * search.small_radius, search.max_radius)
    in_blob.extend(arc_candidates(arcs, search, mask, config))
    return (found + in_blob + cluster_candidates(contour, search, mask, found + in_blob, arcs)
            + front_balls(contour, search, mask, CLUSTER_MIN_SIZE * search.small_radius))


def arc_candidates(arcs: list[Candidate], search: FrameSearch, mask: np.ndarray,
                   config: DetectorConfig) -> list[Measured]:
    """The circles of a blob's long even outline arcs (see arcs.py), refined and measured
    on ``mask``: those as large as a cluster member and evenly edged all round
    (CLUSTER_MIN_SIZE, CLUSTER_SPREAD): a piece of outline alone proves less than a whole
    blob, and a lobe of ragged clutter is round along one arc only."""
    return [(candidate, metrics) for candidate, metrics in measure_proposals(arcs, search, mask, config)
            if metrics.size >= CLUSTER_MIN_SIZE and metrics.mask.spread <= CLUSTER_SPREAD]


def measure_proposals(proposals: list[Candidate], search: FrameSearch, mask: np.ndarray,
                      config: DetectorConfig) -> list[Measured]:
    """Refine each proposal on the mask boundary, then measure it on ``mask``."""
    results: list[Measured] = []
    fitted_circles: list[Candidate] = []
    for proposal in proposals:
        candidate = refine_on_boundary(proposal, search.boundary_x, search.boundary_y)
        if candidate is None:
            continue
        # (the colour of a ball with a dark side, no ambient light, may be a smaller cap)
        if not (LIT_CAP_SHARE * search.min_radius <= candidate.radius <= search.max_radius):
            continue
        if any(math.hypot(candidate.x - other.x, candidate.y - other.y) < 0.1 * other.radius + 0.5
               and abs(candidate.radius - other.radius) < 0.1 * other.radius + 0.5
               for other in fitted_circles):
            continue  # converged onto a circle already measured
        fitted_circles.append(candidate)
        on_mask = measure_mask(candidate, mask)
        if on_mask is None:
            continue
        metrics = CandidateMetrics(mask=on_mask, colour=colour_stats(candidate, search.planes),
                                   size=candidate.radius / search.small_radius)
        if needs_highlight(metrics, config) and judge(metrics, config) is None:
            joined = highlight_metrics(candidate, mask, search.planes, config)
            if joined is not None:
                highlighted = dataclasses.replace(metrics, mask=joined, highlighted=True)
                if judge(highlighted, config) is not None:
                    metrics = highlighted
        metrics = measured_in_view(candidate, metrics, mask, config)
        results.append((candidate, metrics))
    return results
