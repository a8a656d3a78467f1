"""The camera service as a real process over a real router: photos, a video, a calibration
file, and the ways a source ends."""

import functools
import http.server
import re
import threading

import cv2
import numpy as np
import pytest

from balltrack.common.images import image_to_bgr
from balltrack.common.messages import decode
from balltrack.services.camera.calibration import CameraModel, write_calibration
from tests.harness import Collector, free_port, query_config, start_service

WIDTH, HEIGHT = 320, 240
CALIBRATION = CameraModel(WIDTH, HEIGHT, 300.0, 301.0, 158.0, 121.0, (-0.2, 0.05, 0.001, 0.0, 0.0), "bench")


def numbered_frame(index: int) -> np.ndarray:
    """A frame whose mean grey level tells its index, and a gradient so it is not flat."""
    image = np.full((HEIGHT, WIDTH, 3), 40 + 40 * index, np.uint8)
    image[:, :, 1] = np.linspace(0, 255, WIDTH, dtype=np.uint8)[None, :]
    return image


def index_of(image: np.ndarray) -> int:
    return int(round((float(image[:, :, 0].mean()) - 40) / 40))


@pytest.fixture
def photos(tmp_path):
    folder = tmp_path / "photos"
    folder.mkdir()
    for index in range(3):
        cv2.imwrite(str(folder / f"frame{index:02d}.png"), numbered_frame(index))
    (folder / "notes.txt").write_text("not an image, not read")
    return folder


def write_video(path, frames: int) -> None:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 30.0, (WIDTH, HEIGHT))
    for index in range(frames):
        writer.write(numbered_frame(index % 5))
    writer.release()


def test_photos_with_a_calibration_loop_in_order(session, launch, photos, tmp_path):
    calibration = tmp_path / "camera.yaml"
    write_calibration(calibration, CALIBRATION)
    images = Collector(session, "camera/image_raw", "Image")
    infos = Collector(session, "camera/camera_info", "CameraInfo")
    launch("camera", f"source={photos}", "rate_hz=20", "loop=true", "encoding=bgr8",
           f"calibration={calibration}")
    received = images.wait_count(8, 30)
    assert all((m["width"], m["height"], m["encoding"]) == (WIDTH, HEIGHT, "bgr8") for m in received)
    first = next(i for i, m in enumerate(received) if index_of(image_to_bgr(m)) == 0)
    # Lossless: the published frame is the photo; in name order, and again after the last.
    assert np.array_equal(image_to_bgr(received[first]), numbered_frame(0))
    order = [index_of(image_to_bgr(m)) for m in received[first:first + 6]]
    assert order == [0, 1, 2, 0, 1, 2], order
    seqs = [m["header"]["seq"] for m in received]
    assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)

    info = infos.wait_count(1, 10)[0]
    assert (info["width"], info["height"], info["fx"], info["fy"], info["cx"], info["cy"]) == \
        (WIDTH, HEIGHT, 300.0, 301.0, 158.0, 121.0)
    assert info["distortion_model"] == "plumb_bob" and info["d"] == list(CALIBRATION.distortion)
    # Answered as a query too, as the simulator does (a locator started late asks).
    replies = [reply for reply in session.get("camera/camera_info", timeout=5.0) if reply.ok is not None]
    assert len(replies) == 1

    # Live: the encoding changes; a source change is refused (it takes a restart; accepted, it
    # was reported as set while the camera went on with the old source).
    refused = query_config(session, "camera", {"source": str(tmp_path / "other.mp4")})
    assert not refused["ok"] and refused["error"].startswith("source: can only be set at start (live: ")
    assert query_config(session, "camera")["config"]["source"] != str(tmp_path / "other.mp4")
    # (and so is a width without its height: "give both or neither" was no news)
    refused = query_config(session, "camera", {"width": "320"})
    assert not refused["ok"] and refused["error"].startswith("width: can only be set at start (live: "), refused
    assert query_config(session, "camera", {"encoding": "jpeg"})["ok"]
    images.wait_for(lambda m: m[-1]["encoding"] == "jpeg", 10, "a jpeg frame")
    stats = Collector(session, "camera/stats", "Stats").wait_count(1, 5)[0]
    assert stats["rewinds"] >= 2 and stats["frames"] >= 8 and stats["unreadable_files"] == 0


def test_video_to_its_end_exits_0(session, router, tmp_path):
    video = tmp_path / "clip.avi"
    write_video(video, 12)
    images = Collector(session, "camera/image_raw", "Image")
    process = start_service("camera", router.endpoint, tmp_path, "--set", f"source={video}")
    assert process.popen.wait(60) == 0, process.output()
    received = images.wait_count(12, 10)
    assert [m["header"]["seq"] for m in received] == list(range(12))
    assert [index_of(image_to_bgr(m)) for m in received] == [index % 5 for index in range(12)]
    assert all(m["encoding"] == "jpeg" for m in received)
    assert "end of video" in process.output()


def test_video_loops(session, launch, tmp_path):
    video = tmp_path / "clip.avi"
    write_video(video, 5)
    images = Collector(session, "camera/image_raw", "Image")
    launch("camera", f"source={video}", "loop=true", "rate_hz=30")
    received = images.wait_count(12, 30)
    order = [index_of(image_to_bgr(m)) for m in received]
    first = order.index(0)
    assert order[first:first + 7] == [0, 1, 2, 3, 4, 0, 1], order


@pytest.mark.parametrize("overrides, expected", [
    (("source=/nonexistent/clip.mp4",), "camera: source: no such file, folder, device or URL: /nonexistent/clip.mp4"),
    (("source=/dev/video99",), "camera: source: no such device /dev/video99"),
    (("source=97",), "camera: source: cannot open device 97"),
    (("source=BAD_VIDEO",), "camera: source: cannot open video "),
    # (FFmpeg's own "[tcp @ 0x...] Connection refused" line is not printed before ours)
    (("source=http://127.0.0.1:CLOSED_PORT/clip.mp4",), "camera: source: cannot open video http://"),
    (("source=rtsp://127.0.0.1:CLOSED_PORT/cam",), "camera: source: cannot open stream rtsp://"),
    (("source=PHOTOS", "calibration=/nonexistent.yaml"), "camera: /nonexistent.yaml: cannot read"),
    # (photos none of which is an image: not "the end of the photos after 0 frames", status 0)
    (("source=NOT_IMAGES",), "camera: source: no file of NOT_IMAGES is an image OpenCV reads (2 tried; "),
    (("source=NOT_IMAGES", "loop=true"), "camera: source: no file of NOT_IMAGES is an image OpenCV reads"),
    (("source=PHOTOS", "calibration=WRONG_SIZE"), "camera: calibration: calibration is for 640x360"),
])
def test_bad_source_or_calibration_exits_2_with_one_line(session, router, tmp_path, photos, overrides, expected):
    bad_video = tmp_path / "broken.mp4"
    bad_video.write_bytes(b"\x00" * 4096)
    wrong_size = tmp_path / "wide.yaml"
    write_calibration(wrong_size, CameraModel(640, 360, 500.0, 500.0, 320.0, 180.0))
    not_images = tmp_path / "not_images"
    not_images.mkdir()
    for name in ("a.jpg", "b.png"):
        (not_images / name).write_text("not an image")
    replacements = {"CLOSED_PORT": str(free_port()), "BAD_VIDEO": str(bad_video), "PHOTOS": str(photos), "WRONG_SIZE": str(wrong_size),
                    "NOT_IMAGES": str(not_images)}
    arguments = []
    for override in overrides:
        for placeholder, value in replacements.items():
            override = override.replace(placeholder, value)
            expected = expected.replace(placeholder, value)
        arguments += ["--set", override]
    process = start_service("camera", router.endpoint, tmp_path, *arguments)
    assert process.popen.wait(60) == 2, process.output()
    errors = [line for line in process.output().splitlines() if line.startswith("camera: ")]
    assert len(errors) == 1 and errors[0].startswith(expected), process.output()
    assert "Traceback" not in process.output()
    # Besides it, only the service's own log lines (no FFmpeg "[tcp @ 0x...]" line).
    others = [line for line in process.output().splitlines()
              if line.strip() and line not in errors and " camera INFO " not in line]
    assert not others, process.output()


@pytest.mark.parametrize("name", ["camera+ros2_bridge", "ros2_bridge+camera"])
def test_a_refused_source_stops_a_process_of_several_services_whichever_loop_it_is(router, tmp_path, photos, name):
    # (the first service's loop runs in a thread of its own: what it refused was a traceback
    # there, and the process went on without its camera; a calibration is checked against the
    # frames only once they come)
    pytest.importorskip("rosbags")
    wrong_size = tmp_path / "wide.yaml"
    write_calibration(wrong_size, CameraModel(640, 360, 500.0, 500.0, 320.0, 180.0))
    process = start_service(name, router.endpoint, tmp_path, "--set", f"camera.source={photos}",
                            "--set", f"camera.calibration={wrong_size}")
    assert process.popen.wait(60) == 2, process.output()
    errors = [line for line in process.output().splitlines() if line.startswith(f"{name}: ")]
    assert len(errors) == 1 and errors[0].startswith(f"{name}: calibration: calibration is for 640x360"), \
        process.output()
    assert "Traceback" not in process.output()


@pytest.mark.parametrize("name, overrides, expected", [
    ("camera", ("source=/nonexistent/clip.mp4",), "camera: source: no such file, folder, device or URL"),
    ("camera", ("calibration=/nonexistent.yaml",), "camera: /nonexistent.yaml: cannot read"),
    # (photos none of which is an image: found out before a router answers, nor logged as running)
    ("camera", ("source=NOT_IMAGES",), "camera: source: no file of NOT_IMAGES is an image OpenCV reads (1 tried; "),
    # (of several services, which one it is for)
    ("camera+detector", ("camera.source=/nonexistent/clip.mp4",), "camera+detector: camera: source: no such file"),
])
def test_a_missing_file_exits_2_before_a_router_answers(tmp_path, name, overrides, expected):
    # Nobody listens there: a service waits for its router, but not to report a typo in a path.
    not_images = tmp_path / "not_images"
    not_images.mkdir()
    (not_images / "a.jpg").write_text("not an image")
    overrides = [override.replace("NOT_IMAGES", str(not_images)) for override in overrides]
    expected = expected.replace("NOT_IMAGES", str(not_images))
    arguments = [item for override in overrides for item in ("--set", override)]
    process = start_service(name, f"tcp/127.0.0.1:{free_port()}", tmp_path, *arguments)
    assert process.popen.wait(60) == 2, process.output()
    assert process.output().strip().startswith(expected), process.output()
    assert len(process.output().strip().splitlines()) == 1, process.output()


def test_unreadable_photos_are_skipped_and_counted(session, launch, photos):
    (photos / "frame01.png").write_bytes(b"not a png")
    images = Collector(session, "camera/image_raw", "Image")
    launch("camera", f"source={photos}/*.png", "rate_hz=20", "loop=true", "encoding=bgr8")
    received = images.wait_count(6, 30)
    assert set(index_of(image_to_bgr(m)) for m in received) == {0, 2}
    # Counted once, though each pass of the loop tries it again.
    stats = Collector(session, "camera/stats", "Stats").wait_for(
        lambda m: m and m[-1]["rewinds"] >= 2 and m[-1], 10, "two passes")
    assert stats["unreadable_files"] == 1


def test_status_shows_the_camera_s_own_figures(session, launch, router, photos):
    from tests.integration.test_cli import balltrack

    (photos / "frame01.png").write_bytes(b"not a png")
    launch("camera", f"source={photos}/*.png", "rate_hz=20", "loop=true")
    Collector(session, "camera/stats", "Stats").wait_for(lambda m: m and m[-1]["frames"] >= 1, 10, "camera stats")
    status = balltrack("status", "--connect", router.endpoint)
    assert status.returncode == 0, status.stderr
    rows = {line.split()[0]: line for line in status.stdout.splitlines()[1:]}
    assert status.stdout.splitlines()[0].split()[-1] == "other"
    assert re.search(r" frames=[1-9]\d* .*unreadable_files=1\b", rows["camera"]), status.stdout


def test_a_new_frame_size_is_announced_before_its_frame(session, launch, tmp_path):
    # Photos of two sizes in turn, faster than the once-a-second CameraInfo: each frame's size
    # must be the latest CameraInfo's when the frame arrives, or a locator uses the other size's.
    folder = tmp_path / "sizes"
    folder.mkdir()
    for index in range(4):
        image = numbered_frame(index % 3)
        cv2.imwrite(str(folder / f"frame{index:02d}.png"), image if index % 2 == 0 else image[::2, ::2])
    arrivals = Collector(session, "camera/*", None)  # one subscriber: both keys in arrival order
    launch("camera", f"source={folder}", "rate_hz=20", "loop=true", "encoding=bgr8")

    def images(messages):
        return [item for item in messages if item["key"] == "camera/image_raw"]

    arrivals.wait_for(lambda messages: len(images(messages)) >= 12, 30, "12 frames")
    latest_size, checked = None, 0
    for item in list(arrivals.messages):
        if item["key"] == "camera/camera_info":
            info = decode("CameraInfo", item["payload"])
            latest_size = (info["width"], info["height"])
        elif item["key"] == "camera/image_raw" and latest_size is not None:
            image = decode("Image", item["payload"])
            assert (image["width"], image["height"]) == latest_size, image["header"]["seq"]
            checked += 1
    assert checked >= 10


def test_a_video_served_over_http_plays_at_its_rate_to_its_end(session, router, tmp_path):
    # A URL naming a video file is a video, not a live stream: paced at the file's 30 fps (a
    # stream is sent as fast as it delivers) and ended with status 0 (a stream is reopened).
    write_video(tmp_path / "clip.avi", 12)
    handler = functools.partial(http.server.SimpleHTTPRequestHandler, directory=str(tmp_path))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        images = Collector(session, "camera/image_raw", "Image")
        url = f"http://127.0.0.1:{server.server_address[1]}/clip.avi"
        process = start_service("camera", router.endpoint, tmp_path, "--set", f"source={url}")
        assert process.popen.wait(60) == 0, process.output()
        received = images.wait_count(12, 10)
    finally:
        server.shutdown()
        server.server_close()
    assert [index_of(image_to_bgr(m)) for m in received] == [index % 5 for index in range(12)]
    assert "end of video" in process.output()
    stamps = [m["header"]["stamp"] for m in received]
    # 11 intervals at 30 fps: 367 ms; unpaced, a 12-frame file is read in a few milliseconds.
    assert (stamps[-1] - stamps[0]) / 1e9 > 0.3
