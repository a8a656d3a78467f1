"""Locator parameters: the paper's ``h_fov`` and ``ball_radius``, plus the choice of model."""

import math
from dataclasses import dataclass

from balltrack.common.config import ConfigError

from balltrack.services.locator.geometry import CIRCLE_MODELS

LOCATOR_MODES = ("auto", "exact", "faithful")


@dataclass
class LocatorConfig:
    """How Ball2D detections are turned into 3D positions.

    ``h_fov`` (radians) is only used by the faithful model (the exact model takes the field of
    view from CameraInfo); 1.089 rad is the paper's camera. ``ball_radius`` is in metres, a
    tennis ball by default. ``mode``: ``exact`` (pinhole, needs CameraInfo), ``faithful`` (the
    paper's equations 1-8) or ``auto`` (exact once CameraInfo intrinsics have been seen, else
    faithful). ``circle_model`` is what the detector's circle is assumed to measure of the
    ball's elliptical silhouette (see :mod:`services.locator.geometry`): ``mean`` (best-fit
    circle), ``area`` (equal-area circle) or ``enclosing`` (smallest enclosing circle).
    """

    h_fov: float = 1.089
    ball_radius: float = 0.033
    mode: str = "auto"
    circle_model: str = "mean"

    def __post_init__(self):
        if isinstance(self.h_fov, bool) or not isinstance(self.h_fov, (int, float)):
            raise ConfigError(f"h_fov: expected a number, got {self.h_fov!r}")
        if not (math.isfinite(self.h_fov) and 0.0 < self.h_fov < math.pi):
            raise ConfigError(f"h_fov: must be in (0, pi) radians, got {self.h_fov!r}")
        if isinstance(self.ball_radius, bool) or not isinstance(self.ball_radius, (int, float)):
            raise ConfigError(f"ball_radius: expected a number, got {self.ball_radius!r}")
        if not (math.isfinite(self.ball_radius) and self.ball_radius > 0.0):
            raise ConfigError(f"ball_radius: must be > 0 metres, got {self.ball_radius!r}")
        if self.mode not in LOCATOR_MODES:
            raise ConfigError(f"mode: must be one of {', '.join(LOCATOR_MODES)}, got {self.mode!r}")
        if self.circle_model not in CIRCLE_MODELS:
            raise ConfigError(
                f"circle_model: must be one of {', '.join(CIRCLE_MODELS)}, got {self.circle_model!r}")
        self.h_fov = float(self.h_fov)
        self.ball_radius = float(self.ball_radius)

    def resolved_mode(self, have_intrinsics: bool) -> str:
        """``exact`` or ``faithful``: what ``mode`` means given whether CameraInfo was seen."""
        if self.mode == "auto":
            return "exact" if have_intrinsics else "faithful"
        return self.mode
