"""Services of a local router joined as peers (``--peer``, as the launcher starts them): they
link to each other directly, so their messages flow even with the router gone."""

import subprocess
import sys

from balltrack.common.images import bgr_to_message
from balltrack.common.messages import encode
from balltrack.common.session import open_session
from tests.harness import Collector, REPO, draw_ball, floor_image, put_until, start_service, wait_until
from tests.integration.test_pipeline import CAMERA_INFO, INTRINSICS, POINTS
from balltrack.services.locator.projection import project_sphere


def frame_message(seq: int) -> bytes:
    u, v, radius = project_sphere(POINTS[1], 0.033, INTRINSICS)
    image = draw_ball(floor_image(640, 480, seq), u, v, radius)
    return encode("Image", bgr_to_message(image, 1_000_000_000 * seq, seq))


def test_peers_keep_exchanging_messages_without_their_router(router, log_dir):
    services = [start_service(name, router.endpoint, log_dir, "--peer") for name in ("detector", "locator")]
    session = open_session([router.endpoint], open_timeout=10, peer=True)
    try:
        # The router tells each peer of the others; each then links to them directly.
        wait_until(lambda: len(list(session.info.peers_zid())) >= 2, 60,
                   "direct links to the detector and the locator", *services)
        located = Collector(session, "detected_ball_3d", "Ball3D")
        session.put("camera/camera_info", encode("CameraInfo", CAMERA_INFO))
        put_until(lambda _: session.put("camera/image_raw", frame_message(1)), located,
                  lambda items: [item for item in items if item["header"]["seq"] == 1], 60, 1, "seq 1")
        assert router.stop() == 0, router.process.output()
        # With the router gone, frame -> detector -> locator -> here still goes round.
        put_until(lambda _: session.put("camera/image_raw", frame_message(2)), located,
                  lambda items: [item for item in items if item["header"]["seq"] == 2], 20, 1,
                  "seq 2 with the router stopped")
        located.close()
    finally:
        session.close()
        for service in services:
            assert service.stop() == 0, service.output()


def test_peer_refuses_a_secure_profile_in_one_line(tmp_path):
    finished = subprocess.run([sys.executable, "-m", "balltrack.services.locator", "--peer", "--secure",
                               str(tmp_path)], capture_output=True, text=True, timeout=60, cwd=REPO)
    assert finished.returncode == 2
    assert finished.stderr.count("\n") == 1 and "--peer" in finished.stderr, finished.stderr
