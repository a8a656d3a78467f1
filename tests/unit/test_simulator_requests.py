"""SimCommand requests are checked before the simulation changes (services/simulator/requests.py):
whatever arrives from the network is a valid request or a ValueError with a reason."""

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from balltrack.services.simulator.requests import (COMMAND_OPS, ball_index, ball_position, checked_form,
                                                   checked_request, light_level, robot_position)

ANY_VALUE = st.recursive(st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8),
                         lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner,
                                                                                     max_size=4),
                         max_leaves=10)


@given(ANY_VALUE)
def test_any_request_is_checked_or_refused_with_a_reason(request):
    try:
        op, arguments = checked_request(request)
    except ValueError as error:
        assert str(error)
        return
    assert op in COMMAND_OPS and "op" not in arguments


@pytest.mark.parametrize("request_, reason", [
    ([1, 2], "expected a map with an 'op', got list"),
    ({"op": "explode"}, "op: must be one of reset, set_light, place_ball, place_robot, got 'explode'"),
    ({"op": "place_robot", "x": 1, "y": 2, "z": 3}, "place_robot: unknown argument 'z' (allowed: x, y, yaw)"),
])
def test_bad_requests_name_what_is_wrong(request_, reason):
    with pytest.raises(ValueError, match="^" + reason.replace("(", r"\(").replace(")", r"\)") + "$"):
        checked_request(request_)


@given(ANY_VALUE)
def test_a_request_whose_form_passes_passes_the_request_check(request):
    # (checked_form is what `balltrack sim` refuses before sending: never looser than the simulator's first check)
    try:
        checked_form(request)
    except ValueError as error:
        assert str(error)
        return
    checked_request(request)


@pytest.mark.parametrize("request_, reason", [
    ({"op": "set_light"}, "set_light: give diffuse and/or ambient"),
    ({"op": "set_light", "ambient": "abc"}, "ambient: expected a number, got 'abc'"),
    ({"op": "set_light", "diffuse": 2}, "diffuse: must be between 0 and 1, got 2"),
    ({"op": "set_light", "ambient": [0.1, 1.5, 0.1]}, "ambient: values must be between 0 and 1, got [0.1, 1.5, 0.1]"),
    ({"op": "place_ball", "position": [1, 2]}, "place_ball: missing 'id'"),
    ({"op": "place_ball", "id": "tennis", "position": 1}, "position: expected [x, y] or [x, y, z], got 1"),
    ({"op": "place_robot", "x": 1}, "place_robot: 'x' and 'y' are required"),
    ({"op": "place_robot", "x": 1, "y": 2, "yaw": "q"}, "yaw: expected a number, got 'q'"),
    ({"op": "reset", "scenario": ""}, "scenario: expected a scenario name, got ''"),
])
def test_the_form_of_arguments_is_checked_without_a_world(request_, reason):
    with pytest.raises(ValueError) as raised:
        checked_form(request_)
    assert str(raised.value) == reason


@pytest.mark.parametrize("request_", [
    {"op": "reset"}, {"op": "reset", "scenario": "search"}, {"op": "set_light", "ambient": [0.1, 0.2, 0.3]},
    # (whether the ball exists and the place is inside the world, only the simulator knows)
    {"op": "place_ball", "id": "nosuch", "position": [99, 0]}, {"op": "place_robot", "x": 99, "y": 0, "yaw": 1},
])
def test_arguments_of_a_good_form_pass(request_):
    assert checked_form(request_) == checked_request(request_)


def test_good_request_keeps_its_arguments():
    assert checked_request({"op": "set_light", "diffuse": 0.2}) == ("set_light", {"diffuse": 0.2})


@pytest.mark.parametrize("value, expected", [(0.5, (0.5, 0.5, 0.5)), ([0.1, 0.2, 0.3], (0.1, 0.2, 0.3)),
                                             (0, (0.0, 0.0, 0.0))])
def test_light_level_takes_a_grey_or_rgb(value, expected):
    assert light_level("diffuse", value) == expected


@pytest.mark.parametrize("value", [1.5, -0.1, [0.1, 0.2], [0.1, math.nan, 0.2], True, "bright", None])
def test_light_level_refuses_what_is_not_a_level(value):
    with pytest.raises(ValueError, match="^diffuse"):
        light_level("diffuse", value)


def test_ball_is_named_by_its_id():
    assert ball_index("b", ["a", "b"]) == 1
    for bad in (None, True, "c", ["a"]):
        with pytest.raises(ValueError):
            ball_index(bad, ["a", "b"])


def test_ball_position_rests_on_the_floor_and_stays_in_the_world():
    assert ball_position([1.0, 2.0], 0.033, 5.0) == (1.0, 2.0, 0.033)
    assert ball_position((1, 2, 3), 0.033, 5.0) == (1.0, 2.0, 3.0)
    for bad in ([5.0, 0.0], [0.0, 0.0, -1.0], [0.0, 0.0, 11.0], [0.0], "here", [0.0, math.inf]):
        with pytest.raises(ValueError, match="^position"):
            ball_position(bad, 0.033, 5.0)


def test_robot_position_needs_both_coordinates_inside_the_limit():
    assert robot_position(1, -2.5, 4.8) == (1.0, -2.5)
    for x, y in ((None, 1.0), (1.0, None), (4.9, 0.0), (0.0, math.nan), ("1", 0.0)):
        with pytest.raises(ValueError):
            robot_position(x, y, 4.8)
