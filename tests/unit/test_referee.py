"""The shared referee of "the robot reached the ball", the angle wrap and the free-port helper."""

import math
import socket

import pytest

from balltrack.common.geometry import heading_error, wrap_angle
from balltrack.common.network import free_port
from balltrack.common.referee import Referee, errors


def truth(x, y, yaw, *balls):
    balls = balls or (("tennis", 1.0, 0.0),)
    return {"robot": {"x": x, "y": y, "yaw": yaw},
            "balls": [{"id": name, "radius": 0.033, "position": [bx, by, 0.033],
                       "in_camera": [0, 0, 1], "visible": True} for name, bx, by in balls]}


def test_wrap_angle_takes_the_shorter_way_round():
    assert wrap_angle(0.0) == 0.0
    assert wrap_angle(3 * math.pi / 2) == pytest.approx(-math.pi / 2)
    assert wrap_angle(-3 * math.pi / 2) == pytest.approx(math.pi / 2)
    assert wrap_angle(math.pi) == pytest.approx(-math.pi)  # [-pi, pi)
    assert wrap_angle(10 * math.pi + 0.25) == pytest.approx(0.25)
    assert heading_error(0, 0, math.radians(350), 1, 0) == pytest.approx(math.radians(10))
    assert heading_error(1, 1, 0.0, 1, 3) == pytest.approx(math.pi / 2)


def test_errors_use_the_target_ball_and_say_so_when_it_is_missing():
    frame = truth(0.0, 0.0, 0.0, ("near", 0.5, 0.0), ("far", 0.0, 2.0))
    assert errors(frame) == pytest.approx((0.5, 0.0))  # the first ball is the target
    assert errors(frame, "far") == pytest.approx((2.0, math.pi / 2))
    assert errors(frame, "gone") == (math.inf, math.pi)
    assert errors({"robot": {"x": 0, "y": 0, "yaw": 0}, "balls": []}) == (math.inf, math.pi)


def test_reached_needs_distance_heading_and_the_hold():
    referee = Referee(distance=0.35, heading_degrees=10, hold=1.0)
    assert not referee.update(0.0, truth(0.7, 0.0, 0.0))             # too far
    assert not referee.update(0.5, truth(0.7, 0.0, math.radians(20)))  # close, facing away
    assert not referee.update(1.0, truth(0.7, 0.0, 0.0))             # close and facing: the hold starts
    assert not referee.update(1.5, truth(0.7, 0.0, math.radians(5)))
    assert referee.update(2.0, truth(0.72, 0.0, 0.0))
    assert referee.reached_at == 1.0 and referee.within
    assert referee.distance == pytest.approx(0.28) and referee.heading == pytest.approx(0.0)
    assert referee.closest == pytest.approx(0.28)
    referee.update(2.5, truth(0.0, 0.0, 0.0))  # a reach, once held, stays reached
    assert referee.reached and not referee.within and referee.reached_at == 1.0
    assert referee.distance == pytest.approx(1.0)


def test_a_break_restarts_the_hold():
    referee = Referee(hold=1.0)
    referee.update(0.0, truth(0.7, 0.0, 0.0))
    referee.update(0.5, truth(0.0, 0.0, 0.0))  # drove away
    assert not referee.update(1.2, truth(0.7, 0.0, 0.0))
    assert not referee.update(2.1, truth(0.7, 0.0, 0.0))
    assert referee.update(2.2, truth(0.7, 0.0, 0.0)) and referee.reached_at == 1.2


def test_time_limit_counts_only_reaches_that_began_in_time():
    referee = Referee(hold=1.0, time_limit=30.0)
    referee.update(29.0, truth(0.0, 0.0, 0.0))
    assert not referee.over
    referee.update(30.5, truth(0.7, 0.0, 0.0))  # too late to begin
    assert not referee.update(31.6, truth(0.7, 0.0, 0.0)) and referee.over
    in_time = Referee(hold=1.0, time_limit=30.0)
    in_time.update(29.9, truth(0.7, 0.0, 0.0))
    assert in_time.update(30.9, truth(0.7, 0.0, 0.0)) and in_time.reached_at == 29.9 and in_time.over


@pytest.mark.parametrize("arguments", [dict(distance=0), dict(heading_degrees=0), dict(hold=-1)])
def test_bad_criteria_are_refused(arguments):
    with pytest.raises(ValueError, match="referee"):
        Referee(**arguments)


def test_free_port_prefers_the_given_one_when_nothing_listens_there():
    port = free_port()
    assert 0 < port < 65536
    assert free_port(port) == port
    with socket.socket() as listener:
        listener.bind(("127.0.0.1", port))
        listener.listen()
        other = free_port(port)
        assert other != port and 0 < other < 65536
