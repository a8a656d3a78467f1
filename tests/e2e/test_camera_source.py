"""A real source end to end: a video file of simulator frames, with the ground truth of every
frame kept aside, goes through camera -> detector -> locator as real processes over a real
router, and the 3D positions match the truth as closely as in live simulation.

The video is rendered in-process by the simulator core (``Simulation``, scenario ``moving``: a
tennis ball crossing the view 2 m ahead) and written as MJPEG, so the camera service, the
detector and the locator see nothing but an ordinary video file and an ideal-pinhole
CameraInfo from ``hfov``, the simulator's field of view.
"""

import math

import cv2
import pytest

from balltrack.services.simulator.config import SimulatorConfig
from balltrack.services.simulator.sim import Simulation
from tests.harness import Collector, fully_in_view

pytestmark = pytest.mark.slow

FRAMES = 60
WIDTH, HEIGHT, HFOV = 640, 480, 1.089


@pytest.fixture(scope="module")
def video_with_truth(tmp_path_factory):
    folder = tmp_path_factory.mktemp("video")
    path = folder / "moving.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 30.0, (WIDTH, HEIGHT))
    writer.set(cv2.VIDEOWRITER_PROP_QUALITY, 95)
    truths = []
    with Simulation(SimulatorConfig(scenario="moving", width=WIDTH, height=HEIGHT, hfov=HFOV)) as simulation:
        for _ in range(FRAMES):
            simulation.step_frame()
            writer.write(cv2.cvtColor(simulation.render(), cv2.COLOR_RGB2BGR))
            ball = simulation.ground_truth()["balls"][0]
            truths.append((ball["in_camera"], ball["radius"]))
    writer.release()
    return path, truths


def test_video_file_through_camera_detector_locator(session, launch, video_with_truth):
    path, truths = video_with_truth
    located = Collector(session, "detected_ball_3d", "Ball3D")
    infos = Collector(session, "camera/camera_info", "CameraInfo")
    launch("detector")
    launch("locator")
    # 15 frames/s: what two shared cores keep up with; the seq of each frame is its index.
    camera = launch("camera", f"source={path}", "rate_hz=15", f"hfov={HFOV}")
    assert camera.popen.wait(60) == 0, camera.output()  # the end of the file: a clean exit
    assert infos.wait_count(1, 5)[0]["fx"] == pytest.approx((WIDTH / 2) / math.tan(HFOV / 2))
    checkable = [seq for seq, (point, radius) in enumerate(truths) if fully_in_view(point, radius, WIDTH, HEIGHT, HFOV)]
    assert len(checkable) >= FRAMES // 2, "the scenario keeps the ball in view"
    positions = located.wait_for(
        lambda messages: len({m["header"]["seq"] for m in messages} & set(checkable)) >= len(checkable) * 3 // 4
        and messages, 30, "3/4 of the frames located")
    errors = []
    for message in positions:
        seq = message["header"]["seq"]
        if seq not in checkable:
            continue
        point, _ = truths[seq]
        truth = math.dist(point, (0, 0, 0))
        # The live pipeline's stated tolerance: distance within 5%, position within 5% of it.
        assert abs(message["distance"] - truth) < 0.05 * truth, (seq, point, message)
        assert math.dist((message["x"], message["y"], message["z"]), point) < 0.05 * truth, (seq, point, message)
        errors.append(math.dist((message["x"], message["y"], message["z"]), point) / truth)
    print(f"E2E camera source: {len(errors)} frames located, mean error {100 * sum(errors) / len(errors):.2f}% "
          f"of distance, worst {100 * max(errors):.2f}%")
