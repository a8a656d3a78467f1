"""Parameters of the ball detector: the paper's HSV and Hough settings plus the extra checks.

Names of the colour and Hough parameters follow the paper and the ROS2 ball_tracker package
(``h_min h_max s_min s_max v_min v_max``, ``dp min_dist param1 param2 min_radius max_radius``);
the rest are this implementation's preprocessing and candidate checks. Defaults find a tennis
ball (yellow-green, radius 0.033 m) in real photos and in simulated renders, bright or dark.

Example::

    python -m services.detector --set h_min=22 --set param2=18
"""

import dataclasses
import math
from dataclasses import dataclass

from balltrack.common.config import ConfigError


def _check_range(name: str, value: float, low: float, high: float) -> None:
    if not (low <= value <= high):
        raise ConfigError(f"{name}: must be in [{low}, {high}], got {value}")


def _check_positive(name: str, value: float) -> None:
    if not (math.isfinite(value) and value > 0):
        raise ConfigError(f"{name}: must be > 0, got {value}")


@dataclass
class DetectorConfig:
    """Every knob of :class:`services.detector.detector.BallDetector`.

    Colour: OpenCV HSV ranges (H 0-179, S and V 0-255). ``h_min > h_max`` means a range that
    wraps through 0 (for red targets). V is tested after brightness normalisation (global gain,
    then CLAHE), so ``v_min``/``v_max`` are relative to the frame, not absolute pixel values.
    """

    # HSV colour range of the target. Tennis-ball felt measures H 29-44 (5th-95th percentile)
    # in sun and shade, S mostly above 150 (less in highlights); 25 keeps orange (H <= ~20)
    # out, 50 keeps pure green (H ~60) and blue out while allowing the bluer light of shade.
    h_min: int = 25
    h_max: int = 50
    s_min: int = 80
    s_max: int = 255
    v_min: int = 40
    v_max: int = 255

    # Hough circle transform (cv2.HOUGH_GRADIENT on the smoothed colour mask, inside each blob
    # that is not already one clean ball), radii in pixels of the input frame. param2 is the
    # accumulator threshold. max_radius = 0: no limit but half the frame's shorter side.
    # min_radius bounds the reported radius too (the outline's): a tennis ball 5 m away from
    # the 640 px, 1.089 rad camera is ~3.5 px.
    dp: float = 1.0
    min_dist: float = 8.0
    param1: float = 100.0
    param2: float = 20.0
    min_radius: int = 3
    max_radius: int = 0
    # Balls smaller than this (pixels) must be whole and have their outline found on the frame,
    # and a ball cut by the frame edge must show at least as much rim as a whole ball of this
    # radius has: a few pixels of yellow-green prove little.
    small_radius: int = 5

    # Preprocessing. blur_kernel 1 = no blur; clahe_clip_limit 0 = no CLAHE.
    blur_kernel: int = 5
    clahe_clip_limit: float = 2.0
    clahe_tile_grid: int = 8
    # Brightness normalisation of dark frames: the frame's reference level (99th percentile
    # of V, at most 3x its median) is scaled up to gain_target, by at most max_gain (1 = off).
    # Hue and saturation do not depend on it; it keeps the blur precise and V comparable.
    gain_target: float = 100.0
    max_gain: float = 64.0
    # Smallest max-min channel difference (raw pixel units, after blur) whose hue is trusted.
    # A noiseless render of a ball under a 0.01 diffuse light and no ambient has a chroma of
    # 1-2 units on its lit side, and a grey floor has 0; raise it for noisy dark cameras.
    min_chroma: float = 1.5
    # Extremely dark frames: at a gain of at least dark_gain (0 = never) the colour is
    # classified on a wider average (Gaussian blur of dark_blur_kernel px, odd) against a
    # chroma floor of dark_min_chroma raw units, and the mask is not opened. A ball under a
    # 0.01 diffuse light and no ambient is 1-2 grey levels above black: its lit cap averages
    # a chroma of 1.2-2, a dim orange box or grey floor less (or a hue out of range).
    dark_gain: float = 32.0
    dark_blur_kernel: int = 9
    dark_min_chroma: float = 1.2
    # Morphological clean-up of the mask (elliptic kernels, pixels; 0 or 1 = skip).
    open_kernel: int = 3
    close_kernel: int = 5

    # Checks on each candidate circle (all ratios 0-1): mask fraction of the disc; fraction of
    # the rim that is a mask edge (a two-colour ball shows ~half), plus the mask fraction just
    # around the circle (touching balls, clutter); mask fraction of the ring 1.15-1.45 r; rim
    # fraction inside the frame (a ball cut by the edge); the final score.
    min_fill_ratio: float = 0.55
    min_edge_support: float = 0.4
    max_outside_ratio: float = 0.3
    min_visible_fraction: float = 0.25
    min_score: float = 0.5
    # Colourfulness of a candidate: the mean chroma (max - min channel) of its mask pixels over
    # the frame's reference level (see gain_target). Fluorescent felt is vivid; leaves in shade,
    # pale dry leaves and sunlit trees are duller, whatever their hue.
    min_colourfulness: float = 0.28
    max_detections: int = 16

    # Frames wider than this are shrunk before processing (speed); 0 = always full size.
    work_width: int = 640

    def __post_init__(self) -> None:
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if field.type is int and (isinstance(value, bool) or not isinstance(value, int)):
                raise ConfigError(f"{field.name}: must be an integer, got {value!r}")
            if field.type is float:
                if isinstance(value, bool) or not isinstance(value, (int, float)):
                    raise ConfigError(f"{field.name}: must be a number, got {value!r}")
                if not math.isfinite(value):
                    raise ConfigError(f"{field.name}: must be finite, got {value!r}")
        for name in ("h_min", "h_max"):
            _check_range(name, getattr(self, name), 0, 179)
        for name in ("s_min", "s_max", "v_min", "v_max"):
            _check_range(name, getattr(self, name), 0, 255)
        if self.s_min > self.s_max:
            raise ConfigError(f"s_max: must be >= s_min ({self.s_min}), got {self.s_max}")
        if self.v_min > self.v_max:
            raise ConfigError(f"v_max: must be >= v_min ({self.v_min}), got {self.v_max}")

        if not (math.isfinite(self.dp) and self.dp >= 1.0):
            raise ConfigError(f"dp: must be >= 1, got {self.dp}")
        for name in ("min_dist", "param1", "param2", "clahe_tile_grid"):
            _check_positive(name, getattr(self, name))
        if self.min_radius < 1:
            raise ConfigError(f"min_radius: must be >= 1, got {self.min_radius}")
        if self.small_radius < 1:
            raise ConfigError(f"small_radius: must be >= 1, got {self.small_radius}")
        if self.max_radius < 0:
            raise ConfigError(f"max_radius: must be >= 0 (0 = no limit), got {self.max_radius}")
        if self.max_radius and self.max_radius <= self.min_radius:
            raise ConfigError(
                f"max_radius: must be > min_radius ({self.min_radius}) or 0, got {self.max_radius}")

        if self.blur_kernel < 1 or self.blur_kernel % 2 == 0:
            raise ConfigError(f"blur_kernel: must be an odd number >= 1, got {self.blur_kernel}")
        if not (math.isfinite(self.clahe_clip_limit) and self.clahe_clip_limit >= 0):
            raise ConfigError(f"clahe_clip_limit: must be >= 0, got {self.clahe_clip_limit}")
        _check_range("gain_target", self.gain_target, 1.0, 255.0)
        if not (math.isfinite(self.max_gain) and self.max_gain >= 1.0):
            raise ConfigError(f"max_gain: must be >= 1, got {self.max_gain}")
        if not (math.isfinite(self.min_chroma) and self.min_chroma >= 0):
            raise ConfigError(f"min_chroma: must be >= 0, got {self.min_chroma}")
        if not (math.isfinite(self.dark_gain) and (self.dark_gain == 0 or self.dark_gain >= 1.0)):
            raise ConfigError(f"dark_gain: must be 0 (off) or >= 1, got {self.dark_gain}")
        if self.dark_blur_kernel < 1 or self.dark_blur_kernel % 2 == 0:
            raise ConfigError(
                f"dark_blur_kernel: must be an odd number >= 1, got {self.dark_blur_kernel}")
        if not (math.isfinite(self.dark_min_chroma) and self.dark_min_chroma >= 0):
            raise ConfigError(f"dark_min_chroma: must be >= 0, got {self.dark_min_chroma}")
        for name in ("open_kernel", "close_kernel"):
            if getattr(self, name) < 0:
                raise ConfigError(f"{name}: must be >= 0, got {getattr(self, name)}")

        for name in ("min_fill_ratio", "min_edge_support", "max_outside_ratio",
                     "min_visible_fraction", "min_score", "min_colourfulness"):
            _check_range(name, getattr(self, name), 0.0, 1.0)
        if self.max_detections < 1:
            raise ConfigError(f"max_detections: must be >= 1, got {self.max_detections}")
        if self.work_width != 0 and self.work_width < 64:
            raise ConfigError(f"work_width: must be 0 (full size) or >= 64, got {self.work_width}")
