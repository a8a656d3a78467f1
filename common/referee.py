"""The one judge of "the robot reached the ball", from ground truth (demo, experiments, tests).

Reached means: the robot's centre within ``distance`` (m, on the floor) of the target ball's
centre AND the robot facing it within ``heading_degrees``, both without a break for ``hold``
seconds of simulated time, so that driving past the ball does not count. The time of reaching
is the start of that streak. The defaults are the README's for the demo.

Feed it ground truth as it comes, in order: ``update(t, truth)`` with ``t`` the simulated
seconds on whatever origin the caller counts from and ``truth`` a ``GroundTruth`` message (or
a dict with its ``robot`` and ``balls``). Pure: no Zenoh, no clock of its own.
"""

import math

from balltrack.common.geometry import heading_error

REACH_DISTANCE = 0.35  # m, robot centre to ball centre
REACH_HEADING_DEGREES = 10.0
HOLD_SECONDS = 1.0  # simulated


def errors(truth: dict, target: str | None = None) -> tuple[float, float]:
    """(robot centre to the target ball's centre on the floor in m, heading error in rad).

    ``target`` is a ball id; None is the first ball, the scenario's target. Without that ball
    in ``truth`` the robot is nowhere near it: (inf, pi)."""
    robot = truth["robot"]
    balls = [ball for ball in truth["balls"] if target is None or ball["id"] == target]
    if not balls:
        return math.inf, math.pi
    x, y = balls[0]["position"][:2]
    return (math.hypot(x - robot["x"], y - robot["y"]),
            heading_error(robot["x"], robot["y"], robot["yaw"], x, y))


class Referee:
    """Has the robot reached the ball? One ground-truth frame at a time.

    After each ``update``: ``reached_at`` (the start of the streak that held, or None),
    ``distance`` and ``heading`` (rad) of the latest frame, ``within`` (the latest frame meets
    the criteria), ``closest`` (smallest distance so far) and ``time`` (the latest ``t``).
    With a ``time_limit`` (simulated s) only a reach that began by then counts, and ``over``
    tells when waiting longer cannot change the verdict."""

    def __init__(self, distance: float = REACH_DISTANCE, heading_degrees: float = REACH_HEADING_DEGREES,
                 hold: float = HOLD_SECONDS, time_limit: float | None = None, target: str | None = None):
        if not (distance > 0 and 0 < heading_degrees <= 180 and hold >= 0):
            raise ValueError(f"referee: distance > 0, 0 < heading <= 180 and hold >= 0, got "
                             f"{distance}, {heading_degrees}, {hold}")
        self.max_distance = distance
        self.max_heading = math.radians(heading_degrees)
        self.hold = hold
        self.time_limit = time_limit
        self.target = target
        self.since: float | None = None  # start of the current streak within the criteria
        self.reached_at: float | None = None
        self.distance = math.inf
        self.heading = math.pi
        self.closest = math.inf
        self.within = False
        self.time: float | None = None

    @property
    def reached(self) -> bool:
        return self.reached_at is not None

    @property
    def over(self) -> bool:
        """Reached, or simulated time is past the limit plus the hold."""
        return self.reached or (self.time_limit is not None and self.time is not None
                                and self.time > self.time_limit + self.hold)

    def update(self, t: float, truth: dict) -> bool:
        """Take one frame's ground truth at ``t``; True once the ball has been reached."""
        self.time = t
        self.distance, self.heading = errors(truth, self.target)
        self.closest = min(self.closest, self.distance)
        self.within = self.distance <= self.max_distance and self.heading <= self.max_heading
        if not self.within:
            self.since = None
        elif self.since is None and (self.time_limit is None or t <= self.time_limit):
            self.since = t
        if self.since is not None and self.reached_at is None and t - self.since >= self.hold:
            self.reached_at = self.since
        return self.reached

    def criteria(self) -> dict:
        return {"distance_m": self.max_distance, "heading_deg": math.degrees(self.max_heading),
                "hold_s": self.hold}
