"""The follower's state machine, step by step, with exact filter values."""

import math

import pytest

from balltrack.common.config import ConfigError, load_config, replace_config
from balltrack.services.follower.config import FollowerConfig
from balltrack.services.follower.controller import ARRIVED, CHASE, SEARCH, Command, FollowerController


def controller(**changes) -> FollowerController:
    return FollowerController(FollowerConfig(**changes))


def original(**changes) -> FollowerController:
    """The ROS2 node's behaviour: blend from zero, always search counter-clockwise."""
    return controller(search_toward_last_seen=False, reset_filter_on_reacquire=False, **changes)


# --- config ----------------------------------------------------------------------------------

def test_defaults_are_the_ros2_packages():
    config = FollowerConfig()
    assert (config.rcv_timeout_secs, config.angular_chase_multiplier, config.forward_chase_speed,
            config.search_angular_speed, config.max_size_thresh, config.filter_value) == \
        (1.0, 0.7, 0.1, 0.5, 0.1, 0.9)
    assert (config.rate_hz, config.use_sim_time, config.search_toward_last_seen,
            config.reset_filter_on_reacquire) == (10.0, False, True, True)


@pytest.mark.parametrize("changes, field", [
    ({"rcv_timeout_secs": 0.0}, "rcv_timeout_secs"),
    ({"rcv_timeout_secs": -1.0}, "rcv_timeout_secs"),
    ({"rcv_timeout_secs": math.inf}, "rcv_timeout_secs"),
    ({"angular_chase_multiplier": -0.7}, "angular_chase_multiplier"),
    ({"angular_chase_multiplier": "fast"}, "angular_chase_multiplier"),
    ({"forward_chase_speed": -0.1}, "forward_chase_speed"),
    ({"search_angular_speed": math.nan}, "search_angular_speed"),
    ({"max_size_thresh": 0.0}, "max_size_thresh"),
    ({"filter_value": 1.0}, "filter_value"),
    ({"filter_value": -0.1}, "filter_value"),
    ({"rate_hz": 0.0}, "rate_hz"),
    ({"rate_hz": 5000.0}, "rate_hz"),
    ({"rate_hz": True}, "rate_hz"),
    ({"use_sim_time": "yes"}, "use_sim_time"),
    ({"search_toward_last_seen": 1}, "search_toward_last_seen"),
    ({"reset_filter_on_reacquire": None}, "reset_filter_on_reacquire"),
])
def test_config_rejects_bad_values(changes, field):
    with pytest.raises(ConfigError, match=f"^{field}:"):
        FollowerConfig(**changes)


def test_config_accepts_edge_values_and_overrides():
    FollowerConfig(filter_value=0.0, forward_chase_speed=0.0, search_angular_speed=-0.5,
                   angular_chase_multiplier=0.0)
    config = load_config(FollowerConfig, overrides=["filter_value=0.5", "use_sim_time=true", "rate_hz=20"])
    assert (config.filter_value, config.use_sim_time, config.rate_hz) == (0.5, True, 20.0)
    with pytest.raises(ConfigError, match="^filter_value:"):
        replace_config(config, {"filter_value": 2})


# --- the state machine -----------------------------------------------------------------------

def test_searches_before_any_detection():
    follower = controller()
    assert follower.tick(0.0) == Command(0.0, 0.5, SEARCH)
    assert follower.tick(123.4) == Command(0.0, 0.5, SEARCH)
    assert follower.last_seen is None


def test_original_filter_maths_exact_values():
    follower = original()
    assert follower.on_detection(0.5, 0.04, now=10.0)
    # 0 * 0.9 + 0.5 * 0.1 = 0.05; 0 * 0.9 + 0.04 * 0.1 = 0.004
    assert follower.target_x == pytest.approx(0.05, abs=1e-15)
    assert follower.target_size == pytest.approx(0.004, abs=1e-15)
    follower.on_detection(-0.3, 0.06, now=10.1)
    # 0.05 * 0.9 - 0.3 * 0.1 = 0.015; 0.004 * 0.9 + 0.06 * 0.1 = 0.0096
    assert follower.target_x == pytest.approx(0.015, abs=1e-15)
    assert follower.target_size == pytest.approx(0.0096, abs=1e-15)
    command = follower.tick(10.15)
    assert command.mode == CHASE
    assert command.linear == 0.1
    assert command.angular == pytest.approx(-0.7 * 0.015, abs=1e-15)


def test_filter_restarts_at_first_detection_by_default():
    follower = controller()
    follower.on_detection(0.5, 0.04, now=10.0)
    assert (follower.target_x, follower.target_size) == (0.5, 0.04)
    follower.on_detection(-0.3, 0.06, now=10.1)
    # Tracking now, so it blends: 0.5 * 0.9 - 0.03 = 0.42; 0.036 + 0.006 = 0.042.
    assert follower.target_x == pytest.approx(0.42, abs=1e-15)
    assert follower.target_size == pytest.approx(0.042, abs=1e-15)
    assert follower.tick(10.2) == Command(0.1, pytest.approx(-0.7 * 0.42, abs=1e-15), CHASE)


def test_filter_value_zero_follows_every_detection():
    follower = original(filter_value=0.0)
    follower.on_detection(0.2, 0.05, now=0.0)
    follower.on_detection(-0.6, 0.07, now=0.05)
    assert (follower.target_x, follower.target_size) == (-0.6, 0.07)


def test_chase_then_arrive_as_the_ball_grows():
    follower = controller()
    now, modes = 0.0, []
    for step in range(40):  # the ball grows 0.05 -> 0.25 at 30 Hz, dead ahead
        now = step / 30
        follower.on_detection(0.0, 0.05 + 0.2 * step / 39, now)
        if step % 3 == 0:
            command = follower.tick(now + 0.001)
            modes.append(command.mode)
            assert command.angular == 0.0 and not math.copysign(1.0, command.angular) < 0
            assert command.linear == (0.1 if command.mode == CHASE else 0.0)
    assert modes[0] == CHASE and modes[-1] == ARRIVED
    # Once the filtered size passes the threshold it stays arrived (the ball keeps growing).
    first_arrival = modes.index(ARRIVED)
    assert set(modes[first_arrival:]) == {ARRIVED}
    assert follower.target_size >= 0.1


def test_arrived_still_turns_toward_the_ball():
    follower = controller()
    follower.on_detection(-0.4, 0.3, now=1.0)
    assert follower.tick(1.05) == Command(0.0, pytest.approx(0.28), ARRIVED)


def test_timeout_boundary_then_search():
    follower = controller()
    follower.on_detection(0.2, 0.05, now=5.0)
    assert follower.tick(5.0).mode == CHASE
    assert follower.tick(5.999).mode == CHASE
    # Age == rcv_timeout_secs is lost, as in the node's "now - last < timeout".
    assert follower.tick(6.0) == Command(0.0, -0.5, SEARCH)
    assert follower.tick(7.5).mode == SEARCH


def test_search_direction_toward_last_seen_side():
    follower = controller()
    follower.on_detection(-0.9, 0.05, now=0.0)  # left edge: spin counter-clockwise
    assert follower.tick(2.0) == Command(0.0, 0.5, SEARCH)
    follower.on_detection(0.95, 0.05, now=3.0)  # right edge: spin clockwise
    assert follower.tick(5.0) == Command(0.0, -0.5, SEARCH)


def test_search_side_is_the_last_raw_detection_not_the_lagging_filter():
    follower = controller()
    follower.on_detection(-0.8, 0.05, now=0.0)
    for step in range(1, 4):  # a fast crossing: the filter is still negative at the end
        follower.on_detection(0.9, 0.05, now=step * 0.033)
    assert follower.target_x < 0
    assert follower.tick(2.0).angular == -0.5


def test_search_direction_of_the_original():
    follower = original()
    follower.on_detection(0.95, 0.05, now=0.0)
    assert follower.tick(2.0) == Command(0.0, 0.5, SEARCH)
    ccw = original(search_angular_speed=-0.3)
    assert ccw.tick(0.0).angular == -0.3


def test_search_toward_last_seen_uses_magnitude_and_default_sign():
    follower = controller(search_angular_speed=-0.3)
    assert follower.tick(0.0).angular == -0.3  # nothing seen yet: as configured
    follower.on_detection(-0.5, 0.05, now=1.0)
    assert follower.tick(3.0).angular == 0.3
    follower.on_detection(0.0, 0.05, now=4.0)  # lost dead centre: as configured
    assert follower.tick(6.0).angular == -0.3


def test_reacquire_after_timeout_restarts_the_filter():
    follower = controller()
    for step in range(30):  # close up on the left: big and arrived
        follower.on_detection(-0.5, 0.3, now=step / 30)
    assert follower.tick(1.0).mode == ARRIVED
    assert follower.tick(3.0).mode == SEARCH
    follower.on_detection(0.7, 0.03, now=10.0)  # far away on the right
    assert (follower.target_x, follower.target_size) == (0.7, 0.03)
    assert follower.tick(10.05) == Command(0.1, pytest.approx(-0.49), CHASE)


def test_reacquire_after_timeout_in_the_original_keeps_stale_values():
    follower = original()
    for step in range(60):
        follower.on_detection(-0.5, 0.3, now=step / 30)
    assert follower.tick(2.0).mode == ARRIVED
    stale_x, stale_size = follower.target_x, follower.target_size
    follower.on_detection(0.7, 0.03, now=10.0)
    assert follower.target_x == pytest.approx(stale_x * 0.9 + 0.07)
    assert follower.target_size == pytest.approx(stale_size * 0.9 + 0.003)
    # Still "arrived" and still turning left although the ball is far away on the right.
    command = follower.tick(10.05)
    assert command.mode == ARRIVED and command.angular > 0


def test_detections_within_timeout_keep_blending():
    follower = controller()
    follower.on_detection(0.5, 0.05, now=0.0)
    follower.on_detection(0.1, 0.05, now=0.9)  # 0.9 s later: still tracking
    assert follower.target_x == pytest.approx(0.46)


def test_clock_going_backwards_loses_the_target_without_crashing():
    follower = controller()
    follower.on_detection(0.3, 0.05, now=100.0)
    assert follower.tick(100.1).mode == CHASE
    # Simulation reset: time restarts near zero.
    command = follower.tick(0.2)
    assert command.mode == SEARCH and command.linear == 0.0
    assert follower.last_seen is None
    assert follower.tick(0.3).mode == SEARCH
    follower.on_detection(-0.2, 0.06, now=0.4)  # a re-acquisition: the filter restarts
    assert (follower.target_x, follower.target_size) == (-0.2, 0.06)
    assert follower.tick(0.45) == Command(0.1, pytest.approx(0.14), CHASE)


def test_detection_stamped_before_the_last_one_is_a_reacquisition():
    follower = controller()
    follower.on_detection(0.3, 0.05, now=100.0)
    follower.on_detection(-0.4, 0.07, now=1.0)  # clock reset between two detections
    assert (follower.target_x, follower.target_size, follower.last_seen) == (-0.4, 0.07, 1.0)
    assert follower.tick(1.1).mode == CHASE


def test_unusable_inputs_are_ignored():
    follower = controller()
    follower.on_detection(0.2, 0.05, now=1.0)
    bad = ((math.nan, 0.05, 1.1), (0.2, math.inf, 1.1), (0.2, -0.01, 1.1), (0.2, 0.05, math.nan))
    for x, size, now in bad:
        assert follower.on_detection(x, size, now) is False
    assert (follower.target_x, follower.target_size, follower.last_seen) == (0.2, 0.05, 1.0)
    assert follower.tick(math.nan) == Command(0.0, -0.5, SEARCH)
    assert follower.tick(1.2).mode == CHASE  # state untouched by the bad tick


def test_reset_forgets_everything():
    follower = controller()
    follower.on_detection(0.9, 0.2, now=1.0)
    follower.reset()
    assert (follower.target_x, follower.target_size, follower.last_seen) == (0.0, 0.0, None)
    assert follower.tick(1.1) == Command(0.0, 0.5, SEARCH)


def test_update_config_applies_from_the_next_call_and_keeps_state():
    follower = controller()
    follower.on_detection(0.5, 0.05, now=1.0)
    follower.update_config(replace_config(follower.config, {"angular_chase_multiplier": 1.0,
                                                            "max_size_thresh": 0.04,
                                                            "rcv_timeout_secs": 0.5}))
    assert follower.tick(1.2) == Command(0.0, -0.5, ARRIVED)
    assert follower.tick(1.6).mode == SEARCH  # the shorter timeout applies at once
    follower.update_config(replace_config(follower.config, {"rcv_timeout_secs": 2.0}))
    assert follower.tick(1.6).mode == ARRIVED


def _ball(x, z):
    return {"x": x, "z": z}


def test_choose_takes_the_largest_until_tracking_then_keeps_the_target():
    controller = FollowerController(FollowerConfig())
    first = controller.choose([_ball(-0.5, 0.05), _ball(0.4, 0.08)], 0.0)
    assert first == _ball(0.4, 0.08)  # not tracking yet: the largest, as the paper does
    controller.on_detection(first["x"], first["z"], 0.0)
    # A bigger ball appears elsewhere: the target (moved a little) is kept.
    kept = controller.choose([_ball(-0.3, 0.2), _ball(0.35, 0.085)], 0.1)
    assert kept == _ball(0.35, 0.085)
    controller.on_detection(kept["x"], kept["z"], 0.1)
    # The target is gone from the frame: no ball is taken in its place during the hold...
    assert controller.choose([_ball(-0.3, 0.2)], 0.35) is None
    # ...and after it (0.3 s since the target was last seen) the largest is taken again.
    assert controller.choose([_ball(-0.3, 0.2)], 0.45) == _ball(-0.3, 0.2)
    assert controller.choose([_ball(-0.3, 0.2)], 5.0) == _ball(-0.3, 0.2)


def test_choose_rejects_balls_of_very_different_size_beside_the_target():
    controller = FollowerController(FollowerConfig())
    assert controller.choose([_ball(0.0, 0.05)], 0.0) == _ball(0.0, 0.05)
    controller.on_detection(0.0, 0.05, 0.0)
    assert controller.choose([_ball(0.25, 0.2)], 0.1) is None       # 4x larger: another ball
    assert controller.choose([_ball(0.05, 0.06)], 0.1) == _ball(0.05, 0.06)
    assert controller.choose([], 0.1) is None


def test_choose_forgets_the_target_once_the_controller_lost_it():
    controller = FollowerController(FollowerConfig(target_hold_secs=5.0))
    assert controller.choose([_ball(0.0, 0.05)], 0.0) == _ball(0.0, 0.05)
    controller.on_detection(0.0, 0.05, 0.0)
    # Searching after rcv_timeout_secs: nothing is held, whatever the hold time.
    assert controller.choose([_ball(0.8, 0.2)], 1.5) == _ball(0.8, 0.2)


def test_target_gate_is_validated():
    with pytest.raises(ConfigError, match="target_gate"):
        FollowerConfig(target_gate=0.0)
    with pytest.raises(ConfigError, match="target_hold_secs"):
        FollowerConfig(target_hold_secs=-1.0)
    with pytest.raises(ConfigError, match="keep_target"):
        FollowerConfig(keep_target="yes")


# --- command_on_detection: the service asks for a command right after each detection ---------

def test_command_on_detection_is_off_by_default_and_a_declared_parameter():
    assert FollowerConfig().command_on_detection is False
    config = load_config(FollowerConfig, overrides=["command_on_detection=true"])
    assert config.command_on_detection is True
    with pytest.raises(ConfigError, match="^command_on_detection"):
        load_config(FollowerConfig, overrides=["command_on_detection=often"])


def test_command_at_the_detection_time_uses_that_detection():
    # The event path is on_detection(now) then tick(now) under one lock: the command must
    # already include the detection just taken in, not wait for the next timer tick.
    follower = controller(command_on_detection=True)
    assert follower.on_detection(0.4, 0.05, 3.0)
    assert follower.tick(3.0) == Command(0.1, -0.7 * 0.4, CHASE)
    assert follower.on_detection(0.2, 0.5, 3.033)
    command = follower.tick(3.033)
    assert command.mode == CHASE and command.angular == pytest.approx(-0.7 * (0.9 * 0.4 + 0.1 * 0.2))
    # A frame without the target is answered with the held command, then the timer searches.
    assert follower.choose([], 3.066) is None
    assert follower.tick(3.066).mode == CHASE
    assert follower.tick(3.033 + 1.01) == Command(0.0, -0.5, SEARCH)
