"""Follower parameters: the ROS2 ball_tracker ``follow_ball`` node's, with its defaults."""

import math
from dataclasses import dataclass

from balltrack.common.config import ConfigError


def _number(name: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f"{name}: expected a number, got {value!r}")
    if not math.isfinite(value):
        raise ConfigError(f"{name}: must be finite, got {value!r}")
    return float(value)


@dataclass
class FollowerConfig:
    """How detections become ``cmd_vel``.

    The first six are the ROS2 package's parameters and defaults. ``rcv_timeout_secs``: a
    detection older than this means the ball is lost. ``angular_chase_multiplier``: the
    proportional gain, rad/s per unit of normalised ``x``. ``forward_chase_speed``: m/s while the
    ball looks smaller than ``max_size_thresh`` (apparent diameter / image width).
    ``search_angular_speed``: rad/s while searching; positive is counter-clockwise, the
    original's direction. ``filter_value``: the exponential filter's memory in [0, 1).

    ``rate_hz``: the command timer. ``use_sim_time``: time from the ``clock`` key rather than the
    wall clock. ``search_toward_last_seen``: spin toward the side where the ball was last seen
    (the original always spins at +``search_angular_speed``). ``reset_filter_on_reacquire``: when
    the ball is found again after a timeout (or for the first time), restart the filter from
    that detection instead of blending it into values from before the loss (the original
    blends, starting from zero).
    """

    rcv_timeout_secs: float = 1.0
    angular_chase_multiplier: float = 0.7
    forward_chase_speed: float = 0.1
    search_angular_speed: float = 0.5
    max_size_thresh: float = 0.1
    filter_value: float = 0.9
    rate_hz: float = 10.0
    use_sim_time: bool = False
    search_toward_last_seen: bool = True
    reset_filter_on_reacquire: bool = True
    # Among several balls, keep following the one already chased (nearest its last position in
    # x and apparent size, within ``target_gate``) instead of whichever looks largest; False
    # follows ``detected_ball`` (the largest) as the original node does.
    keep_target: bool = True
    target_gate: float = 0.3
    # How long other balls are ignored after the target was last matched: long enough to ride
    # out a missed frame or two, short enough that a target that jumped (or was replaced) is
    # re-acquired quickly.
    target_hold_secs: float = 0.3

    def __post_init__(self):
        self.rcv_timeout_secs = _number("rcv_timeout_secs", self.rcv_timeout_secs)
        if self.rcv_timeout_secs <= 0.0:
            raise ConfigError(f"rcv_timeout_secs: must be > 0, got {self.rcv_timeout_secs!r}")
        self.angular_chase_multiplier = _number("angular_chase_multiplier", self.angular_chase_multiplier)
        if self.angular_chase_multiplier < 0.0:
            raise ConfigError("angular_chase_multiplier: must be >= 0 (a negative gain turns away "
                              f"from the ball), got {self.angular_chase_multiplier!r}")
        self.forward_chase_speed = _number("forward_chase_speed", self.forward_chase_speed)
        if self.forward_chase_speed < 0.0:
            raise ConfigError(f"forward_chase_speed: must be >= 0, got {self.forward_chase_speed!r}")
        self.search_angular_speed = _number("search_angular_speed", self.search_angular_speed)
        self.max_size_thresh = _number("max_size_thresh", self.max_size_thresh)
        if self.max_size_thresh <= 0.0:
            raise ConfigError(f"max_size_thresh: must be > 0, got {self.max_size_thresh!r}")
        self.filter_value = _number("filter_value", self.filter_value)
        if not 0.0 <= self.filter_value < 1.0:
            raise ConfigError("filter_value: must be in [0, 1) (1 would never let a detection in), "
                              f"got {self.filter_value!r}")
        self.rate_hz = _number("rate_hz", self.rate_hz)
        if not 0.0 < self.rate_hz <= 1000.0:
            raise ConfigError(f"rate_hz: must be in (0, 1000], got {self.rate_hz!r}")
        self.target_gate = _number("target_gate", self.target_gate)
        if not 0.0 < self.target_gate <= 2.0:
            raise ConfigError(f"target_gate: must be in (0, 2] (normalised image units), got {self.target_gate!r}")
        self.target_hold_secs = _number("target_hold_secs", self.target_hold_secs)
        if self.target_hold_secs < 0.0:
            raise ConfigError(f"target_hold_secs: must be >= 0, got {self.target_hold_secs!r}")
        for name in ("use_sim_time", "search_toward_last_seen", "reset_filter_on_reacquire",
                     "keep_target"):
            if not isinstance(getattr(self, name), bool):
                raise ConfigError(f"{name}: expected a boolean, got {getattr(self, name)!r}")
