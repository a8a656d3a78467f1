"""Parameters of the ball detector: the paper's HSV and Hough settings plus the extra checks.

Names of the colour and Hough parameters follow the paper and the ROS2 ball_tracker package
(``h_min h_max s_min s_max v_min v_max``, ``dp min_dist param1 param2 min_radius max_radius``);
the rest are this implementation's preprocessing and candidate checks. Defaults find a tennis
ball (yellow-green, radius 0.033 m) in real photos and in simulated renders, bright or dark.

Example::

    balltrack run detector --set h_min=22 --set param2=18
"""

import enum
from dataclasses import dataclass

from balltrack.common.config import ConfigError, check_fields, param


class Method(enum.StrEnum):
    """How candidates are judged: by the hand-written checks (``detector.py``) or by the network
    trained in the simulator (``learned.py``)."""

    rules = "rules"
    learned = "learned"


@dataclass
class DetectorConfig:
    """Every knob of :class:`services.detector.detector.BallDetector`.

    Colour: OpenCV HSV ranges (H 0-179, S and V 0-255). V is tested after brightness
    normalisation (global gain, then CLAHE), so ``v_min``/``v_max`` are relative to the frame,
    not absolute pixel values.
    """

    method: Method = param(Method.rules, "how balls are told from the rest: rules (the hand-written checks) or "
                                         "learned (the network trained on simulator renders, models/ball_network.onnx)")

    # HSV colour range of the target. Tennis-ball felt measures H 29-44 (5th-95th percentile)
    # in sun and shade, S mostly above 150 (less in highlights); 25 keeps orange (H <= ~20)
    # out, 50 keeps pure green (H ~60) and blue out while allowing the bluer light of shade.
    h_min: int = param(25, "lowest hue (OpenCV H, 0-179); `h_min > h_max` wraps through 0 (red targets)",
                       low=0, high=179)
    h_max: int = param(50, "highest hue", low=0, high=179)
    s_min: int = param(80, "lowest saturation (0-255)", low=0, high=255)
    s_max: int = param(255, "highest saturation", low=0, high=255)
    v_min: int = param(40, "lowest value, after brightness normalisation (relative to the frame)",
                       low=0, high=255)
    v_max: int = param(255, "highest value", low=0, high=255)

    # Hough circle transform (cv2.HOUGH_GRADIENT on the smoothed colour mask, inside each blob
    # that is not already one clean ball), radii in pixels of the input frame.
    dp: float = param(1.0, "Hough: inverse accumulator resolution (1 = the image's)", low=1)
    min_dist: float = param(8.0, "Hough: smallest distance between circle centres (px)", above=0)
    param1: float = param(100.0, "Hough: upper Canny threshold", above=0)
    param2: float = param(20.0, "Hough: accumulator threshold (lower finds more, and more false, circles)",
                          above=0)
    # min_radius bounds the reported radius too (the outline's): a tennis ball 5 m away from
    # the 640 px, 1.089 rad camera is ~3.5 px.
    min_radius: int = param(3, "smallest ball radius (px)", low=1)
    max_radius: int = param(0, "largest ball radius (px); 0 = half the frame's shorter side", low=0)
    # A few pixels of yellow-green prove little.
    small_radius: int = param(5, "balls smaller than this (px) are kept only when their outline is found "
                                 "on the frame; a ball cut by the frame edge must show at least this much rim",
                              low=1)

    # Preprocessing.
    blur_kernel: int = param(5, "Gaussian blur kernel (odd px); 1 = no blur", low=1)
    clahe_clip_limit: float = param(2.0, "CLAHE contrast limit on V; 0 = no CLAHE", low=0)
    clahe_tile_grid: int = param(8, "CLAHE tiles per side", low=1)
    # The frame's reference level is the 99th percentile of V (of small areas, not single
    # pixels), at most 3x its median. Hue and saturation do not depend on the gain; it keeps the
    # blur precise and V comparable.
    gain_target: float = param(100.0, "dark frames are brightened until their reference level reaches "
                                      "this (0-255)", low=1, high=255)
    max_gain: float = param(64.0, "largest brightening factor; 1 = off", low=1)
    # A noiseless render of a ball under a 0.01 diffuse light and no ambient has a chroma of
    # 1-2 units on its lit side, and a grey floor has 0; raise it for noisy dark cameras.
    min_chroma: float = param(1.5, "smallest max-min channel difference whose hue is trusted (grey pixels "
                                   "are ignored)", low=0)
    # A ball under a 0.01 diffuse light and no ambient is 1-2 grey levels above black: its lit
    # cap averages a chroma of 1.2-2, a dim orange box or grey floor less (or a hue out of range).
    dark_gain: float = param(32.0, "frame gain at or above which a frame counts as pitch dark (0 = never): "
                                   "colour is then classified on averaged values and the mask is not opened",
                             low=1, off=0)
    dark_blur_kernel: int = param(9, "Gaussian blur (odd px) that averages colour in pitch-dark frames", low=1)
    dark_min_chroma: float = param(1.2, "chroma floor (raw units) of a ball pixel in pitch-dark frames", low=0)
    # Elliptic kernels.
    open_kernel: int = param(3, "morphological opening of the mask (px); 0 or 1 = skip", low=0)
    close_kernel: int = param(5, "morphological closing of the mask (px); 0 or 1 = skip", low=0)

    # Checks on each candidate circle. A two-colour ball shows ~half its rim as a mask edge; the
    # ring outside is 1.15-1.45 r (touching balls, clutter).
    min_fill_ratio: float = param(0.55, "smallest mask fraction inside a candidate circle", low=0, high=1)
    min_edge_support: float = param(0.4, "smallest fraction of the rim that is a mask edge", low=0, high=1)
    max_outside_ratio: float = param(0.3, "largest mask fraction in the ring just outside the circle",
                                     low=0, high=1)
    min_visible_fraction: float = param(0.25, "smallest fraction of the rim inside the frame (balls cut by "
                                              "the edge)", low=0, high=1)
    min_score: float = param(0.5, "smallest final score of a detection", low=0, high=1)
    # Chroma is max - min channel, the reference level as for gain_target. Fluorescent felt is
    # vivid; leaves in shade, pale dry leaves and sunlit trees are duller, whatever their hue.
    min_colourfulness: float = param(0.28, "smallest mean chroma of a candidate over the frame's reference "
                                           "level", low=0, high=1)
    # Single pixels' hues spread over the whole range (shading, highlights, JPEG, reflected
    # light), but the mean colour of a ball's disc is its felt's: tennis balls measure H 28-44
    # (5th-95th percentile) on the real dev photos, while wood, skin, lamps and orange light
    # sit at the range's orange end.
    hue_margin: float = param(3.0, "the mean colour of a candidate's colour-mask pixels must lie this far "
                                   "inside the hue range (OpenCV H units), unless its shape alone makes it "
                                   "plainly a ball", low=0, high=45)
    # In direct sun a ball's felt washes out to saturation 20-60 (S 39-52 on the floor set's
    # sunlit concrete) while grey concrete stays under ~15; such a ball is kept only when its
    # shape, its hue and its contrast with what is around it make it plainly one (see pale.py).
    pale_s_min: int = param(20, "lowest saturation of a washed-out ball, kept only when round, alone, brightly "
                                "lit and far more colourful than its surroundings; 0 (or s_min and above) = off",
                            low=0, high=255)
    # A court or floor strewn with balls shows a few dozen at once (up to 30 in the floor photos).
    max_detections: int = param(32, "most balls reported per frame (largest first)", low=1)

    # Shrinking is for speed.
    work_width: int = param(640, "wider frames are shrunk to this before processing (px); 0 = full size",
                            low=64, off=0)
    # A frame makes dozens of small OpenCV calls, each of which wakes the pool's other threads:
    # on frames the demo's size that costs about what the second thread saves, and one thread
    # leaves the other cores to the camera and Zenoh.
    threads: int = param(1, "OpenCV threads of the detector service's process (cv2.setNumThreads); "
                            "0 = OpenCV's default, one per core", low=0, high=64)

    @property
    def pale_pass(self) -> bool:
        """Whether washed-out balls are looked for (see pale_s_min)."""
        return 0 < self.pale_s_min < self.s_min

    def __post_init__(self) -> None:
        check_fields(self)
        if self.s_min > self.s_max:
            raise ConfigError(f"s_max: must be >= s_min ({self.s_min}), got {self.s_max}")
        if self.v_min > self.v_max:
            raise ConfigError(f"v_max: must be >= v_min ({self.v_min}), got {self.v_max}")
        if self.max_radius and self.max_radius <= self.min_radius:
            raise ConfigError(
                f"max_radius: must be > min_radius ({self.min_radius}) or 0, got {self.max_radius}")
        for name in ("blur_kernel", "dark_blur_kernel"):
            if getattr(self, name) % 2 == 0:
                raise ConfigError(f"{name}: must be odd (a centred kernel), got {getattr(self, name)}")
