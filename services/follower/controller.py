"""The follower's state machine: detections in, velocity commands out (paper section 2.4).

This is the ROS2 ball_tracker ``follow_ball`` node without ROS. Detections update an
exponential filter when they arrive (``on_detection``); a ``rate_hz`` timer asks for a command
(``tick``):

* **chase**: the last detection is younger than ``rcv_timeout_secs``. Turn
  ``angular = -angular_chase_multiplier * filtered_x`` and drive ``forward_chase_speed`` while
  the filtered apparent size is below ``max_size_thresh``;
* **arrived**: as chase, but the ball looks big enough, so ``linear = 0`` (still turning to
  keep it centred);
* **search**: no detection yet, or none for ``rcv_timeout_secs``: ``linear = 0`` and spin at
  ``search_angular_speed``.

Times are float seconds from whichever clock the caller uses (wall or simulated); the
controller never reads a clock itself.

Decisions beyond the original node:

* **Search direction** (``search_toward_last_seen``, default on): spin toward the side of the
  image where the ball was last seen, judged by the last raw detection's ``x`` (where the ball
  actually left the picture; the filtered value lags and can still have the old sign after a
  fast crossing). Ball last seen on the right (``x > 0``) means a negative (clockwise) turn,
  the same sign convention as the chase. Before any detection, or if it was dead centre, the
  configured ``search_angular_speed`` is used as is, the original's behaviour.
* **Filter on re-acquisition** (``reset_filter_on_reacquire``, default on): the first
  detection after a loss (and the very first one) restarts the filter at that detection. The
  original keeps blending, from zero at start-up and from the values of before the loss after
  a search. With ``filter_value = 0.9`` a stale state takes about 22 detections (0.7 s at
  30 Hz) to fade to 10 %: after a search the robot would first steer by where the ball *was*
  (often the opposite side, having just spun), and a size remembered from close up would hold
  it in "arrived" while the ball is far away; from a zero start the size reads small, so the
  robot drives on toward a ball that is already close. Restarting costs only the smoothing of
  one sample.
* **Clock going backwards** (a simulation reset): a detection or tick time before the last
  detection means the target is lost; the controller searches until the next detection, which
  counts as a re-acquisition. A non-finite time makes ``tick`` search without touching state
  and ``on_detection`` ignore the sample, as it ignores non-finite or negative values, so one
  bad number cannot poison the filter.
"""

import math
from dataclasses import dataclass

from balltrack.services.follower.association import AssociationSettings, TargetAssociation
from balltrack.services.follower.config import FollowerConfig

CHASE = "chase"
ARRIVED = "arrived"
SEARCH = "search"


@dataclass(frozen=True)
class Command:
    """One velocity command: ``linear`` (m/s, forward), ``angular`` (rad/s, counter-clockwise
    positive, about the robot's z axis) and the ``mode`` that produced it."""

    linear: float
    angular: float
    mode: str


class FollowerController:
    """Exponentially filtered P controller with timeout search; see the module docstring."""

    def __init__(self, config: FollowerConfig):
        self._config = config
        self._association = TargetAssociation(AssociationSettings.from_config(config))
        self.reset()

    @property
    def config(self) -> FollowerConfig:
        return self._config

    @property
    def target_x(self) -> float:
        """The filtered normalised horizontal position (-1 left .. 1 right)."""
        return self._target_x

    @property
    def target_size(self) -> float:
        """The filtered apparent size (diameter / image width)."""
        return self._target_size

    @property
    def last_seen(self) -> float | None:
        """When the last detection arrived, or None if none since start, reset or loss by clock."""
        return self._last_seen

    def reset(self) -> None:
        """Forget everything: as freshly started (searching, filter at zero)."""
        self._target_x = 0.0
        self._target_size = 0.0
        self._last_seen: float | None = None
        self._last_x: float | None = None
        self._association.reset()

    @property
    def association(self) -> TargetAssociation:
        """The target's track among several balls (used by ``choose``)."""
        return self._association

    def update_config(self, config: FollowerConfig) -> None:
        """Use new parameters from the next call on; the filter and timing state are kept."""
        self._config = config
        self._association.settings = AssociationSettings.from_config(config)

    def tracking(self, now: float) -> bool:
        """Whether a detection younger than ``rcv_timeout_secs`` has been received by ``now``."""
        if self._last_seen is None or not math.isfinite(now):
            return False
        age = now - self._last_seen
        return 0.0 <= age < self._config.rcv_timeout_secs

    def on_detection(self, x: float, size: float, now: float) -> bool:
        """Take in one detection at time ``now``; False (and no change) if it is unusable."""
        if not (math.isfinite(x) and math.isfinite(size) and math.isfinite(now)) or size < 0.0:
            return False
        if not self.tracking(now) and self._config.reset_filter_on_reacquire:
            self._target_x = x
            self._target_size = size
        else:
            keep = self._config.filter_value
            self._target_x = self._target_x * keep + x * (1.0 - keep)
            self._target_size = self._target_size * keep + size * (1.0 - keep)
        self._last_seen = now
        self._last_x = x
        return True

    def choose(self, balls: list[dict], now: float) -> dict | None:
        """The ball to follow among one frame's detections (maps with ``x``, ``z`` and usually
        ``y``), or None when the target is not in this frame and is still held.

        The target's track (services/follower/association.py) predicts where it is and how
        large it looks; another ball replaces it only once it has been neither matched nor
        covered for ``target_hold_secs``, or after a loss. With no target, the largest ball (the
        paper's choice)."""
        if not self.tracking(now):
            self._association.reset()  # lost (searching): nothing to hold
        return self._association.choose(balls, now)

    def tick(self, now: float) -> Command:
        """The command for time ``now`` (called by the ``rate_hz`` timer)."""
        if not math.isfinite(now):
            return self._search()
        if self._last_seen is not None and now < self._last_seen:
            self._last_seen = None  # the clock went backwards: the target is lost
        if not self.tracking(now):
            return self._search()
        config = self._config
        angular = -config.angular_chase_multiplier * self._target_x + 0.0  # + 0.0: no "-0.0"
        if self._target_size < config.max_size_thresh:
            return Command(config.forward_chase_speed, angular, CHASE)
        return Command(0.0, angular, ARRIVED)

    def _search(self) -> Command:
        speed = self._config.search_angular_speed
        if self._config.search_toward_last_seen and self._last_x:
            speed = -math.copysign(abs(speed), self._last_x)
        return Command(0.0, speed, SEARCH)
