"""The locator as a real process over a real router."""

import math

import pytest

from balltrack.common.messages import encode, header
from balltrack.common.pinhole import Intrinsics
from balltrack.services.locator.projection import project_sphere
from tests.harness import Collector, garbage_payloads, put_until, query_config

WIDTH, HEIGHT, HFOV = 640, 480, 1.089
INTRINSICS = Intrinsics.from_fov(WIDTH, HEIGHT, HFOV)


def camera_info(intrinsics):
    return {"header": header(0, 0), "width": intrinsics.width, "height": intrinsics.height,
            "fx": intrinsics.fx, "fy": intrinsics.fy, "cx": intrinsics.cx, "cy": intrinsics.cy,
            "hfov": intrinsics.h_fov, "vfov": intrinsics.v_fov}


CAMERA_INFO = camera_info(INTRINSICS)


def ball_message(point, seq, radius=0.033, intrinsics=INTRINSICS):
    u, v, radius_px = project_sphere(point, radius, intrinsics)
    width, height = intrinsics.width, intrinsics.height
    return {"header": header(1_000_000 + seq, seq), "x": (u - width / 2) / (width / 2),
            "y": (v - height / 2) / (height / 2), "z": 2 * radius_px / width, "u": u, "v": v,
            "radius_px": radius_px, "image_width": width, "image_height": height, "score": 1.0}


def since(positions: list[dict], seq: int) -> list[dict]:
    return [position for position in positions if position["header"]["seq"] >= seq]


@pytest.fixture
def locator(launch):
    return launch("locator")


def test_exact_positions_then_live_config_then_clean_exit(session, locator):
    output = Collector(session, "detected_ball_3d", "Ball3D")
    session.put("camera/camera_info", encode("CameraInfo", CAMERA_INFO))
    # Exact mode starts once CameraInfo is in; wait until a located ball shows it is.
    points = [(0.0, 0.05, 0.3), (0.4, 0.1, 1.0), (-0.9, 0.05, 2.0), (1.5, -0.2, 3.5)]
    put_until(lambda attempt: session.put("detected_ball", encode("Ball2D", ball_message(points[0], attempt))),
              output, lambda m: m and abs(m[-1]["z"] - 0.3) < 0.003, 20, 0.1, "exact mode")
    for seq, point in enumerate(points, start=1000):
        session.put("detected_ball", encode("Ball2D", ball_message(point, seq)))
    # (picked by seq: under load, the answer to one of put_until's later attempts can come after)
    located = output.wait_for(lambda m: len(since(m, 1000)) >= len(points) and since(m, 1000), 10,
                              "4 positions")[:len(points)]
    assert [position["header"]["seq"] for position in located] == [1000, 1001, 1002, 1003]
    for point, position in zip(points, located):
        truth = math.dist(point, (0, 0, 0))
        assert position["header"]["frame_id"] == "camera_optical"
        # Exact inverse of the projection: within 0.5% of distance, tolerances stated.
        assert math.dist((position["x"], position["y"], position["z"]), point) < 0.005 * truth
        assert abs(position["distance"] - truth) < 0.005 * truth

    reply = query_config(session, "locator", {"ball_radius": 0.066})
    assert reply["ok"] and reply["config"]["ball_radius"] == 0.066
    session.put("detected_ball", encode("Ball2D", ball_message(points[1], 2000)))
    moved = output.wait_for(lambda m: since(m, 2000), 10, "position after config change")[0]
    assert abs(moved["distance"] - 2 * math.dist(points[1], (0, 0, 0))) < 0.02

    bad = query_config(session, "locator", {"ball_radius": -1})
    assert not bad["ok"] and "ball_radius" in bad["error"]
    assert query_config(session, "locator")["config"]["ball_radius"] == 0.066


def test_faithful_mode_without_camera_info(session, locator):
    output = Collector(session, "detected_ball_3d", "Ball3D")
    message = ball_message((0.0, 0.0, 1.0), 7)
    session.put("detected_ball", encode("Ball2D", message))
    position = output.wait_count(1, 10)[0]
    expected = 0.033 / math.tan(message["z"] * HFOV / 2)  # paper eq. 1-2
    assert abs(position["distance"] - expected) < 1e-9
    assert position["header"] == message["header"] | {"frame_id": "camera_optical"}


def test_survives_every_kind_of_bad_input(session, locator):
    output = Collector(session, "detected_ball_3d", "Ball3D")
    stats = Collector(session, "locator/stats", "Stats")
    good = ball_message((0.2, 0.0, 1.5), 1)
    session.put("detected_ball", encode("Ball2D", good))
    output.wait_count(1, 10)
    cases = garbage_payloads(good) + garbage_payloads(CAMERA_INFO)
    for label, payload in garbage_payloads(good):
        session.put("detected_ball", payload)
    for label, payload in garbage_payloads(CAMERA_INFO):
        session.put("camera/camera_info", payload)
    good_after = ball_message((0.2, 0.0, 1.5), 2)
    session.put("detected_ball", encode("Ball2D", good_after))
    output.wait_count(2, 10)
    assert output.messages[1]["header"]["seq"] == 2
    stats.wait_for(lambda m: m and m[-1]["rejected"] >= len(cases), 5, f"{len(cases)} rejected")
    assert "rejected message on detected_ball" in locator.output()


def test_each_frame_size_is_located_with_its_own_camera_info(session, locator):
    # Photos from two cameras: another size, lens and principal point. Detections of the first
    # size still arrive after the second size's CameraInfo; each is located with its own.
    other = Intrinsics(250.0, 252.0, 170.0, 110.0, 320, 240)
    output = Collector(session, "detected_ball_3d", "Ball3D")
    point = (0.3, -0.1, 1.2)
    truth = math.dist(point, (0, 0, 0))
    intrinsics_of = {0: INTRINSICS, 1: other}

    def both_exact(messages):
        latest = {message["header"]["seq"] % 2: message for message in messages}
        return len(latest) == 2 and all(abs(message["distance"] - truth) < 0.005 * truth
                                        for message in latest.values())

    def put(attempt):
        # Both CameraInfos each time (one put before the locator subscribed is lost), the
        # other size's last.
        for size in (1 - attempt % 2, attempt % 2):
            session.put("camera/camera_info", encode("CameraInfo", camera_info(intrinsics_of[size])))
        session.put("detected_ball", encode(
            "Ball2D", ball_message(point, attempt, intrinsics=intrinsics_of[1 - attempt % 2])))

    put_until(put, output, both_exact, 40, 0.1, "both sizes located exactly")
    for position in output.messages[-2:]:
        assert math.dist((position["x"], position["y"], position["z"]), point) < 0.005 * truth


def test_exact_mode_rejects_a_size_without_camera_info_and_faithful_uses_the_cameras_fov(session, launch):
    launch("locator", "mode=exact")
    output = Collector(session, "detected_ball_3d", "Ball3D")
    stats = Collector(session, "locator/stats", "Stats")
    narrow = Intrinsics.from_fov(WIDTH, HEIGHT, 0.62)
    put_until(lambda attempt: session.put("detected_ball", encode(
                  "Ball2D", ball_message((0.0, 0.0, 1.0), attempt, intrinsics=narrow))),
              stats, lambda m: m and m[-1]["rejected"] >= 1, 20, 0.5, "a rejected detection")
    assert not output.messages  # not located with the faithful model instead

    def put(attempt):
        session.put("camera/camera_info", encode("CameraInfo", camera_info(narrow)))
        session.put("detected_ball", encode("Ball2D", ball_message((0.0, 0.0, 1.0), 100 + attempt,
                                                                   intrinsics=narrow)))

    put_until(put, output, lambda m: m, 20, 0.1, "a located ball once CameraInfo came")
    assert abs(output.messages[-1]["distance"] - 1.0) < 0.005
    # Faithful with CameraInfo: the camera's 0.62 rad, not the configured 1.089.
    assert query_config(session, "locator", {"mode": "faithful"})["ok"]
    message = ball_message((0.0, 0.0, 1.0), 500, intrinsics=narrow)
    start = len(output.messages)
    session.put("detected_ball", encode("Ball2D", message))
    position = output.wait_for(lambda m: m[start:], 10, "a faithful position")[0]
    assert abs(position["distance"] - 0.033 / math.tan(message["z"] * narrow.h_fov / 2)) < 1e-9
