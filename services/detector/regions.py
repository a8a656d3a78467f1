"""Regions of interest of the colour mask (steps 2-4 of the detector, see ``mask.py``).

Most of a frame is not ball-coloured, and blurring, converting and cleaning all of it costs
more than the rest of the detector. So the colour is first looked for on every COARSE_STEP-th
pixel with loose thresholds, and steps 2-4 run at full resolution only in boxes around what
passed: inside a box the mask is the whole frame's (but for CLAHE's rounding, see
PartEqualiser), outside it is empty. The one plane that needs the whole frame is the
CLAHE-equalised value (its tiles' histograms); it is made only on the CLAHE tiles around the
boxes.
"""

import math

import cv2
import numpy as np

from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.geometry import brightest_channel

# The coarse search: every this many pixels, each way.
COARSE_STEP = 4
# The coarse search lets through hues up to this far outside h_min..h_max and saturations down
# to this share of s_min: it reads the raw frame, and the mask the blurred one. (With these, no
# mask pixel of 200 renders and 145 photos was outside the boxes.)
COARSE_HUE_SLACK = 5
COARSE_SATURATION_SHARE = 0.75
# Frames at most this wide (px) equalise at full size (see ColourMasker.equalise), frames
# smaller than REGIONS_MIN_HEIGHT are not worth shrinking, and frames of an odd width or height
# are not exactly twice their half size: all are done whole.
REGIONS_MIN_WIDTH = 321
REGIONS_MIN_HEIGHT = 128
# A box reaches this far (px) past the coarse samples that passed (their neighbours included).
REGION_MARGIN = 8
# Around a box its mask is computed on this many px more (blur 2 + opening 2 + closing 4), so
# that inside the box it is the whole frame's.
COMPUTE_MARGIN = 10
# A box whose mask touches its edge (a blob that may go on past it) grows by this much (px),
# for at most MAX_REGION_ROUNDS rounds.
REGION_GROWTH = 24
MAX_REGION_ROUNDS = 4
# More blobs than this among the coarse samples (clutter all over): the whole frame is cheaper.
MAX_BLOBS = 12
# Each box costs about as much as steps 2-4 on this many pixels more (the calls' overhead):
# boxes are merged while their bounding box costs less than they do apart.
BOX_OVERHEAD_PIXELS = 6000
# The 2x2 samples a washed-out ball covers (see pale_in_sample).
PALE_SAMPLE_KERNEL = np.ones((2, 2), np.uint8)
# Beyond this share of the frame in boxes, doing the whole frame is cheaper.
MAX_REGION_SHARE = 0.3
# CLAHE reads the value plane at half size (see ColourMasker.equalise), smoothed by a Gaussian
# of this sigma (half-size px) after its 2x2 averages: with them, about as smooth as the colour
# mask's 5 px blur leaves the frame (sigma 1.1 px, plus 0.6 px for the averages), and a
# Gaussian of a single half-size plane costs a small fraction of one of the colour frame.
HALF_VALUE_SIGMA = 0.55
# Once the parts of the half-size plane have needed more than this share of its CLAHE tiles
# (in all), the whole plane is equalised, once, instead.
PART_TILES_SHARE = 0.5

Box = tuple[int, int, int, int]  # left, top, right, bottom (full-size px, right/bottom excluded)


def coarse_hue_table(config: DetectorConfig) -> np.ndarray:
    """256-entry lookup table: 255 for the hues the coarse search lets through, else 0."""
    hues = np.arange(256)
    low, high = config.h_min - COARSE_HUE_SLACK, config.h_max + COARSE_HUE_SLACK
    if config.h_min <= config.h_max:  # (widened, the range may wrap through 0)
        inside = (hues >= low) & (hues <= high) | (hues - 180 >= low) | (hues + 180 <= high)
    else:
        inside = (hues >= low) | (hues <= high)
    return np.where(inside & (hues < 180), 255, 0).astype(np.uint8)


def regions_apply(shape: tuple[int, ...]) -> bool:
    """Whether a frame of this shape is worth doing by regions."""
    height, width = shape[:2]
    return width >= REGIONS_MIN_WIDTH and height >= REGIONS_MIN_HEIGHT and width % 2 == height % 2 == 0


def coarse_boxes(frame: np.ndarray, hue_table: np.ndarray, config: DetectorConfig,
                 sample_hsv: np.ndarray | None = None) -> list[Box] | None:
    """Boxes holding every pixel of ``frame`` whose colour may pass the mask, found on every
    COARSE_STEP-th pixel of it; None when they would cover too much of it. ``sample_hsv``:
    the HSV of that sample (nearest-neighbour, COARSE_STEP times smaller) when already made."""
    height, width = frame.shape[:2]
    # (every 4th pixel: a ball of min_radius 3 px holds one wherever it lies)
    size = (width // COARSE_STEP, height // COARSE_STEP)
    hsv = sample_hsv
    if hsv is None or hsv.shape[1::-1] != size:
        hsv = cv2.cvtColor(cv2.resize(frame, size, interpolation=cv2.INTER_NEAREST), cv2.COLOR_BGR2HSV)
    coarse = cv2.LUT(cv2.extractChannel(hsv, 0), hue_table)
    coarse &= cv2.inRange(cv2.extractChannel(hsv, 1), int(config.s_min * COARSE_SATURATION_SHARE), 255)
    if not cv2.countNonZero(coarse):
        return []
    # (a blob's pixels reach up to a sample spacing past its samples)
    coarse = cv2.dilate(coarse, None)
    # (the outer contours' boxes are the 8-connected blobs' boxes; cheaper than labelling)
    contours, _ = cv2.findContours(coarse, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    if len(contours) > MAX_BLOBS:
        return None  # ball-coloured clutter all over
    rectangles = [cv2.boundingRect(contour) for contour in contours]
    covered = sum(box_width * box_height for _, _, box_width, box_height in rectangles)
    if covered * COARSE_STEP * COARSE_STEP > MAX_REGION_SHARE * width * height:
        return None  # much of the frame may be ball-coloured (grass, a yellow floor)
    boxes = blob_boxes(rectangles, COARSE_STEP, width, height)
    if sum(box_area(box) for box in boxes) > MAX_REGION_SHARE * width * height:
        return None
    return boxes


def pale_in_sample(sample_hsv: np.ndarray, hue_table: np.ndarray, config: DetectorConfig, bright: float) -> bool:
    """Whether the HSV of a frame's sample (every COARSE_STEP-th pixel) may hold a washed-out
    ball (see pale.py): 2x2 neighbouring samples of a hue the coarse search lets through, a
    saturation from COARSE_SATURATION_SHARE of pale_s_min up to s_min, and a value of at least
    ``bright``. The pale plane is made on frames done whole only (a pale blob cut by a
    box's edge would look alone and round), so such a frame is done whole."""
    if not config.pale_pass:
        return False
    pale = cv2.LUT(cv2.extractChannel(sample_hsv, 0), hue_table)
    pale &= cv2.inRange(cv2.extractChannel(sample_hsv, 1), int(config.pale_s_min * COARSE_SATURATION_SHARE),
                        config.s_min - 1)
    pale &= cv2.inRange(cv2.extractChannel(sample_hsv, 2), min(255, math.ceil(bright)), 255)
    # (a ball of the smallest washed-out radius, 8 px, covers 2x2 samples wherever it lies)
    return cv2.countNonZero(cv2.erode(pale, PALE_SAMPLE_KERNEL)) > 0


def blob_boxes(rectangles, step: int, width: int, height: int) -> list[Box]:
    """The boxes around blobs whose bounding rectangles (x, y, w, h, as ``cv2.boundingRect``
    gives them) are in pixels of a plane ``step`` times smaller than the ``width`` x ``height``
    frame: each REGION_MARGIN px wider all round, inside the frame, then merged (``merged_boxes``)."""
    return merged_boxes([(max(0, left * step - REGION_MARGIN), max(0, top * step - REGION_MARGIN),
                          min(width, (left + box_width) * step + REGION_MARGIN),
                          min(height, (top + box_height) * step + REGION_MARGIN))
                         for left, top, box_width, box_height in rectangles])


def box_area(box: Box) -> int:
    """Pixels of ``box`` with the margin its mask is computed on."""
    left, top, right, bottom = box
    return (right - left + 2 * COMPUTE_MARGIN) * (bottom - top + 2 * COMPUTE_MARGIN)


def merged_boxes(boxes: list[Box]) -> list[Box]:
    """``boxes`` with any two merged into their bounding box while that costs less than the
    two apart (see BOX_OVERHEAD_PIXELS)."""
    boxes = list(boxes)
    merging = True
    while merging:
        merging = False
        for first in range(len(boxes)):
            for second in range(first + 1, len(boxes)):
                a, b = boxes[first], boxes[second]
                union = (min(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]), max(a[3], b[3]))
                if box_area(union) <= box_area(a) + box_area(b) + BOX_OVERHEAD_PIXELS:
                    boxes[first] = union
                    del boxes[second]
                    merging = True
                    break
            if merging:
                break
    return boxes


def half_value(frame: np.ndarray, rows: slice | None = None, columns: slice | None = None) -> np.ndarray:
    """Rows and columns (default all) of the frame's half-size value plane: the brightest
    channel of its 2x2 averages, blurred by HALF_VALUE_SIGMA; read from the part of the frame
    they cover and a half-size pixel around it, so that a part is the whole plane's."""
    height, width = frame.shape[:2]
    rows = rows if rows is not None else slice(0, height // 2)
    columns = columns if columns is not None else slice(0, width // 2)
    # (the blur reads one half-size pixel past the part: two of the frame, where it has them)
    top, left = max(0, rows.start - 1), max(0, columns.start - 1)
    bottom, right = min(height // 2, rows.stop + 1), min(width // 2, columns.stop + 1)
    # (the brightest channel of the 2x2 averages: averaging first, the channels are a quarter
    # of the pixels)
    half = cv2.resize(frame[2 * top:2 * bottom, 2 * left:2 * right], (right - left, bottom - top),
                      interpolation=cv2.INTER_AREA)
    value = brightest_channel(half)
    value = cv2.GaussianBlur(value, (3, 3), HALF_VALUE_SIGMA)
    return value[rows.start - top:rows.stop - top, columns.start - left:columns.stop - left]


def source_span(rows: slice, columns: slice, height: int, width: int) -> tuple[slice, slice]:
    """Rows and columns of a ``height`` x ``width`` plane that its doubled plane's
    ``rows``, ``columns`` read (INTER_LINEAR: within one pixel of half their coordinates)."""
    return (slice(max(0, rows.start // 2 - 1), min(height, (rows.stop - 1) // 2 + 2)),
            slice(max(0, columns.start // 2 - 1), min(width, (columns.stop - 1) // 2 + 2)))


def doubled_part(part: np.ndarray, span: tuple[slice, slice], rows: slice, columns: slice) -> np.ndarray:
    """``cv2.resize(small, twice its size, INTER_LINEAR)[rows, columns]`` from ``part``, the
    ``source_span`` of those rows and columns in ``small``."""
    doubled = cv2.resize(part, (2 * part.shape[1], 2 * part.shape[0]), interpolation=cv2.INTER_LINEAR)
    top, left = rows.start - 2 * span[0].start, columns.start - 2 * span[1].start
    return doubled[top:top + rows.stop - rows.start, left:left + columns.stop - columns.start]


def tile_span(pixels: slice, tile: int, grid: int) -> tuple[int, int]:
    """First and last pixel (excluded) of the CLAHE tiles whose histograms ``pixels`` of a
    plane read: a pixel interpolates between the tiles whose centres surround it."""
    first = max(0, math.floor(pixels.start / tile - 0.5))
    last = min(grid - 1, math.floor((pixels.stop - 1) / tile - 0.5) + 1)
    return first * tile, (last + 1) * tile


class PartEqualiser:
    """CLAHE of a frame's half-size value plane, computed only on the tiles a part of it needs.

    A pixel's CLAHE value depends on the histograms of the (up to four) tiles whose centres
    surround it, so equalising those tiles gives a part the whole plane's values, to within one
    level: OpenCV interpolates between tiles in float32, and at a part's offsets a weight may
    round the other way (a pixel at v_min's edge may then change sides). Planes that the tile
    grid does not divide exactly (OpenCV pads them) are equalised whole, and so is the rest of
    the frame's parts once they have needed PART_TILES_SHARE of its tiles in all (parts' tiles
    overlap).
    """

    def __init__(self, clahe: cv2.CLAHE, grid: int, frame: np.ndarray):
        self._clahe = clahe
        self._grid = grid
        self._frame = frame
        height, width = frame.shape[0] // 2, frame.shape[1] // 2
        self._size = (height, width)
        self._tile = (height // grid, width // grid)
        self._tiled = height % grid == 0 and width % grid == 0
        self._whole: np.ndarray | None = None
        self._tiles_done = 0

    def part(self, rows: slice, columns: slice) -> np.ndarray:
        """The CLAHE-equalised value plane's ``rows``, ``columns``."""
        height, width = self._size
        if self._whole is None and self._tiled:
            tile_height, tile_width = self._tile
            tile_rows = slice(*tile_span(rows, tile_height, self._grid))
            tile_columns = slice(*tile_span(columns, tile_width, self._grid))
            tiles = ((tile_rows.stop - tile_rows.start) // tile_height,
                     (tile_columns.stop - tile_columns.start) // tile_width)
            self._tiles_done += tiles[0] * tiles[1]
            if self._tiles_done <= PART_TILES_SHARE * self._grid * self._grid:
                self._clahe.setTilesGridSize((tiles[1], tiles[0]))
                equalised = self._clahe.apply(half_value(self._frame, tile_rows, tile_columns))
                return equalised[rows.start - tile_rows.start:rows.stop - tile_rows.start,
                                 columns.start - tile_columns.start:columns.stop - tile_columns.start]
        if self._whole is None:
            self._clahe.setTilesGridSize((self._grid, self._grid))
            self._whole = self._clahe.apply(half_value(self._frame))
        return self._whole[rows, columns]


def grown_box(box: Box, piece: np.ndarray, width: int, height: int) -> Box | None:
    """``box`` grown past each of its edges inside the frame that its mask ``piece`` touches
    (a blob that may go on past it); None when it touches none."""
    left, top, right, bottom = box
    grown = (max(0, left - REGION_GROWTH) if left > 0 and piece[:, 0].any() else left,
             max(0, top - REGION_GROWTH) if top > 0 and piece[0].any() else top,
             min(width, right + REGION_GROWTH) if right < width and piece[:, -1].any() else right,
             min(height, bottom + REGION_GROWTH) if bottom < height and piece[-1].any() else bottom)
    return None if grown == box else grown


def compute_window(box: Box, width: int, height: int) -> tuple[slice, slice]:
    """Rows and columns whose mask is computed for ``box``: the box and COMPUTE_MARGIN more."""
    left, top, right, bottom = box
    return (slice(max(0, top - COMPUTE_MARGIN), min(height, bottom + COMPUTE_MARGIN)),
            slice(max(0, left - COMPUTE_MARGIN), min(width, right + COMPUTE_MARGIN)))
