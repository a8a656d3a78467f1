"""The colour mask: steps 1-4 of the detector (see ``detector.py``).

1. Brightness: the frame's reference level (99th percentile of V over small areas, at most 3x
   its median) is measured; a dark frame is scaled up to ``gain_target`` before anything else,
   so that the blur keeps the colour information that uint8 rounding would otherwise
   destroy. Pixels the gain would clip keep their colour (``brighten``).
2. Gaussian blur, then HSV; adaptive histogram equalisation (CLAHE) of V, which the
   ``v_min``/``v_max`` test uses, so that test is relative to the local brightness (of frames
   wider than 320 px, on the half-size V plane made by ``regions.half_value``). Hue and
   saturation do not depend on brightness: a dark ball keeps its colour.
3. Colour mask: the HSV ranges, and a chroma (max - min channel, raw units) of at least
   ``min_chroma``, below which a pixel's hue is rounding or sensor noise (a dark grey floor).
4. Morphological opening and closing of the mask (specks out, seams and logos filled). In
   extremely dark frames (gain >= ``dark_gain``: colour 1-2 grey levels above black) steps 2-4
   work on wider averages instead (``dark_blur_kernel``, chroma floor ``dark_min_chroma``, no
   opening).

Steps 2-4 run at full resolution only in regions of interest, boxes around what may be
ball-coloured on a shrunk copy (see ``regions.py``); frames where such boxes would cover much
of the frame, small frames and pitch-dark frames are done whole.
"""

import math
from dataclasses import dataclass

import cv2
import numpy as np

from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.geometry import brightest_channel, gaussian_blur
from balltrack.services.detector.jit import compiled
from balltrack.services.detector.regions import (MAX_REGION_ROUNDS, MAX_REGION_SHARE, Box, PartEqualiser,
                                                 coarse_boxes, coarse_hue_table, compute_window,
                                                 doubled_part, grown_box, half_value, pale_in_sample,
                                                 regions_apply, source_span)

# The reference level's bright end is that of 3x3 areas of the frame's quarter sample (12x12
# pixels of the frame).
AREA_KERNEL = np.ones((3, 3), np.uint8)
# The smallest frame side (px) the detector takes: its blur, sampling and CLAHE tiles need room.
MIN_IMAGE_SIDE = 8
# A sample of a washed-out ball is at least this share of the frame's reference level bright
# (below pale.PALE_MIN_BRIGHTNESS, which the mean of its whole blob must reach).
PALE_SAMPLE_BRIGHTNESS = 0.5
# Mask value of an accepted ball's disc while its neighbours are judged: neither colour nor not.
EXPLAINED = 128


def explained_radius(radius: float) -> int:
    """Radius (px) of the disc that stands for a ball of ``radius`` once it is accepted or
    taken: 8 % and a pixel wider than its circle, as a mask's edge is ragged."""
    return int(math.ceil(1.08 * radius + 1))


def hue_mask(hue: np.ndarray, config: DetectorConfig) -> np.ndarray:
    """255 where a hue plane (OpenCV's 0-179) is in the configured range, else 0; the range may
    wrap through 0 (red)."""
    if config.h_min <= config.h_max:
        return cv2.inRange(hue, config.h_min, config.h_max)
    return cv2.inRange(hue, config.h_min, 179) | cv2.inRange(hue, 0, config.h_max)


@dataclass
class ColourPlanes:
    """Per-frame images shared by the candidate checks (all at processing size)."""

    mask: np.ndarray        # cleaned colour mask, 0/255
    frame: np.ndarray       # the BGR frame after the dark-frame gain, before the blur
    gain: float             # that gain
    chroma: np.ndarray      # max - min channel after gain and blur (= S * V / 255), uint8
    reference: float        # the frame's reference level on the ``value`` scale
    dark: bool = False      # an extremely dark frame (gain >= dark_gain: averaged colour)
    # 255 where the hue is in range but the saturation only pale_s_min..s_min-1 (a washed-out
    # ball's, see pale.py); None when off, in a dark frame, and where the mask is computed by
    # regions: a pale blob cut by a region's edge would look alone and round, and the regions'
    # coarse search looks for saturated colour only
    pale: np.ndarray | None = None
    # (left, top, right, bottom): the mask is empty outside it (None: anywhere in the frame)
    extent: tuple[int, int, int, int] | None = None


def ellipse_kernel(size: int) -> np.ndarray | None:
    """Elliptic structuring element of ``size`` pixels; None (skip the operation) below 2."""
    if size <= 1:
        return None
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size))


def check_image(image_bgr: np.ndarray) -> np.ndarray:
    """The frame as uint8 HxWx3 BGR (grey frames are expanded); ValueError for anything else."""
    if not isinstance(image_bgr, np.ndarray) or image_bgr.dtype != np.uint8:
        raise ValueError("image must be a uint8 numpy array")
    if image_bgr.ndim == 3 and image_bgr.shape[2] == 1:
        image_bgr = image_bgr[:, :, 0]
    if image_bgr.ndim == 2:
        image_bgr = cv2.cvtColor(image_bgr, cv2.COLOR_GRAY2BGR)
    if image_bgr.ndim != 3 or image_bgr.shape[2] != 3:
        raise ValueError(f"image must be HxWx3 BGR, got shape {image_bgr.shape}")
    if image_bgr.shape[0] < MIN_IMAGE_SIDE or image_bgr.shape[1] < MIN_IMAGE_SIDE:
        raise ValueError(f"image too small: {image_bgr.shape[1]}x{image_bgr.shape[0]}")
    return image_bgr


def quarter_sample(image_bgr: np.ndarray) -> np.ndarray:
    """The frame's 1/4-size nearest-neighbour sample."""
    height, width = image_bgr.shape[:2]
    return cv2.resize(image_bgr, (max(1, width // 4), max(1, height // 4)), interpolation=cv2.INTER_NEAREST)


def reference_level(image_bgr: np.ndarray, value: np.ndarray | None = None) -> float:
    """The frame's bright level: 99th percentile of V over 3x3 areas (of the sample), but at
    most 3x its median.

    The cap keeps a small bright area (the sky above a dimly lit floor, a lamp) from
    setting the level of a dark frame. Measured on a 1/4-size nearest-neighbour sample
    (``value``: the V plane of the frame's ``quarter_sample`` when already made).
    """
    if value is None:
        small = quarter_sample(image_bgr)
        value = brightest_channel(small)
    last = value.size - 1
    median = ranked_value(value, last // 2)
    # The bright level of areas, not of single pixels: isolated glints, hot pixels and
    # salt noise would otherwise make every colour in the frame look dull.
    bright = ranked_value(cv2.erode(value, AREA_KERNEL), int(0.99 * last))
    return float(max(1.0, min(float(bright), 3.0 * float(median))))


def ranked_value(plane: np.ndarray, rank: int) -> int:
    """The ``rank``-th smallest value (from 0) of a uint8 plane: ``np.partition``'s, read from
    the plane's histogram (~30 against ~55 us on a 160x120 sample)."""
    counts = np.cumsum(cv2.calcHist([plane], [0], None, [256], [0, 256]).ravel().astype(np.int64))
    return int(np.searchsorted(counts, rank, side="right"))


def brighten(image_bgr: np.ndarray, gain: float, small: np.ndarray) -> np.ndarray:
    """``image_bgr`` times ``gain``, keeping each pixel's colour: a pixel whose brightest
    channel would pass 255 is scaled only up to 255.

    The gain of a dark frame is set by its dark surroundings; clipping each channel alone would
    turn a brightly lit ball in it white (yellow-green's red and green both clip), and its
    hue and saturation are what the colour mask reads. ``small``: the frame's
    ``quarter_sample``, whose brightest pixel tells whether anything may clip.
    """
    gained = cv2.convertScaleAbs(image_bgr, alpha=gain)
    if float(small.max()) * gain <= 255.0:
        return gained
    # (contiguous, as ``gained`` is: one compiled signature whatever the caller's frame is)
    scale_to_white(np.ascontiguousarray(image_bgr), gained, 255.0 / gain)
    return gained


@compiled
def scale_to_white(image_bgr: np.ndarray, gained: np.ndarray, limit: float) -> None:
    """``brighten``'s clipping pixels, in place in ``gained``: each pixel of ``image_bgr``
    whose brightest channel is above ``limit`` scaled (in float32) until that channel is 255.
    (Numpy's indexing of those pixels took ~4 ms on a dark 640x480 photo with a bright sky.)"""
    white = np.float32(255.0)
    for row in range(image_bgr.shape[0]):
        for column in range(image_bgr.shape[1]):
            blue = image_bgr[row, column, 0]
            green = image_bgr[row, column, 1]
            red = image_bgr[row, column, 2]
            value = max(blue, green, red)
            if value > limit:
                scale = white / np.float32(value)
                gained[row, column, 0] = np.uint8(np.rint(np.float32(blue) * scale))
                gained[row, column, 1] = np.uint8(np.rint(np.float32(green) * scale))
                gained[row, column, 2] = np.uint8(np.rint(np.float32(red) * scale))


def frame_gain(reference: float, config: DetectorConfig) -> float:
    """The dark-frame gain that brings ``reference`` up to gain_target (1 = none)."""
    if config.max_gain > 1.0:
        return float(min(config.max_gain, max(1.0, config.gain_target / reference)))
    return 1.0


class ColourMasker:
    """Builds the colour planes of frames for one configuration.

    Holds an OpenCV CLAHE object, which is not meant to be shared between threads.
    """

    def __init__(self, config: DetectorConfig):
        self.config = config
        self._clahe = (cv2.createCLAHE(clipLimit=config.clahe_clip_limit,
                                       tileGridSize=(config.clahe_tile_grid, config.clahe_tile_grid))
                       if config.clahe_clip_limit > 0 else None)
        self._open_kernel = ellipse_kernel(config.open_kernel)
        self._close_kernel = ellipse_kernel(config.close_kernel)
        self._coarse_hue = coarse_hue_table(config)
        # (its tile grid changes with the part of the frame it equalises)
        self._part_clahe = (cv2.createCLAHE(clipLimit=config.clahe_clip_limit)
                            if config.clahe_clip_limit > 0 else None)

    def planes(self, image_bgr: np.ndarray, boxes: list[Box] | None = None, whole: bool = False) -> ColourPlanes:
        """The cleaned colour mask of a checked BGR frame, with the planes the checks read.
        ``boxes``: the regions of interest to compute the mask in, in place of those the coarse
        search finds (see ``BallDetector.detect``); ``whole``: the frame done whole, never by
        regions (with the pale plane when that pass is on)."""
        config = self.config
        small = quarter_sample(image_bgr)
        # (the sample's HSV serves the reference level, its V, and the regions' coarse search)
        small_hsv = cv2.cvtColor(small, cv2.COLOR_BGR2HSV)
        reference = reference_level(image_bgr, cv2.extractChannel(small_hsv, 2))
        gain = frame_gain(reference, config)
        # Dark frames are scaled up before the blur, so that the blur's averaging keeps the
        # sub-unit colour information that uint8 rounding would otherwise destroy.
        gained = brighten(image_bgr, gain, small) if gain > 1.0 else image_bgr
        # Extremely dark frames (gain of at least dark_gain): the colour is only a grey level
        # or two above black, so single pixels' hue and chroma are rounding noise; colour is
        # classified on wider averages instead (dark_blur_kernel), with its own chroma floor,
        # and no opening (the averaged mask has no specks, and a small lit cap would not
        # survive it).
        dark = config.dark_gain > 0 and gain >= config.dark_gain
        if not dark and not whole and regions_apply(gained.shape):
            # (nearest-neighbour sampling commutes with the per-pixel gain: the regions' coarse
            # search reads the same sample of the gained frame)
            if gain > 1.0:
                small_hsv = cv2.cvtColor(brighten(small, gain, small), cv2.COLOR_BGR2HSV)
            # (a frame that may hold a washed-out ball is done whole: see pale_in_sample)
            found = None if boxes is None and pale_in_sample(
                small_hsv, self._coarse_hue, config, PALE_SAMPLE_BRIGHTNESS * min(255.0, reference * gain)
            ) else self._mask_in_regions(gained, gain, small_hsv, boxes)
            if found is not None:
                return ColourPlanes(mask=found[0], frame=gained, gain=gain, chroma=found[1],
                                    reference=min(255.0, reference * gain), dark=dark, extent=found[2])
        kernel = config.dark_blur_kernel if dark else config.blur_kernel
        min_chroma = config.dark_min_chroma if dark else config.min_chroma
        mask, chroma, pale = self._colour_mask(gained, gain, kernel, min_chroma, opening=not dark,
                                               with_pale=not dark)
        return ColourPlanes(mask=mask, frame=gained, gain=gain, chroma=chroma,
                            reference=min(255.0, reference * gain), dark=dark, pale=pale)

    def _colour_mask(self, gained: np.ndarray, gain: float, kernel: int, min_chroma: float,
                     opening: bool, equalised: np.ndarray | None = None, with_pale: bool = False
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """Steps 2-4 on ``gained`` (a frame or a part of one): the cleaned mask, the chroma and,
        ``with_pale``, the pale plane (see ColourPlanes; None without, or when the pass is off).
        ``equalised``: the CLAHE-equalised value plane of the part, None to equalise its own."""
        config = self.config
        hsv = cv2.cvtColor(gaussian_blur(gained, kernel), cv2.COLOR_BGR2HSV)
        # (three extractChannel calls are several times faster than one cv2.split here)
        hue, saturation, value = (cv2.extractChannel(hsv, channel) for channel in range(3))
        # Adaptive histogram equalisation: v_min/v_max apply to locally normalised brightness,
        # so a ball in a shadow keeps its dark side in the mask.
        if equalised is None:
            equalised = self.equalise(value, gained)

        in_hue = hue_mask(hue, config)
        pale = None
        if with_pale and config.pale_pass:
            pale = in_hue & cv2.inRange(saturation, config.pale_s_min, config.s_min - 1)
        mask = in_hue & cv2.inRange(saturation, config.s_min, config.s_max)
        mask &= cv2.inRange(equalised, config.v_min, config.v_max)
        # chroma (max - min channel) = S * V / 255; raw units are these over the gain
        chroma = cv2.multiply(saturation, value, scale=1.0 / 255.0)
        if min_chroma > 0:
            mask &= cv2.inRange(chroma, min(255, math.ceil(min_chroma * gain - 0.5)), 255)
        if self._open_kernel is not None and opening:
            mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, self._open_kernel)
        if self._close_kernel is not None:
            mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, self._close_kernel)
        return mask, chroma, pale

    def _mask_in_regions(self, gained: np.ndarray, gain: float, sample_hsv: np.ndarray | None = None,
                         boxes: list[Box] | None = None
                         ) -> tuple[np.ndarray, np.ndarray, tuple[int, int, int, int]] | None:
        """Steps 2-4 only in boxes around what may be ball-coloured (see ``regions.py``), each
        grown until no mask blob crosses its edge: the mask and chroma, zero elsewhere, and the
        bounding box of the boxes; None (do the whole frame) when the boxes would cover too
        much of it. ``sample_hsv``: the HSV of the gained frame's ``quarter_sample`` when
        already made; ``boxes``: the boxes to start from instead of the coarse search's."""
        config = self.config
        height, width = gained.shape[:2]
        pending = boxes if boxes is not None else coarse_boxes(gained, self._coarse_hue, config, sample_hsv)
        if pending is None:
            return None
        mask = np.zeros((height, width), np.uint8)
        chroma = np.zeros((height, width), np.uint8)
        equaliser = (PartEqualiser(self._part_clahe, config.clahe_tile_grid, gained)
                     if self._part_clahe is not None else None)
        done = 0
        extent = (width, height, 0, 0)
        for _round in range(MAX_REGION_ROUNDS):
            grown = []
            for box in pending:
                left, top, right, bottom = box
                done += (right - left) * (bottom - top)
                extent = (min(extent[0], left), min(extent[1], top), max(extent[2], right),
                          max(extent[3], bottom))
                if done > MAX_REGION_SHARE * width * height:
                    return None
                window = compute_window(box, width, height)
                part_equalised = None  # (without CLAHE, each part's own value plane)
                if equaliser is not None:
                    span = source_span(*window, height // 2, width // 2)
                    part_equalised = doubled_part(equaliser.part(*span), span, *window)
                part_mask, part_chroma, _ = self._colour_mask(
                    gained[window], gain, config.blur_kernel, config.min_chroma, opening=True,
                    equalised=part_equalised)
                inner = (slice(top - window[0].start, bottom - window[0].start),
                         slice(left - window[1].start, right - window[1].start))
                piece = part_mask[inner]
                mask[top:bottom, left:right] |= piece
                chroma[top:bottom, left:right] = part_chroma[inner]
                larger = grown_box(box, piece, width, height)
                if larger is not None:
                    grown.append(larger)
            if not grown:
                return mask, chroma, extent
            pending = grown
        return None

    def equalise(self, value: np.ndarray, frame: np.ndarray) -> np.ndarray:
        """CLAHE of the value channel of ``frame`` (``value``, of its blurred copy); for frames
        wider than 320 px, of its half-size value plane (``regions.half_value``), scaled back up.

        The result only feeds the v_min/v_max test, which needs local brightness, not detail,
        and CLAHE is the costliest step of the colour mask at full size.
        """
        if self._clahe is None:
            return value
        height, width = value.shape
        if width <= 320 or height < 64:
            return self._clahe.apply(value)
        return cv2.resize(self._clahe.apply(half_value(frame)), (width, height), interpolation=cv2.INTER_LINEAR)
