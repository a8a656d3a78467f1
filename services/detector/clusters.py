"""Clusters of touching balls: one blob of the colour mask that is several balls (step 5 of
the detector, see ``detector.py``), read as the set of member circles that explains most of it.
"""

import math

import cv2
import numpy as np

from balltrack.services.detector.checks import CandidateMetrics
from balltrack.services.detector.measure import NO_COLOUR, colour_stats, measure_mask
from balltrack.services.detector.fit import refine_on_boundary
from balltrack.services.detector.geometry import Candidate, circle_overlap
from balltrack.services.detector.mask import EXPLAINED, explained_radius
from balltrack.services.detector.proposals import CLUSTER_COVER, FrameSearch, blob_cover, inscribed_discs

# A member of a cluster of touching balls (see cluster_candidates) is a circle of enough pixels
# (CLUSTER_MIN_SIZE times small_radius) to be told from a lobe of a blob; its fitted circle is
# nearly all colour (CLUSTER_FILL: one ball of the heap) and its own edge is even
# (CLUSTER_SPREAD: a ball's is at most ~0.09 of its radius on real photos).
CLUSTER_MIN_SIZE = 1.5
CLUSTER_FILL = 0.9
CLUSTER_SPREAD = 0.09

Measured = tuple[Candidate, CandidateMetrics]


def cluster_candidates(contour: np.ndarray, search: FrameSearch, mask: np.ndarray,
                       proposed: list[Measured], arcs: list[Candidate]) -> list[Measured]:
    """The balls of a cluster of touching balls, each measured as if the others were
    already found (its rim towards them is neither edge nor leak); [] unless the blob is
    such a cluster.

    Members are circles nearly all colour, evenly edged and large enough (CLUSTER_*), not
    overlapping: the blob's measured proposals, most rim support first, then the
    inscribed discs of what they leave of it (proposals.inscribed_discs); together they
    must cover most of the blob (proposals.CLUSTER_COVER). ``arcs``: the circles of the
    blob's outline arcs (arcs.py), which seed a third reading.
    """
    smallest = CLUSTER_MIN_SIZE * search.small_radius
    if cv2.contourArea(contour) < 2 * 0.8 * math.pi * smallest * smallest:
        return []  # no room for two members
    # (the spread is judged once the other members are explained: rays into them meet
    # their far edges)
    def member_like(candidate: Candidate, metrics: CandidateMetrics) -> bool:
        return candidate.radius >= smallest and metrics.mask.fill >= CLUSTER_FILL

    def completed(members: list[Candidate]) -> list[Candidate]:
        """``members`` and the inscribed discs of what they leave of the blob."""
        members = list(members)
        for proposal in inscribed_discs(contour, search, members):
            fitted = refine_on_boundary(proposal, search.boundary_x, search.boundary_y)
            # (the fit may slide onto a neighbour's outer rim: then the inscribed disc stays)
            if fitted is None or math.hypot(fitted.x - proposal.x, fitted.y - proposal.y) > 0.5 * proposal.radius:
                fitted = proposal
            # (the cheap tests first: most discs of a blob that is no cluster are too small)
            if fitted.radius < smallest or any(circle_overlap(fitted, other) >= 0.3 for other in members):
                continue
            on_mask = measure_mask(fitted, mask)
            if on_mask is not None and on_mask.fill >= CLUSTER_FILL:  # (member_like's other half)
                members.append(fitted)
        return members

    from_proposals: list[Candidate] = []
    for candidate, metrics in sorted(proposed, key=lambda item: item[1].mask.support, reverse=True):
        if member_like(candidate, metrics) and all(circle_overlap(candidate, other) < 0.3
                                                   for other in from_proposals):
            from_proposals.append(candidate)
    # (unrefined: the mask's boundary pixels near an arc's circle include its neighbours')
    from_arcs: list[Candidate] = []
    for candidate in arcs:
        on_mask = measure_mask(candidate, mask)
        if (on_mask is not None and member_like(candidate, CandidateMetrics(on_mask, NO_COLOUR, 0.0))
                and all(circle_overlap(candidate, other) < 0.3 for other in from_arcs)):
            from_arcs.append(candidate)
    # Three readings of the blob: the proposals' circles completed by inscribed discs (Hough
    # splits a heap whose gaps the mask's closing filled), the outline arcs' circles
    # completed so (a ball partly behind another), or inscribed discs alone; the one that
    # explains most of it.
    # (with no proposal or no arc a member, a reading is the discs alone: made once)
    readings = ([completed(from_proposals)] + ([completed([])] if from_proposals else [])
                + ([completed(from_arcs)] if from_arcs else []))
    covers = [blob_cover(contour, mask, reading) if len(reading) >= 2 else 0.0 for reading in readings]
    best = int(np.argmax(covers))
    if covers[best] < CLUSTER_COVER:
        return []
    members = readings[best]
    results: list[Measured] = []
    for member in members:
        others = mask.copy()
        for other in members:
            if other is not member:
                cv2.circle(others, (int(round(other.x)), int(round(other.y))),
                           explained_radius(other.radius), EXPLAINED, -1)
        on_mask = measure_mask(member, others)
        if on_mask is None or on_mask.fill < CLUSTER_FILL or on_mask.spread > CLUSTER_SPREAD:
            continue
        ball = Candidate(member.x, member.y, member.radius)
        results.append((ball, CandidateMetrics(mask=on_mask, colour=colour_stats(ball, search.planes),
                                               size=ball.radius / search.small_radius)))
    return results
