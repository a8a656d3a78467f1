"""Malformed requests over a real router (issue 12): every query is answered, nothing quoted
at length, logs stay small, and a bloated header is not passed on.

Each test drives real service processes through the test's router; waits are on replies and
messages with deadlines.
"""

import msgpack
import pytest
import zenoh

from balltrack.common.keys import SERVICES
from balltrack.common.messages import MAX_FRAME_ID, encode, header
from balltrack.services.simulator.control import send_command
from tests.harness import Collector, put_until, query_config, wait_matched

HUGE = "x" * 1_000_000
SMALL_FRAMES = ("width=160", "height=120", "pacing=realtime")


NESTED = "<nested>"


def with_nested(request: dict, depth: int) -> bytes:
    """``request`` packed with its NESTED value replaced by a list nested ``depth`` deep
    (msgpack unpacks up to 1,024 levels but packs only 511, so the bytes are spliced in)."""
    packed = msgpack.packb(request, use_bin_type=True)
    return packed.replace(msgpack.packb(NESTED), b"\x91" * (depth - 1) + b"\x90")


def ask_config(session, service: str, payload: bytes) -> dict:
    """One raw ``<service>/config`` query; the decoded reply (AssertionError if none)."""
    for reply in session.get(f"{service}/config", payload=payload, timeout=10.0):
        assert reply.ok is not None, reply.err.payload.to_string()
        return msgpack.unpackb(reply.ok.payload.to_bytes(), raw=False)
    raise AssertionError(f"{service}/config did not answer")


def rejected_count(session, service: str, at_least: int) -> int:
    stats = Collector(session, f"{service}/stats", "Stats")
    try:
        return stats.wait_for(lambda messages: next(
            (message["rejected"] for message in messages if message["rejected"] >= at_least), None),
            10, f"{service}/stats with rejected >= {at_least}")
    finally:
        stats.close()


def test_config_set_with_a_huge_string_is_answered_by_every_service(session, launch, tmp_path):
    import cv2
    import numpy as np

    # The camera needs a source that stays: one photo, looped.
    cv2.imwrite(str(tmp_path / "frame.png"), np.zeros((48, 64, 3), np.uint8))
    overrides = {"simulator": SMALL_FRAMES, "camera": (f"source={tmp_path}", "loop=true", "rate_hz=5")}
    processes = {name: launch(name, *overrides.get(name, ())) for name in SERVICES}
    for name in SERVICES:
        before = query_config(session, name)["config"]
        # A number field, or a boolean one for the ROS 2 bridge (it has no number): neither
        # takes a string.
        number_field = ([key for key, value in before.items() if isinstance(value, float)]
                        or [key for key, value in before.items() if isinstance(value, bool)])[0]
        for payload in (msgpack.packb({"set": {number_field: HUGE}}),
                        msgpack.packb({"set": {HUGE: 1}}),
                        with_nested({"set": {number_field: NESTED}}, 1000)):
            reply = ask_config(session, name, payload)
            assert reply["ok"] is False, (name, payload[:40])
            assert 0 < len(reply["error"]) < 1000, reply["error"][:200]
        assert query_config(session, name)["config"] == before  # unchanged, and still answering
        assert rejected_count(session, name, 3) >= 3
    for name, process in processes.items():
        assert len(process.output()) < 100_000, f"{name} logged the huge values"


def test_sim_control_answers_every_bad_scenario_and_reads_no_paths(session, launch, tmp_path):
    # A scenario file elsewhere on disk: reachable as a path, so it must be refused by name.
    outside = tmp_path / "outside.toml"
    outside.write_text('name = "outside"\n')
    simulator = launch("simulator", *SMALL_FRAMES)
    bad = [{"op": "reset", "scenario": scenario} for scenario in (
        HUGE, "../../../../etc/hostname", "/dev/zero", str(outside), "/etc/hostname",
        "no_such_scenario", "", 5, [[["chase"]]])]
    bad += [with_nested({"op": "reset", "scenario": NESTED}, 1000),
            {"op": "place_ball", "id": HUGE, "position": [1.0, 0.0]},
            with_nested({"op": "place_ball", "id": "tennis", "position": NESTED}, 1000),
            with_nested({"op": "set_light", "diffuse": NESTED}, 30)]
    for request in bad:
        reply = send_command(session, request, timeout=10.0)
        assert reply["ok"] is False, (str(request)[:80], reply)
        assert 0 < len(reply["error"]) < 1000, reply["error"][:200]
    # Many more of them: the log is rate-limited and never quotes a value at length.
    for _ in range(30):
        assert send_command(session, {"op": "reset", "scenario": HUGE}, timeout=10.0)["ok"] is False
    assert send_command(session, {"op": "reset", "scenario": "multi"}) == {"ok": True}
    assert send_command(session, {"op": "reset", "scenario": "chase.toml"}) == {"ok": True}
    log = simulator.output()
    assert len(log) < 100_000, f"simulator log is {len(log)} characters"


def test_sim_control_loads_files_of_the_configured_scenario_folder(session, launch, tmp_path):
    folder = tmp_path / "worlds"
    folder.mkdir()
    (folder / "start.toml").write_text('name = "start"\n')
    (folder / "second.toml").write_text(
        'name = "second"\n[[balls]]\nid = "golf"\nradius = 0.021\nposition = [1.0, 0.0]\n')
    (folder / "escape.toml").symlink_to("/etc/hostname")
    launch("simulator", *SMALL_FRAMES, f"scenario={folder / 'start.toml'}")
    truths = Collector(session, "sim/ground_truth", "GroundTruth")
    assert send_command(session, {"op": "reset", "scenario": "second"}) == {"ok": True}
    truths.wait_for(lambda messages: any(m["balls"] and m["balls"][0]["id"] == "golf"
                                         for m in messages), 20, "the second scenario's ball")
    assert send_command(session, {"op": "reset", "scenario": str(folder / "start.toml")}) == {"ok": True}
    for refused in ("escape", str(folder / "escape.toml"), str(folder / ".." / "outside.toml")):
        reply = send_command(session, {"op": "reset", "scenario": refused})
        assert reply["ok"] is False and "is not a scenario" in reply["error"], reply


def test_follower_passes_on_only_the_header_contract_fields(session, launch):
    launch("follower")  # keep_target (default): follows detected_balls
    commands = Collector(session, "cmd_vel", None)
    ball = {"x": 0.2, "y": 0.0, "z": 0.1, "u": 384.0, "v": 240.0, "radius_px": 32.0,
            "image_width": 640, "image_height": 480, "score": 1.0}
    bloated = {"header": {**header(1000, 41), "extra": HUGE}, "balls": [ball]}
    # (BLOCK: a 1 MB message is many fragments, and under load DROP may lose one of them)
    detections = session.declare_publisher("detected_balls", congestion_control=zenoh.CongestionControl.BLOCK)
    wait_matched(detections)  # (the follower's token may reach us before its subscription)
    detections.put(msgpack.packb(bloated, use_bin_type=True))
    long_frame = {"header": header(2000, 42, "f" * (MAX_FRAME_ID + 1)), "balls": [ball]}
    detections.put(msgpack.packb(long_frame, use_bin_type=True))

    def decoded(messages):
        return [msgpack.unpackb(m["payload"], raw=False) for m in messages]

    tracked = commands.wait_for(lambda messages: [c for c in decoded(messages)
                                                  if c["mode"] != "search"], 10, "a chase command")
    assert tracked[0]["header"] == {"stamp": 1000, "frame_id": "base_link", "seq": 41}
    assert max(len(message["payload"]) for message in commands.messages) < 1000
    assert not [c for c in decoded(commands.messages) if c["header"]["seq"] == 42]
    assert rejected_count(session, "follower", 1) >= 1  # the over-long frame_id
    detections.put(encode("Ball2DArray", {"header": header(3000, 43), "balls": [ball]}))
    commands.wait_for(lambda messages: [c for c in decoded(messages) if c["header"]["seq"] == 43],
                      10, "a command for the good detection after the bad ones")


@pytest.mark.parametrize("service", ["detector", "locator"])
def test_derived_messages_carry_no_extra_header_fields(session, launch, service):
    from tests.harness import draw_ball, floor_image
    from balltrack.common.images import bgr_to_message

    launch(service)
    if service == "detector":
        output = Collector(session, "detected_ball", None)
        image = bgr_to_message(draw_ball(floor_image(), 400, 300, 30), 1000, 7)
        message = {**image, "header": {**image["header"], "extra": HUGE}}
        key = "camera/image_raw"
    else:
        output = Collector(session, "detected_ball_3d", None)
        session.put("camera/camera_info", encode("CameraInfo", {
            "header": header(0, 0), "width": 640, "height": 480, "fx": 554.0, "fy": 554.0,
            "cx": 320.0, "cy": 240.0, "hfov": 1.089, "vfov": 0.85}))
        message = {"header": {**header(1000, 7), "extra": HUGE}, "x": 0.1, "y": 0.0, "z": 0.1,
                   "u": 352.0, "v": 240.0, "radius_px": 32.0, "image_width": 640,
                   "image_height": 480, "score": 1.0}
        key = "detected_ball"
    payload = msgpack.packb(message, use_bin_type=True)
    # The locator may not have its camera_info yet: resend until something comes out.
    produced = put_until(lambda _: session.put(key, payload), output, lambda messages: messages, 35, 0.5,
                         f"{service} output")
    unpacked = msgpack.unpackb(produced[0]["payload"], raw=False)
    assert set(unpacked["header"]) == {"stamp", "frame_id", "seq"}
    assert len(produced[0]["payload"]) < 1000
