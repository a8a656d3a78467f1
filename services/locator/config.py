"""Locator parameters: the paper's ``h_fov`` and ``ball_radius``, plus the choice of model.

Example::

    balltrack run locator --set mode=faithful --set circle_model=area
"""

import enum
import math
from dataclasses import dataclass

from balltrack.common.config import check_fields, param

from balltrack.services.locator.projection import CIRCLE_MODELS


class LocatorMode(enum.StrEnum):
    # Member names equal their values: an Enum hashes by name, so only then does a member
    # find the same dict entries as its plain string.
    auto = "auto"
    exact = "exact"
    faithful = "faithful"


# The geometry implements the models and owns their names; the config only offers them.
CircleModel = enum.StrEnum("CircleModel", [(name, name) for name in CIRCLE_MODELS])


@dataclass
class LocatorConfig:
    """How Ball2D detections are turned into 3D positions (see :mod:`services.locator.geometry`)."""

    # 1.089 rad is the paper's camera (Gazebo's default).
    h_fov: float = param(1.089, "horizontal field of view (rad), used by the faithful model without "
                                "CameraInfo", above=0, below=math.pi)
    ball_radius: float = param(0.033, "the ball's real radius (m); 0.033 = a tennis ball", above=0)
    mode: LocatorMode = param(LocatorMode.auto, "`exact` (pinhole; a detection of a frame size without "
                                                "CameraInfo is rejected), `faithful` (the paper's "
                                                "equations 1-8) or `auto` (exact once CameraInfo was seen)")
    circle_model: CircleModel = param(CircleModel.mean, "what the detector's circle measures of the "
                                                        "ball's elliptic silhouette: `mean` (best-fit "
                                                        "circle), `area` (equal-area circle) or "
                                                        "`enclosing` (smallest enclosing circle)")

    def __post_init__(self):
        check_fields(self)

    def resolved_mode(self, have_intrinsics: bool) -> str:
        """``exact`` or ``faithful``: what ``mode`` means given whether CameraInfo was seen."""
        if self.mode == LocatorMode.auto:
            return LocatorMode.exact if have_intrinsics else LocatorMode.faithful
        return self.mode
