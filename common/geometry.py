"""Plane geometry shared by the simulator, the demo, the experiments and the tests."""

import math


def wrap_angle(angle: float) -> float:
    """``angle`` (rad) wrapped to [-pi, pi): the shorter way round, for differences of headings."""
    return (angle + math.pi) % (2 * math.pi) - math.pi


def heading_error(x: float, y: float, yaw: float, target_x: float, target_y: float) -> float:
    """The angle (rad, absolute, in [0, pi]) between a heading ``yaw`` at (x, y) and the
    direction to (target_x, target_y)."""
    return abs(wrap_angle(math.atan2(target_y - y, target_x - x) - yaw))
