"""Proposals (services/detector/proposals.py): blobs and Hough circles on drawn masks."""

import math

import cv2
import numpy as np
import pytest

from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.geometry import Candidate, disc
from balltrack.services.detector.mask import EXPLAINED, ColourPlanes
from balltrack.services.detector.proposals import (CLUSTER_COVER, HOUGH_CIRCLES_PER_BLOB,
                                                   blob_proposals,
                                                   boundary_points, frame_search, hough_proposals,
                                                   blob_cover, fill_holes, inscribed_discs,
                                                   leftover_blobs, leftover_search)

SHAPE = (240, 320)


def planes_of(mask, chroma_level=180, value=120):
    """Colour planes of a drawn mask: colour of ``chroma_level`` and brightness ``value`` where
    the mask is, grey elsewhere; the frame's reference level is 250."""
    chroma = np.where(mask == 255, chroma_level, 5).astype(np.uint8)
    frame = np.full(mask.shape + (3,), 120, np.uint8)
    frame[mask == 255] = value
    return ColourPlanes(mask=mask, frame=frame, gain=1.0, chroma=chroma, reference=250.0)


def search_of(mask, config=None, chroma_level=180, value=120):
    return frame_search(planes_of(mask, chroma_level, value), config or DetectorConfig(), 1.0)


def test_fill_holes_one_contour_per_blob():
    mask = disc(SHAPE, 60.0, 60.0, 15.0) | disc(SHAPE, 200.0, 120.0, 25.0)
    blobs, filled = fill_holes(mask)
    assert len(blobs) == 2
    assert sorted(cv2.boundingRect(blob)[2] for blob in blobs) == pytest.approx([31, 51], abs=2)
    assert filled is mask  # no holes: nothing to fill
    assert fill_holes(np.zeros(SHAPE, np.uint8))[0] == []


def test_fill_holes_fills_a_logo_but_not_a_ring():
    # a ball with a dark logo and a highlight inside it: one blob, filled
    ball = disc(SHAPE, 80.0, 120.0, 40.0) & ~disc(SHAPE, 70.0, 110.0, 12.0) & ~disc(SHAPE, 95.0, 130.0, 8.0)
    # a ring (a tape roll): its opening is most of it
    ring = disc(SHAPE, 240.0, 120.0, 40.0) & ~disc(SHAPE, 240.0, 120.0, 32.0)
    blobs, filled = fill_holes(ball | ring)
    assert len(blobs) == 2
    assert np.array_equal(filled[:, :160], disc(SHAPE, 80.0, 120.0, 40.0)[:, :160])
    assert np.array_equal(filled[:, 160:], ring[:, 160:])


def test_boundary_points_lie_on_the_rim_in_row_order_without_the_frame_border():
    x, y, radius = 150.5, 110.2, 30.0
    boundary_x, boundary_y = boundary_points(disc(SHAPE, x, y, radius))
    distance = np.hypot(boundary_x - x, boundary_y - y)
    assert boundary_x.dtype == np.float64 and boundary_x.size > 150
    # (pixel centres of a rasterised rim: within a pixel of the circle)
    assert (distance > radius - 1.5).all() and (distance < radius + 1.0).all()
    assert (np.diff(boundary_y) >= 0).all()
    # a disc cut by the top edge: no boundary pixel on row 0
    boundary_x, boundary_y = boundary_points(disc(SHAPE, 100.0, 5.0, 20.0))
    assert boundary_y.min() >= 1
    assert boundary_points(np.zeros(SHAPE, np.uint8))[0].size == 0


def test_blobs_are_the_whole_masks_contours():
    # (they are searched for in the box around the mask's pixels only)
    mask = disc(SHAPE, 60.0, 50.0, 12.0) | disc(SHAPE, 200.0, 150.0, 25.0)
    mask[0:10, SHAPE[1] - 30:] = 255  # a blob on the frame's corner
    expected, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    found = fill_holes(mask)[0]
    assert len(found) == len(expected) == 3
    order = lambda contours: sorted(contours, key=lambda contour: cv2.boundingRect(contour))  # noqa: E731
    assert all(np.array_equal(first, second) for first, second in zip(order(found), order(expected)))
    assert fill_holes(np.zeros(SHAPE, np.uint8))[0] == []


def test_boundary_points_are_the_whole_masks():
    # (they are searched for in the box around the mask's pixels only)
    mask = disc(SHAPE, 60.0, 50.0, 12.0) | disc(SHAPE, 200.0, 150.0, 25.0)
    mask[0:10, SHAPE[1] - 30:] = 255  # a blob on the frame's corner
    mask[70:75, 100:104] = EXPLAINED
    boundary = cv2.subtract(mask, cv2.erode(mask, np.ones((3, 3), np.uint8)))
    boundary[0, :] = boundary[-1, :] = 0
    boundary[:, 0] = boundary[:, -1] = 0
    rows, columns = np.nonzero(boundary)
    boundary_x, boundary_y = boundary_points(mask)
    assert np.array_equal(boundary_x, columns) and np.array_equal(boundary_y, rows)


def test_frame_search_radius_limits():
    mask = np.zeros(SHAPE, np.uint8)
    search = search_of(mask)
    assert search.min_radius == 3.0 and search.max_radius == 120.0  # half the shorter side
    assert search.small_radius == 5.0
    scaled = frame_search(planes_of(mask), DetectorConfig(min_radius=4, max_radius=50), 0.5)
    assert (scaled.min_radius, scaled.max_radius, scaled.small_radius, scaled.scale) == (2.0, 25.0, 2.5, 0.5)


def test_a_round_blob_proposes_its_enclosing_circle():
    x, y, radius = 160.4, 120.3, 22.0
    mask = disc(SHAPE, x, y, radius)
    [blob] = fill_holes(mask)[0]
    [proposal] = blob_proposals(blob, search_of(mask), mask, DetectorConfig())
    assert math.hypot(proposal.x - x, proposal.y - y) < 1.0
    assert abs(proposal.radius - radius) < 1.5


def test_elongated_blobs_propose_nothing_but_are_kept_for_hough():
    mask = np.zeros(SHAPE, np.uint8)
    mask[100:112, 40:240] = 255  # a bar
    [blob] = fill_holes(mask)[0]
    assert blob_proposals(blob, search_of(mask), mask, DetectorConfig()) == []


def test_blobs_that_cannot_hold_a_ball_are_dropped():
    config = DetectorConfig()
    tiny = disc(SHAPE, 100.0, 100.0, 1.2)
    assert blob_proposals(fill_holes(tiny)[0][0], search_of(tiny), tiny, config) is None
    huge = np.full(SHAPE, 255, np.uint8)
    huge[0, :] = 0
    small_limit = search_of(huge, DetectorConfig(max_radius=20))
    assert blob_proposals(fill_holes(huge)[0][0], small_limit, huge, config) is None
    # a dull blob (leaves in shade): its mean chroma is below 0.7 min_colourfulness
    dull = disc(SHAPE, 100.0, 100.0, 20.0)
    # (as bright as the frame's reference level: dull next to its own lit side too)
    dull_search = search_of(dull, chroma_level=int(0.6 * config.min_colourfulness * 250), value=250)
    assert blob_proposals(fill_holes(dull)[0][0], dull_search, dull, config) is None


def test_a_round_blob_in_shade_is_judged_next_to_its_own_lit_side():
    config = DetectorConfig()
    chroma_level = int(0.6 * config.min_colourfulness * 250)  # dull next to the frame's level
    # a ball in shade, at 0.4 of the frame's bright level: vivid next to its own
    ball = disc(SHAPE, 100.0, 100.0, 20.0)
    [proposal] = blob_proposals(fill_holes(ball)[0][0], search_of(ball, chroma_level=chroma_level, value=100),
                                ball, config)
    assert (proposal.x, proposal.y) == pytest.approx((100.0, 100.0), abs=1.0)
    # shaded leaves, a strip of them: not one round blob, so dull as before
    strip = np.zeros(SHAPE, np.uint8)
    strip[90:110, 40:200] = 255
    assert blob_proposals(fill_holes(strip)[0][0], search_of(strip, chroma_level=chroma_level, value=100),
                          strip, config) is None


def test_hough_splits_touching_balls():
    first, second = (120.0, 120.0, 28.0), (120.0 + 28.0 + 20.0, 125.0, 20.0)
    mask = disc(SHAPE, *first) | disc(SHAPE, *second)
    [blob] = fill_holes(mask)[0]
    proposals = hough_proposals(cv2.boundingRect(blob), search_of(mask), DetectorConfig())
    assert 2 <= len(proposals) <= HOUGH_CIRCLES_PER_BLOB
    for x, y, radius in (first, second):
        nearest = min(proposals, key=lambda p: math.hypot(p.x - x, p.y - y))
        assert math.hypot(nearest.x - x, nearest.y - y) < 3.0
        assert abs(nearest.radius - radius) < 4.0
    # no two proposals are variants of one circle
    for index, one in enumerate(proposals):
        for other in proposals[index + 1:]:
            assert math.hypot(one.x - other.x, one.y - other.y) >= 0.5 * max(one.radius, other.radius)


def test_hough_skips_boxes_too_small_for_a_ball():
    mask = disc(SHAPE, 100.0, 100.0, 3.0)
    assert hough_proposals((97, 97, 7, 7), search_of(mask), DetectorConfig()) == []


def test_leftover_blobs_are_the_pieces_near_an_accepted_ball():
    ball = Candidate(120.0, 120.0, 25.0)
    explained = disc(SHAPE, 120.0, 120.0, 25.0) | disc(SHAPE, 160.0, 120.0, 15.0)  # a neighbour
    explained |= disc(SHAPE, 290.0, 30.0, 10.0)  # far away
    cv2.circle(explained, (120, 120), int(math.ceil(25.0 * 1.08 + 1)), EXPLAINED, -1)
    pieces = leftover_blobs([ball], explained)
    assert len(pieces) == 1
    left, top, width, height = cv2.boundingRect(pieces[0])
    # the neighbour's part outside the accepted ball's disc, in frame coordinates
    assert 145 <= left <= 150 and left + width == 176 and 105 <= top <= 107
    assert leftover_blobs([], explained) == []


def test_leftover_blobs_leave_out_pieces_apart_from_the_ball():
    # a speck within reach of the accepted ball but never joined to it was a blob of its own
    # from the start (already proposed); only the neighbour that touches the disc is new
    ball = Candidate(120.0, 120.0, 25.0)
    explained = disc(SHAPE, 120.0, 120.0, 25.0) | disc(SHAPE, 160.0, 120.0, 15.0)
    explained |= disc(SHAPE, 120.0, 190.0, 5.0)  # 70 px below: inside the reach, apart
    cv2.circle(explained, (120, 120), int(math.ceil(25.0 * 1.08 + 1)), EXPLAINED, -1)
    pieces = leftover_blobs([ball], explained)
    assert len(pieces) == 1
    left, _, width, _ = cv2.boundingRect(pieces[0])
    assert left + width == 176  # the neighbour's outer edge
    # a neighbour whose mask stops a pixel short of the cleared disc (a ragged edge) still counts
    gap = disc(SHAPE, 120.0, 120.0, 25.0) | (disc(SHAPE, 165.0, 120.0, 15.0) & ~disc(SHAPE, 120.0, 120.0, 29.0))
    cv2.circle(gap, (120, 120), int(math.ceil(25.0 * 1.08 + 1)), EXPLAINED, -1)
    assert len(leftover_blobs([ball], gap)) == 1


def test_a_cluster_of_touching_balls_splits_into_inscribed_discs_that_cover_it():
    centres = [(100.0, 120.0), (139.0, 124.0), (120.0, 158.0)]
    mask = np.zeros(SHAPE, np.uint8)
    for x, y in centres:
        mask |= disc(SHAPE, x, y, 20.0)
    [blob] = fill_holes(mask)[0]
    discs = inscribed_discs(blob, search_of(mask), [])
    assert len(discs) == 3
    for x, y in centres:
        nearest = min(discs, key=lambda found: math.hypot(found.x - x, found.y - y))
        # (proposals: the refinement on the mask's boundary follows)
        assert math.hypot(nearest.x - x, nearest.y - y) < 4.0 and abs(nearest.radius - 20.0) < 3.0
    assert blob_cover(blob, mask, discs) >= CLUSTER_COVER
    # with two balls already taken, the third is what is left
    [third] = inscribed_discs(blob, search_of(mask), [Candidate(x, y, 20.0) for x, y in centres[:2]])
    assert math.hypot(third.x - centres[2][0], third.y - centres[2][1]) < 3.0


@pytest.mark.parametrize("side", ["left", "right", "top", "bottom"])
def test_a_ball_cut_by_the_frame_edge_keeps_its_inscribed_disc(side):
    # a ball touching one whose centre lies 6 px inside the frame's edge: the frame's border
    # is not the blob's edge, so its disc is about its own size, not the sliver's (its centre
    # on the border, where the blob is widest: the refinement on the mask's boundary follows)
    height, width = SHAPE
    inside, cut = {"left": ((60.0, 120.0), (6.0, 120.0)), "right": ((width - 61.0, 120.0), (width - 7.0, 120.0)),
                   "top": ((160.0, 60.0), (160.0, 6.0)), "bottom": ((160.0, height - 61.0), (160.0, height - 7.0))}[side]
    mask = disc(SHAPE, *inside, 28.0) | disc(SHAPE, *cut, 26.0)
    [blob] = fill_holes(mask)[0]
    discs = inscribed_discs(blob, search_of(mask), [])
    nearest = min(discs, key=lambda found: math.hypot(found.x - cut[0], found.y - cut[1]))
    assert math.hypot(nearest.x - cut[0], nearest.y - cut[1]) < 8.0 and abs(nearest.radius - 26.0) < 3.0
    assert blob_cover(blob, mask, discs) >= CLUSTER_COVER


def test_a_strip_is_not_covered_by_its_inscribed_discs():
    strip = np.zeros(SHAPE, np.uint8)
    strip[100:120, 40:280] = 255
    [blob] = fill_holes(strip)[0]
    discs = inscribed_discs(blob, search_of(strip), [])
    assert len(discs) >= 2
    assert blob_cover(blob, strip, discs) < CLUSTER_COVER


def test_the_leftover_search_leaves_out_an_accepted_balls_outline():
    mask = disc(SHAPE, 120.0, 120.0, 25.0) | disc(SHAPE, 160.0, 120.0, 15.0)
    search = search_of(mask)
    explained = mask.copy()
    cv2.circle(explained, (120, 120), int(math.ceil(25.0 * 1.08 + 1)), EXPLAINED, -1)
    left = leftover_search(search, explained)
    assert 0 < left.boundary_x.size < search.boundary_x.size
    # only the neighbour's outline is left, in row order
    assert np.all(np.hypot(left.boundary_x - 160.0, left.boundary_y - 120.0) < 17.0)
    assert np.all(np.diff(left.boundary_y) >= 0)
