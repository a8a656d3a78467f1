"""Services of a local router joined as peers (``--peer``, as the launcher starts them): they
link to each other directly, so their messages flow even with the router gone."""

import re
import subprocess
import sys

from balltrack.common.images import bgr_to_message
from balltrack.common.messages import decode, encode
from balltrack.common.recording import RecordingFile
from balltrack.common.session import open_session
from tests.harness import Collector, Process, REPO, draw_ball, floor_image, put_until, start_service, wait_until
from tests.integration.test_pipeline import CAMERA_INFO, INTRINSICS, POINTS
from balltrack.services.locator.projection import project_sphere


def frame_message(seq: int) -> bytes:
    u, v, radius = project_sphere(POINTS[1], 0.033, INTRINSICS)
    image = draw_ball(floor_image(640, 480, seq), u, v, radius)
    return encode("Image", bgr_to_message(image, 1_000_000_000 * seq, seq))


def round_trips_across_router_stop(session, router, answers: Collector) -> None:
    """Frame 1 put until its answer (header seq 1) arrives in ``answers``; then the router
    stopped, and frame 2 put until its answer arrives too: the peers' direct links carry it."""
    put_until(lambda _: session.put("camera/image_raw", frame_message(1)), answers,
              lambda items: [item for item in items if item["header"]["seq"] == 1], 60, 1, "seq 1")
    assert router.stop() == 0, router.process.output()
    put_until(lambda _: session.put("camera/image_raw", frame_message(2)), answers,
              lambda items: [item for item in items if item["header"]["seq"] == 2], 20, 1,
              "seq 2 with the router stopped")


def test_peers_keep_exchanging_messages_without_their_router(router, log_dir):
    services = [start_service(name, router.endpoint, log_dir, "--peer") for name in ("detector", "locator")]
    session = open_session([router.endpoint], open_timeout=10, peer=True)
    try:
        # The router tells each peer of the others; each then links to them directly.
        wait_until(lambda: len(list(session.info.peers_zid())) >= 2, 60,
                   "direct links to the detector and the locator", *services)
        located = Collector(session, "detected_ball_3d", "Ball3D")
        session.put("camera/camera_info", encode("CameraInfo", CAMERA_INFO))
        # With the router gone, frame -> detector -> locator -> here still goes round.
        round_trips_across_router_stop(session, router, located)
        located.close()
    finally:
        session.close()
        for service in services:
            assert service.stop() == 0, service.output()


def test_a_peer_recorder_records_the_peers_with_their_router_gone(router, log_dir, tmp_path):
    """``balltrack record --peer`` (as the demo starts it): the detector's answers reach the
    recording over their direct link, so it keeps recording them when the router stops."""
    path = tmp_path / "peers.mcap"
    detector = start_service("detector", router.endpoint, log_dir, "--peer")
    recorder = Process([sys.executable, "-m", "balltrack", "record", "--peer", "-o", str(path),
                        "--connect", router.endpoint, "--progress", "0.1", "detected_ball"],
                       tmp_path / "record.log")
    recorder.wait_for_output("recording", 30)
    session = open_session([router.endpoint], open_timeout=10, peer=True)
    try:
        wait_until(lambda: len(list(session.info.peers_zid())) >= 2, 60,
                   "direct links to the detector and the recorder", detector, recorder)
        detected = Collector(session, "detected_ball", "Ball2D")
        round_trips_across_router_stop(session, router, detected)
        detected.close()
        # (the recorder's progress lines count what it wrote: as many as arrived here)
        wait_until(lambda: written(recorder) >= len(detected.messages), 30,
                   f"{len(detected.messages)} messages written", recorder)
    finally:
        session.close()
        assert detector.stop() == 0, detector.output()
    assert recorder.stop() == 0, recorder.output()
    with RecordingFile(path) as recording:
        seqs = {decode("Ball2D", message.payload)["header"]["seq"]
                for message in recording.messages(["detected_ball"])}
    assert seqs == {1, 2}


def written(recorder: Process) -> int:
    """The last count of messages written that ``balltrack record --progress`` printed."""
    counts = re.findall(r"(\d+) messages written", recorder.output())
    return int(counts[-1]) if counts else 0


def test_peer_refuses_a_secure_profile_in_one_line(tmp_path):
    finished = subprocess.run([sys.executable, "-m", "balltrack.services.locator", "--peer", "--secure",
                               str(tmp_path)], capture_output=True, text=True, timeout=60, cwd=REPO)
    assert finished.returncode == 2
    assert finished.stderr.count("\n") == 1 and "--peer" in finished.stderr, finished.stderr
