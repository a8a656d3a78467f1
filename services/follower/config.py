"""Follower parameters: the ROS2 ball_tracker ``follow_ball`` node's, with its defaults.

Example::

    balltrack run follower --set forward_chase_speed=0.2 --set keep_target=false
"""

from dataclasses import dataclass

from balltrack.common.config import check_fields, param


@dataclass
class FollowerConfig:
    """How detections become ``cmd_vel``. The first six are the ROS2 package's parameters and
    defaults; the rest are this implementation's."""

    rcv_timeout_secs: float = param(1.0, "a detection older than this (s) means the ball is lost: search",
                                    above=0)
    # A negative gain would turn away from the ball.
    angular_chase_multiplier: float = param(0.7, "turn rate per unit of normalised x (rad/s); the P gain",
                                            low=0)
    forward_chase_speed: float = param(0.1, "forward speed while the ball looks small (m/s)", low=0)
    # Positive is counter-clockwise, the original's direction.
    search_angular_speed: float = param(0.5, "turn rate while searching (rad/s, positive = "
                                             "counter-clockwise)")
    max_size_thresh: float = param(0.1, "stop driving once the ball's apparent diameter / image width "
                                        "exceeds this", above=0)
    # 1 would never let a detection in.
    filter_value: float = param(0.9, "exponential filter memory in [0, 1) (0.9 = 90 % old value)",
                                low=0, below=1)
    # (at least a command every 10 s: the timer is also the watchdog that starts the search)
    rate_hz: float = param(10.0, "cmd_vel timer rate (Hz)", low=0.1, high=1000)
    use_sim_time: bool = param(False, "read time from the `clock` key (simulated time) instead of the "
                                      "wall clock")
    # The original always spins at +search_angular_speed.
    search_toward_last_seen: bool = param(True, "search by turning toward where the ball was last seen")
    # The original blends the first detection into values from before the loss, starting from zero.
    reset_filter_on_reacquire: bool = param(True, "restart the filter from the first detection after a loss")
    keep_target: bool = param(True, "among several balls, keep following the one already chased (nearest "
                                    "its predicted position, of its apparent size) instead of whichever "
                                    "looks largest; false follows `detected_ball` (the largest) as the "
                                    "original node does")
    target_gate: float = param(0.3, "largest distance (normalised image x, y) of a detection from the "
                                    "target's predicted position for it to count as the target",
                               above=0, high=2)
    # Long enough to ride out a missed frame or two, short enough that a target that jumped (or
    # was replaced) is re-acquired quickly.
    target_hold_secs: float = param(0.3, "how long (s) other balls are ignored after the target was last "
                                         "matched or covered by a larger detection", low=0)
    # Frame to frame a ball's detected size changes by under 3 % (99th percentile) in the
    # simulator; two balls merging into one detection grow it by 5-10 % a frame, and a blob of
    # the target with a sliver of a ball behind it is 15-20 % larger. Only a merge makes a ball
    # look larger.
    target_size_ratio: float = param(1.1, "largest apparent size of a detection, relative to the target's "
                                          "reference size, for it to count as the target alone while "
                                          "other balls are near it",
                                     above=1, high=4)
    # A ball partly hidden or cut by the image edge looks smaller (in the simulator up to ~15 %).
    target_shrink_ratio: float = param(1.5, "the target may look smaller than its reference size by up to "
                                            "this factor", above=1, high=4)
    # Slow enough that a merge (more than 1/s) is not followed, fast enough for the robot's own
    # approach from afar (0.1 m/s at 0.5 m: 0.2/s).
    target_size_rate: float = param(0.3, "how fast (log of size per s) the target's reference size may "
                                         "follow its detections while other balls are near it", above=0)
    # A merge needs another ball near the target; the memory bridges frames where that ball is
    # hidden behind the target before it comes out the other side, merging again.
    target_crowd_secs: float = param(1.0, "how long (s) after another detection was near the target (within "
                                          "target_gate) its size is held to target_size_ratio and "
                                          "target_size_rate", low=0)
    target_velocity_memory: float = param(0.9, "exponential memory of the target's image velocity (per "
                                               "matched frame) used to predict its position",
                                          low=0, below=1)

    # Off by default: the paper's node commands only from its timer. On, the command leaves as
    # soon as the detection is in (one frame's latency instead of up to a timer period) while the
    # timer still runs, as the watchdog that starts the search and as the lockstep simulator's tick.
    command_on_detection: bool = param(False, "also publish cmd_vel for every detection message, at once "
                                              "(no `time` field: only the rate_hz timer's commands are "
                                              "ticks); the timer keeps publishing and searching")

    def __post_init__(self):
        check_fields(self)
