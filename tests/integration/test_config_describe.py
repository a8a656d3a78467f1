"""The parameters' declarations over a real router: ``{"describe": true}`` on ``<service>/config``,
``balltrack config SERVICE --describe``, a choice (the locator's ``mode``) changed live, and a
request with an unknown field refused."""

import json
import math
import subprocess
import sys

import msgpack
import pytest

from balltrack.common.config import describe_config
from balltrack.common.messages import decode, encode
from balltrack.services.locator.config import LocatorConfig
from tests.harness import REPO, Collector, process_environment, query_config
from tests.integration.test_locator_service import CAMERA_INFO, HFOV, ball_message


def ask(session, service: str, request: dict, timeout: float = 5.0) -> dict:
    # Packed without validation, so that a bad request reaches the service.
    payload = msgpack.packb(request, use_bin_type=True)
    for reply in session.get(f"{service}/config", payload=payload, timeout=timeout):
        if reply.ok is not None:
            return decode("ConfigReply", reply.ok.payload.to_bytes())
    raise AssertionError(f"{service}/config did not answer")


@pytest.fixture
def locator(launch):
    return launch("locator")


def test_describe_over_the_router_and_from_the_command(router, session, locator):
    reply = ask(session, "locator", {"describe": True})
    assert reply["ok"] and reply["parameters"] == describe_config(LocatorConfig)
    assert reply["parameters"]["mode"]["choices"] == ["auto", "exact", "faithful"]
    assert "parameters" not in ask(session, "locator", {}), "a plain read stays as it was"
    # A change and a description in one request: the reply has both, the change applied.
    both = ask(session, "locator", {"set": {"ball_radius": 0.04}, "describe": True})
    assert both["ok"] and both["config"]["ball_radius"] == 0.04 and "h_fov" in both["parameters"]
    refused = ask(session, "locator", {"describe": "yes"})
    assert not refused["ok"] and refused["error"].startswith("describe:")

    command = subprocess.run([sys.executable, "-m", "balltrack", "config", "locator", "--describe",
                              "--connect", router.endpoint], capture_output=True, text=True,
                             timeout=60, cwd=REPO, env=process_environment())
    assert command.returncode == 0, command.stderr
    assert json.loads(command.stdout) == describe_config(LocatorConfig)


def test_a_request_with_an_unknown_field_is_refused_and_changes_nothing(session, locator):
    before = query_config(session, "locator")["config"]
    typo = ask(session, "locator", {"sett": {"ball_radius": 0.05}})
    assert not typo["ok"] and "'sett'" in typo["error"], typo
    many = ask(session, "locator", {f"key{index}": index for index in range(100_000)})
    assert not many["ok"] and len(many["error"]) < 400, many
    assert query_config(session, "locator")["config"] == before


def test_a_choice_changed_live_is_a_plain_string_and_takes_effect(session, locator):
    output = Collector(session, "detected_ball_3d", "Ball3D")
    session.put("camera/camera_info", encode("CameraInfo", CAMERA_INFO))
    reply = query_config(session, "locator", {"mode": "faithful"})
    assert reply["ok"] and reply["config"]["mode"] == "faithful" and type(reply["config"]["mode"]) is str
    # Faithful despite the CameraInfo just sent: the paper's equations 1-2.
    message = ball_message((0.0, 0.0, 1.0), 7)
    session.put("detected_ball", encode("Ball2D", message))
    position = output.wait_count(1, 10)[0]
    assert position["distance"] == pytest.approx(0.033 / math.tan(message["z"] * HFOV / 2), abs=1e-9)

    bad = query_config(session, "locator", {"mode": "warp"})
    assert not bad["ok"] and bad["error"] == "mode: must be one of auto, exact, faithful, got 'warp'"
    assert query_config(session, "locator")["config"]["mode"] == "faithful"
