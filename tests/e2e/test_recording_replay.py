"""A recorded chase, replayed into a fresh detector and locator, gives the live run's
``detected_ball_3d`` bit for bit.

Live: ``balltrack record`` records ``camera/image_raw``, ``camera/camera_info`` and
``detected_ball_3d`` while the simulator (lockstep, so every frame is processed), the detector,
the locator and the follower chase the ball. Replay: those processes are stopped, a fresh
detector and locator are started, and ``balltrack play --keys camera/image_raw
camera/camera_info --rate 0.5`` publishes the recorded frames again. The detector is
deterministic, so for every frame both runs processed, x, y, z, distance and the header must be
identical. The replaying detector may drop a frame on a loaded machine (it takes the newest);
the frames it did process are all compared. Figures are printed with ``E2E`` in front.
"""

import subprocess
import sys
import threading

import pytest

from balltrack.common.messages import decode
from balltrack.common.recording import RecordingFile
from tests.harness import REPO, Collector, Liveliness, Process, process_environment

pytestmark = [pytest.mark.slow, pytest.mark.timeout(600)]

BALLTRACK = [sys.executable, "-m", "balltrack"]
LIVE_POSITIONS = 120  # about 4 s of simulated time with the ball in view


class LatestStats:
    """The newest ``detector/stats``."""

    def __init__(self, session):
        self.latest: dict = {}
        self._lock = threading.Lock()

        def on_sample(sample):
            with self._lock:
                self.latest = decode("Stats", sample.payload.to_bytes())

        self.subscriber = session.declare_subscriber("detector/stats", on_sample)

    def dropped(self) -> int:
        with self._lock:
            return self.latest.get("dropped", 0)


def test_replayed_chase_gives_the_live_positions(router, session, launch, tmp_path):
    path = tmp_path / "chase.mcap"
    recorder = Process([*BALLTRACK, "record", "-o", str(path), "camera/image_raw",
                        "camera/camera_info", "detected_ball_3d", "--connect", router.endpoint],
                       tmp_path / "record.log")
    recorder.wait_for_output("recording", 30)
    live = Collector(session, "detected_ball_3d", "Ball3D")
    detector, locator = launch("detector"), launch("locator")
    follower = launch("follower", "use_sim_time=true", "max_size_thresh=0.3")
    simulator = launch("simulator", "pacing=lockstep", "lockstep_timeout=5", "image_noise=2",
                       "seed=1")
    live.wait_count(LIVE_POSITIONS, timeout=240)
    # The simulator first: no new frame after it, so the recording ends with the pipeline idle.
    for process in (simulator, follower, detector, locator):
        assert process.stop() == 0, process.output()
    assert recorder.stop() == 0, recorder.output()
    live.close()

    with RecordingFile(path) as recording:
        messages = list(recording.messages())
    recorded = {}
    for message in messages:
        if message.key == "detected_ball_3d":
            position = decode("Ball3D", message.payload)
            recorded[position["header"]["seq"]] = position
    frames = sum(message.key == "camera/image_raw" for message in messages)
    assert len(recorded) >= LIVE_POSITIONS and frames >= LIVE_POSITIONS

    gone = Liveliness(session)
    for name in ("detector", "locator"):
        gone.wait(name, alive=False, timeout=20)
    launch("detector"), launch("locator")
    replayed = Collector(session, "detected_ball_3d", "Ball3D")
    answers = Collector(session, "detected_balls", "Ball2DArray")
    stats = LatestStats(session)
    # The live locator knew the camera before frame 1 (it asked the simulator); the recording
    # may hold frame 1 before the first camera_info, so the replaying locator gets it first too.
    described = subprocess.run([*BALLTRACK, "play", str(path), "--keys", "camera/camera_info", "--rate", "0",
                                "--connect", router.endpoint], capture_output=True, text=True, cwd=REPO,
                               env=process_environment(), timeout=60)
    assert described.returncode == 0, described.stderr
    result = subprocess.run([*BALLTRACK, "play", str(path), "--keys", "camera/image_raw",
                             "camera/camera_info", "--rate", "0.5", "--connect", router.endpoint],
                            capture_output=True, text=True, cwd=REPO, env=process_environment(),
                            timeout=400)
    assert result.returncode == 0, result.stderr
    # Every frame is accounted for (answered or dropped by the detector), then every frame
    # with a ball has its position.
    answers.wait_for(lambda items: len(items) + stats.dropped() >= frames, 60,
                     f"{frames} frames answered or dropped")
    with_ball = {item["header"]["seq"] for item in answers.messages if item["balls"]}
    replayed.wait_for(lambda items: with_ball <= {item["header"]["seq"] for item in items}, 30,
                      "a position for every frame with a ball")

    positions = {item["header"]["seq"]: item for item in replayed.messages}
    matched = sorted(set(positions) & set(recorded))
    difference = max((abs(positions[seq][field] - recorded[seq][field])
                      for seq in matched for field in ("x", "y", "z", "distance")), default=None)
    print(f"\nE2E replay: {frames} frames recorded, {len(recorded)} live positions, "
          f"{len(positions)} replayed, {len(matched)} matched, max difference {difference}, "
          f"{stats.dropped()} frames dropped by the replaying detector", flush=True)
    # (The last frame or two may have been recorded while its live position was in flight.)
    unexpected = sorted(seq for seq in set(positions) - set(recorded) if seq < max(recorded))
    assert not unexpected, unexpected[:10]
    assert len(matched) >= len(recorded) // 2
    for seq in matched:
        assert positions[seq] == recorded[seq], (seq, positions[seq], recorded[seq])
