"""The colour mask's hue and saturation range fitted to balls marked on a user's own frames.

The default range (``h_min``-``h_max`` 25-50, ``s_min`` 80) is that of a yellow-green tennis
ball under white light. Another ball (orange, red, blue), a camera with another white balance,
or a lamp's colour needs another range, and guessing it from a colour picker is slow. Given
frames and where the balls are in them, the range is read off the balls' own pixels:

- the pixels are those the mask would classify: the frame at the detector's work size, blurred
  by ``blur_kernel``, in HSV; of each ball, the disc of BALL_DISC of its radius (its rim mixes
  with the background);
- pixels below FIT_SATURATION (a seam, a logo, a highlight) or ``min_chroma`` (grey: their hue is
  noise) do not shape the range;
- the hue range leaves HUE_TAIL of those pixels out at each end, on the hue circle (a red
  ball's range wraps through 0, ``h_min > h_max``), and keeps ``hue_margin`` and a unit more
  on each side of their median hue and of the balls' own mean colours (HUE_TAIL of the balls
  left out at each end): a candidate's mean colour must lie ``hue_margin`` inside the range
  (``checks.judge``), and a ball in one frame's light may have a cast that puts its mean near
  the pixels' tail; ``s_min`` leaves SATURATION_TAIL out below.

The fit says how much of the balls' pixels (all of their discs) each range admits, and how much
of the frames' other pixels: a range that admits the floor, the walls or the plants gives the
detector clutter to reject (see ``failed_checks``), and one that misses the balls' shaded side
loses them. The value test (``v_min``, on CLAHE-equalised brightness, relative to the frame) is
not fitted. Arrays in, a ``ColourFit`` out; ``balltrack fit-colour`` is the command.
"""

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from balltrack.services.detector.measure import mean_hue
from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.detector import BallDetector
from balltrack.services.detector.geometry import gaussian_blur

# Of a ball, the disc of this share of its radius is sampled.
BALL_DISC = 0.8
# Around each ball, what lies within this share of its radius (and OTHER_MARGIN px) is neither
# ball nor background: its rim, its shadow, a box drawn a little small.
OTHER_CLEARANCE = 1.3
OTHER_MARGIN = 3
# The background is sampled on every this many pixels each way (a frame's worth of pixels is
# far more than its statistics need).
OTHER_STEP = 4
# Pixels below this saturation do not shape the range (the seam, logos, a washed-out highlight).
FIT_SATURATION = 30
# Shares of the shaping pixels left out at each end of the hue range and below s_min.
HUE_TAIL = 0.025
SATURATION_TAIL = 0.05
# Fewer shaping pixels than this are no basis for a range, and of one ball no basis for its
# mean colour.
MIN_PIXELS = 50
MIN_BALL_PIXELS = 10
# Balls of a smaller radius (px, in the input frame) are skipped: their discs are mostly rim.
MIN_RADIUS = 4.0
# A hue spread wider than this (OpenCV hue units, of 180) is not one colour.
MAX_HUE_WIDTH = 90


@dataclass(frozen=True)
class ColourSamples:
    """Pixels of marked balls' discs and of the rest of frames, HSV (N x 3, uint8) as the colour
    mask sees them, and each ball's mean colour."""

    ball: np.ndarray
    other: np.ndarray
    # per ball with at least MIN_BALL_PIXELS shaping pixels: the hue (0-180) of their mean colour
    # in the unblurred frame, as ``measure.colour_stats`` reads a candidate's
    ball_hues: list[float] = field(default_factory=list)
    balls: int = 0  # balls sampled

    @staticmethod
    def joined(samples: "list[ColourSamples]") -> "ColourSamples":
        """The samples of several frames as one."""
        empty = np.zeros((0, 3), np.uint8)
        return ColourSamples(ball=np.concatenate([sample.ball for sample in samples] or [empty]),
                             other=np.concatenate([sample.other for sample in samples] or [empty]),
                             ball_hues=[hue for sample in samples for hue in sample.ball_hues],
                             balls=sum(sample.balls for sample in samples))


@dataclass(frozen=True)
class ColourFit:
    """A fitted range, and what it and the configured one admit (shares 0-1)."""

    h_min: int
    h_max: int
    s_min: int
    balls: int                 # balls sampled
    ball_pixels: int           # pixels of their discs
    ball_admitted: float       # share of those the fitted range admits
    ball_admitted_before: float  # ... and the configured range
    other_pixels: int          # background pixels sampled
    other_admitted: float
    other_admitted_before: float

    def changes(self) -> dict[str, int]:
        """The detector parameters the fit sets."""
        return {"h_min": self.h_min, "h_max": self.h_max, "s_min": self.s_min}


def colour_samples(image_bgr: np.ndarray, circles: list[tuple[float, float, float]],
                   config: DetectorConfig) -> ColourSamples:
    """The pixels of the balls' discs and of the rest of one frame, and each ball's mean colour;
    ``circles``: (u, v, radius) of each ball in pixels of ``image_bgr`` (those under MIN_RADIUS
    are skipped)."""
    height, width = image_bgr.shape[:2]
    scale = scale_y = 1.0
    work = image_bgr
    work_size = BallDetector(config).work_size(width, height)
    if work_size is not None:
        scale, scale_y = work_size[0] / width, work_size[1] / height
        work = cv2.resize(image_bgr, work_size, interpolation=cv2.INTER_AREA)
    hsv = cv2.cvtColor(gaussian_blur(work, config.blur_kernel), cv2.COLOR_BGR2HSV)
    work_height, work_width = hsv.shape[:2]
    ball = np.zeros((work_height, work_width), np.uint8)
    near = np.zeros((work_height, work_width), np.uint8)
    hues, balls = [], 0
    for u, v, radius in circles:
        if radius < MIN_RADIUS:
            continue
        balls += 1
        # (whole coordinates are pixel centres: see detector.in_input_frame)
        centre_x, centre_y = int(round((u + 0.5) * scale - 0.5)), int(round((v + 0.5) * scale_y - 0.5))
        cv2.circle(near, (centre_x, centre_y), int(math.ceil(OTHER_CLEARANCE * radius * scale + OTHER_MARGIN)),
                   255, -1)
        # The disc, drawn in the box around it: the ball's own pixels give its mean colour.
        disc_radius = max(1, int(BALL_DISC * radius * scale))
        top, left = max(0, centre_y - disc_radius), max(0, centre_x - disc_radius)
        box = (slice(top, max(top, min(work_height, centre_y + disc_radius + 1))),
               slice(left, max(left, min(work_width, centre_x + disc_radius + 1))))
        disc = np.zeros(ball[box].shape, np.uint8)
        cv2.circle(disc, (centre_x - left, centre_y - top), disc_radius, 255, -1)
        ball[box] |= disc
        inside = disc > 0
        shaping = shaping_pixels(hsv[box][inside], config)
        if np.count_nonzero(shaping) >= MIN_BALL_PIXELS:
            hue = mean_hue(work[box][inside][shaping].mean(axis=0))
            if hue >= 0:  # (not grey)
                hues.append(hue)
    background = np.zeros_like(near)
    background[::OTHER_STEP, ::OTHER_STEP] = 255
    background[near > 0] = 0
    return ColourSamples(ball=hsv[ball > 0], other=hsv[background > 0], ball_hues=hues, balls=balls)


def shaping_pixels(hsv: np.ndarray, config: DetectorConfig) -> np.ndarray:
    """Which of the HSV pixels (N x 3) shape the range: coloured (FIT_SATURATION) and not grey."""
    return (hsv[:, 1] >= FIT_SATURATION) & chroma_passes(hsv, config.min_chroma)


def admitted(hsv: np.ndarray, h_min: int, h_max: int, s_min: int, s_max: int, min_chroma: float) -> np.ndarray:
    """Which of the HSV pixels (N x 3) pass the hue, saturation and chroma tests of a range."""
    hue, saturation = hsv[:, 0].astype(np.int32), hsv[:, 1].astype(np.int32)
    in_hue = (hue >= h_min) & (hue <= h_max) if h_min <= h_max else (hue >= h_min) | (hue <= h_max)
    return in_hue & (saturation >= s_min) & (saturation <= s_max) & chroma_passes(hsv, min_chroma)


def chroma_passes(hsv: np.ndarray, min_chroma: float) -> np.ndarray:
    """Which of the HSV pixels (N x 3) pass the mask's chroma floor, as the mask tests it: chroma
    (max - min channel) is S * V / 255 rounded to a whole unit, at least ``min_chroma`` rounded."""
    chroma = np.rint(hsv[:, 1].astype(np.float64) * hsv[:, 2] / 255.0)
    return chroma >= max(0, math.ceil(min_chroma - 0.5))


def fit_colour(samples: ColourSamples, config: DetectorConfig) -> ColourFit:
    """The hue and saturation range of the balls' pixels and what it and ``config``'s range admit
    of them and of the background; ValueError with a one-line reason when the pixels hold no
    single colour."""
    if not samples.balls:
        raise ValueError(f"no marked ball to fit (balls of radius under {MIN_RADIUS:g} px are skipped)")
    ball, other = samples.ball, samples.other
    hue = ball[:, 0].astype(np.float64)
    saturation = ball[:, 1].astype(np.float64)
    shaping = shaping_pixels(ball, config)
    if np.count_nonzero(shaping) < MIN_PIXELS:
        raise ValueError(f"only {np.count_nonzero(shaping)} of the balls' {len(ball)} pixels are coloured "
                         f"(saturation >= {FIT_SATURATION}); at least {MIN_PIXELS} are needed")
    # On the hue circle (180 units): deviations from the circular mean, then from their median.
    angles = hue[shaping] * (2.0 * math.pi / 180.0)
    centre = math.atan2(float(np.sin(angles).mean()), float(np.cos(angles).mean())) * 180.0 / (2.0 * math.pi)
    deviation = (hue[shaping] - centre + 90.0) % 180.0 - 90.0
    centre += float(np.median(deviation))
    deviation = (hue[shaping] - centre + 90.0) % 180.0 - 90.0
    low, high = np.quantile(deviation, [HUE_TAIL, 1.0 - HUE_TAIL])
    # A candidate's mean colour must lie hue_margin inside the range (checks.judge): the balls'
    # central hue, and each ball's mean colour, keep that much room and a unit more, however
    # evenly coloured they are.
    room = config.hue_margin + 1.0
    low, high = min(low, -room), max(high, room)
    if samples.ball_hues:  # (HUE_TAIL of the balls left out at each end, as of the pixels)
        offsets = (np.asarray(samples.ball_hues) - centre + 90.0) % 180.0 - 90.0
        lowest, highest = np.quantile(offsets, [HUE_TAIL, 1.0 - HUE_TAIL])
        low, high = min(low, lowest - room), max(high, highest + room)
    if high - low > MAX_HUE_WIDTH:
        raise ValueError(f"the balls' hues spread over {high - low:.0f} of 180 units: not one colour "
                         "(are the boxes on the balls?)")
    h_min = int(math.floor(centre + low)) % 180
    h_max = int(math.ceil(centre + high)) % 180
    in_hue = (deviation >= low) & (deviation <= high)
    s_min = max(FIT_SATURATION, int(math.floor(np.quantile(saturation[shaping][in_hue], SATURATION_TAIL))))
    s_min = min(s_min, config.s_max)

    def share(pixels: np.ndarray, low_hue: int, high_hue: int, low_saturation: int) -> float:
        if not len(pixels):
            return 0.0
        passing = admitted(pixels, low_hue, high_hue, low_saturation, config.s_max, config.min_chroma)
        return float(np.count_nonzero(passing)) / len(pixels)

    return ColourFit(h_min=h_min, h_max=h_max, s_min=s_min, balls=samples.balls, ball_pixels=len(ball),
                     ball_admitted=share(ball, h_min, h_max, s_min),
                     ball_admitted_before=share(ball, config.h_min, config.h_max, config.s_min),
                     other_pixels=len(other),
                     other_admitted=share(other, h_min, h_max, s_min),
                     other_admitted_before=share(other, config.h_min, config.h_max, config.s_min))
