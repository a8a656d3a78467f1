"""The balltrack command against a real router and services."""

import json
import re
import signal
import subprocess
import sys
import time
import tomllib

import cv2
import numpy as np
import pytest

from balltrack.common.images import bgr_to_message
from balltrack.common.messages import encode
from balltrack.experiments.base import development_photos
from tests.harness import (REPO, Collector, Liveliness, Process, client, draw_ball, floor_image, free_port,
                           process_environment, start_service)
from tests.integration.test_pipeline import CAMERA_INFO


def balltrack(*arguments, timeout=60):
    return subprocess.run([sys.executable, "-m", "balltrack", *arguments], capture_output=True,
                          text=True, timeout=timeout, cwd=REPO, env=process_environment())


def test_detect_offline_prints_one_json_line_per_image(tmp_path):
    ball = tmp_path / "ball.png"
    cv2.imwrite(str(ball), draw_ball(floor_image(), 200.0, 300.0, 25.0))
    empty = tmp_path / "empty.png"
    cv2.imwrite(str(empty), floor_image())
    result = balltrack("detect", str(ball), str(empty))
    assert result.returncode == 0, result.stderr
    lines = [json.loads(line) for line in result.stdout.splitlines()]
    assert [line["file"] for line in lines] == [str(ball), str(empty)]
    (found,) = lines[0]["balls"]
    assert abs(found["u"] - 200) < 1.5 and abs(found["v"] - 300) < 1.5
    assert abs(found["radius_px"] - 25) < 2.5 and 0 < found["score"] <= 1
    assert lines[1]["balls"] == []


def test_detect_explains_a_found_ball_and_a_pale_one(tmp_path):
    # A ball of felt colour, and one washed out to a saturation far below s_min (80).
    image = draw_ball(draw_ball(floor_image(), 200.0, 300.0, 25.0), 450.0, 200.0, 25.0, colour=(170, 200, 195))
    photo = tmp_path / "two.png"
    cv2.imwrite(str(photo), image)
    result = balltrack("detect", str(photo), "--explain", "200,300", "--explain", "450.0,200")
    assert result.returncode == 0, result.stderr
    (line,) = [json.loads(text) for text in result.stdout.splitlines()]
    found, pale = line["explain"]
    assert (found["u"], found["v"]) == (200.0, 300.0) and found["found"] is not None
    assert found["summary"].startswith("found at (200, 300)")
    assert pale["found"] is None and pale["candidate"] is None
    assert any(reason.startswith("saturation") for reason in pale["colour"]["failed"])
    assert "saturation" in pale["summary"]


def test_detect_on_real_photos_finds_balls():
    photo = development_photos() / "real_tennis_dev/1747468182.jpg"
    if not photo.exists():
        pytest.skip(f"{photo} not present")
    result = balltrack("detect", str(photo))
    (line,) = [json.loads(text) for text in result.stdout.splitlines()]
    # Labelled box: x 191, y 215, w 72, h 73 -> centre (227, 251.5).
    assert any(abs(ball["u"] - 227) < 18 and abs(ball["v"] - 251.5) < 18 for ball in line["balls"])


def test_detect_stops_on_sigterm_after_a_whole_line(tmp_path, log_dir):
    photo = tmp_path / "b.png"
    cv2.imwrite(str(photo), draw_ball(floor_image(), 200.0, 300.0, 25.0))
    count = 5000  # (several seconds of work at the least: SIGTERM comes long before the end)
    detect = Process([sys.executable, "-m", "balltrack", "detect", *[str(photo)] * count],
                     log_dir / "detect.log")
    detect.wait_for_output('"balls"', timeout=120)
    assert detect.stop() == 0
    lines = detect.output().splitlines()
    assert 1 <= len(lines) < count
    assert all(len(json.loads(line)["balls"]) == 1 for line in lines)


def test_fit_colour_stops_on_sigterm_with_one_line_and_no_fit(tmp_path, log_dir):
    photo = tmp_path / "b.png"
    cv2.imwrite(str(photo), cv2.resize(draw_ball(floor_image(), 200.0, 300.0, 25.0), (160, 120)))
    count = 20000  # (many seconds of work: SIGTERM comes long before the end)
    fit = Process([sys.executable, "-m", "balltrack", "fit-colour", *[str(photo)] * count,
                   "--box", "40,65,20,20"], log_dir / "fit-colour.log")
    fit.wait_for_signal_handler(signal.SIGTERM, timeout=120)
    assert fit.stop() == 1
    output = fit.output()
    assert re.fullmatch(r"balltrack fit-colour: stopped by a signal after \d+ of 20000 images; nothing fitted\n",
                        output), output


@pytest.mark.parametrize("arguments, reason", [
    (["detect", "x.png", "--set", "min_radius=-1"], "min_radius"),
    (["detect", "x.png", "--set", "bogus=1"], "bogus: unknown parameter"),
    (["detect", "x.png", "--explain", "412"], "expected U,V"),
    (["detect", "x.png", "--explain", "inf,3"], "finite"),
    (["fit-colour", "x.png"], "--box"),
    (["fit-colour", "x.png", "--box", "1,2,3"], "expected X,Y,W,H"),
    (["fit-colour", "x.png", "--box", "1,2,0,3"], "positive"),
    (["fit-colour", "x.png", "--box", "1,2,3,3"], "x.png: cannot read image"),
    (["fit-colour", "--labels", "missing.json"], "cannot read"),
    (["fit-colour", "--labels", "README.md"], "expected {"),
    (["status", "--namespace", "a*b"], "namespace"),
    (["hz"], "required"),
    # (an empty key: a zenoh traceback, status 1)
    *[([command, ""], "balltrack " + command.split()[0] + ": '': not a key expression")
      for command in ("echo", "hz", "bw", "delay")],
    (["topic", "info", ""], "balltrack topic: '': not a key expression"),
    (["echo", "detected_ball", "--timeout", "nan"], "--timeout: must be a finite number"),
    (["status", "--timeout", "-1"], "--timeout: must be at least 0"),
    # (nan, 0 or a negative window: reports in a tight loop; a negative count or nan duration: never ending)
    (["hz", "detected_ball", "--window", "0"], "--window: must be at least 0.01"),
    # (a wait past Python's ~9.2e9 s is an OverflowError, traceback, and then a hang; a rate
    # whose period is as long, the same)
    (["status", "--timeout", "1e10"], "--timeout: must be at most 10000000, got 1e10"),
    (["record", "-o", "x.mcap", "--duration", "1e300"], "--duration: must be at most 10000000"),
    (["pub", "cmd_vel", "{}", "--rate", "1e-300"], "--rate: must be 0 (once) or at least 0.001, got 1e-300"),
    (["play", "x.mcap", "--rate", "1e-300"], "--rate: must be 0 (as fast as possible) or at least 0.001"),
    (["bw", "detected_ball", "--window", "nan"], "--window: must be a finite number"),
    (["delay", "detected_ball", "--count", "-1"], "--count: must be at least 0"),
    (["echo", "detected_ball", "--count", "-2"], "--count: must be at least 0"),
    (["topic", "list", "--window", "-1"], "--window: must be at least 0.01"),
    (["record", "-o", "x.mcap", "--duration", "nan"], "--duration: must be a finite number"),
    (["record", "-o", "x.mcap", "--progress", "-1"], "--progress: must be at least 0"),
    # (an output that cannot be written: said before any router is sought, not after)
    (["record", "-o", "no-such-folder/x.mcap"], "cannot write no-such-folder/x.mcap: no-such-folder is no folder"),
    (["record", "-o", "."], "cannot write .: Is a directory"),
    # (a key Zenoh refuses: said before a router is sought, and no empty recording left behind)
    (["record", "-o", "x.mcap", "bad**key//"], "'bad**key//': not a key expression (Invalid Key Expr"),
    (["echo", "bad**key//"], "balltrack echo: 'bad**key//': not a key expression (Invalid Key Expr"),
    (["hz", "camera//image_raw"], "balltrack hz: 'camera//image_raw': not a key expression"),
    (["play", "x.mcap", "--rate", "-1"], "--rate: must be at least 0"),
    (["play", "x.mcap", "--start", "inf"], "--start: must be a finite number"),
    (["pub", "detected_ball", "{}", "--rate", "inf"], "--rate: must be a finite number"),
    (["secure", "init", "profile", "--hosts", "a", "--days", "0"], "--days: must be at least 1"),
    (["secure", "init", "profile", "--hosts", "a", "--days", "99999999"], "--days: must be at most 36500"),
    (["calibrate", "x.png", "--square", "0"], "--square: must be greater than 0"),
    # (these were OpenCV's tracebacks: an overload it could not resolve, a failed assertion)
    (["calibrate", "x.png", "--square", "0.02", "--board", "3000000000x6"], "board: at most 100 inner corners a side"),
    (["calibrate", "x.png", "--square", "1e308"], "--square: must be at most 10"),
    (["calibrate", "x.png", "--square", "0.02", "-o", "no-such-folder/camera.yaml"],
     "no-such-folder/camera.yaml: cannot write (no-such-folder is no folder)"),
    # (what Zenoh refuses: one line naming the option, before any router is sought)
    (["echo", "detected_ball", "--connect", "tcp-127.0.0.1"], "--connect tcp-127.0.0.1: Endpoints must be of the form"),
    (["record", "-o", "x.mcap", "--zenoh-config", "missing.json5"], "missing.json5: No such file or directory"),
    (["hz", "detected_ball", "--zenoh-config", "README.md"], "README.md: Unsupported file type"),
    (["router", "--listen", "7447"], "--listen 7447: Endpoints must be of the form"),
    # (Zenoh takes it, and fails only when it listens: status 1, as a port in use)
    (["router", "--listen", "tcp/127.0.0.1:99999"], "--listen tcp/127.0.0.1:99999: port 99999 is past 65535"),
    (["run", "locator", "--connect", "localhost:7447"], "locator: --connect localhost:7447: Endpoints must be"),
    (["run", "detector+locator", "--zenoh-config", "missing.json5"], "detector+locator: missing.json5: No such file"),
    (["deploy", "start", "--router", "--listen", "foo"], "deploy start: --listen foo: Endpoints must be"),
    (["deploy", "start", "--services", "locator", "--zenoh-config", "missing.json5"], "deploy start: missing.json5: No such"),
    (["deploy", "start", "--wait", "-1"], "--wait: must be at least 0"),
    (["deploy", "stop", "--timeout", "nan"], "--timeout: must be a finite number"),
    (["sim", "explode"], "invalid choice"),
    (["status", "--json"], "balltrack status: --json: only with --run-dir"),
    (["status", "--no-network"], "balltrack status: --no-network: only with --run-dir"),
    # (refused before any router is asked: nothing listens at the default endpoint here)
    (["sim", "set_light", "diffuse=bright"], "balltrack sim: diffuse: expected a number, got 'bright'"),
    (["sim", "place_robot", "x=1"], "balltrack sim: place_robot: 'x' and 'y' are required"),
    (["deploy", "start", "--services", ""], "deploy start: --services: '' names no service"),
    (["run", "detector+bogus"], "expected SERVICE or SERVICE+SERVICE"),
    (["run", "detector+detector"], "each once"),
    (["run", "detector+locator", "--secure", "secure"], "--secure: a secure setup gives each service"),
    # (a profile that is not there: said at once, as a bad --zenoh-config is; status 1 before)
    (["run", "locator", "--secure", "no-profile"], "locator: --secure: no no-profile/locator/client.json5"),
    (["echo", "detected_ball", "--secure", "no-profile"], "--secure: no no-profile/viewer/client.json5"),
    (["hz", "detected_ball", "--secure", "no-profile", "--role", "operator"], "--secure: no no-profile/operator/client.json5"),
    (["run", "detector+locator", "--set", "v_min=3"], "expected SERVICE.KEY=VALUE"),
    (["run", "detector+locator", "--set", "follower.keep_target=false"], "follower is not among this process's detector, locator"),
    (["run", "detector+locator", "--set", "locator.bogus=1"], "detector+locator: locator: bogus: unknown parameter"),
    (["run", "detector+locator", "--config", "x.toml"], "expected SERVICE=FILE"),
    (["run", "detector+locator", "--config", "locator=missing.toml"], "missing.toml: no such config file"),
    (["run", "detector", "--config", "."], "detector: .: cannot read the config file (Is a directory)"),
    (["run", "detector+locator", "--namespaces", "robot1,robot1"],
     "detector+locator: --namespaces: 'robot1' is listed twice"),
    (["run", "locator", "--namespaces", "robot1,,robot2"], "locator: --namespaces: 'robot1,,robot2' has an empty name"),
    (["run", "follower", "--namespaces", "robot1,robot*"], "follower: --namespaces: namespace: 'robot*' may not contain"),
    (["run", "locator", "--namespace", "robot1", "--namespaces", "robot1,robot2"], "--namespaces: not with --namespace"),
    (["run", "locator+simulator", "--namespaces", "robot1,robot2"], "--namespaces: simulator serves one robot per process"),
    (["run", "simulator", "--namespaces", "robot1,robot2"], "unrecognized arguments: --namespaces"),
    (["deploy", "start", "--services", "detector+locator,locator"], "a service may run once"),
    (["deploy", "start", "--secure", "secure", "--services", "detector+locator"], "each runs in a process of its own"),
])
def test_bad_arguments_give_one_line_and_status_2(arguments, reason):
    result = balltrack(*arguments)
    assert result.returncode == 2
    assert len(result.stderr.strip().splitlines()) == 1 and reason in result.stderr, result.stderr


def test_a_scenario_that_is_not_there_is_refused_before_a_router_answers():
    # (nothing listens on that port: it used to wait 30 s for a router, then exit 1)
    result = balltrack("run", "simulator", "--set", "scenario=nosuch", "--connect", f"tcp/127.0.0.1:{free_port()}")
    assert result.returncode == 2
    assert len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert "nosuch.toml: no such scenario file (shipped scenarios: chase," in result.stderr


def test_fit_colour_writes_a_parameter_file_the_detector_reads(tmp_path):
    # Orange balls, which the default (tennis) range does not admit; the fitted file finds them.
    image = draw_ball(draw_ball(floor_image(), 200.0, 300.0, 25.0, colour=(30, 110, 235)),
                      450.0, 200.0, 20.0, colour=(30, 110, 235))
    photo = tmp_path / "orange.png"
    cv2.imwrite(str(photo), image)
    before = balltrack("detect", str(photo))
    assert json.loads(before.stdout)["balls"] == []
    fitted = balltrack("fit-colour", str(photo), "--box", "175,275,50,50", "--box", "430,180,40,40")
    assert fitted.returncode == 0, fitted.stderr
    settings = tomllib.loads(fitted.stdout)["detector"]
    assert settings["h_min"] <= 12 <= settings["h_max"]
    (tmp_path / "orange.toml").write_text(fitted.stdout)
    after = balltrack("detect", str(photo), "--config", str(tmp_path / "orange.toml"))
    balls = sorted((round(ball["u"]), round(ball["v"])) for ball in json.loads(after.stdout)["balls"])
    assert balls == [(200, 300), (450, 200)]


def test_fit_colour_refuses_a_box_whose_centre_is_outside_the_image(tmp_path):
    photo = tmp_path / "floor.png"
    cv2.imwrite(str(photo), floor_image())
    height, width = floor_image().shape[:2]
    result = balltrack("fit-colour", str(photo), "--box", f"{width},10,20,20")
    assert result.returncode == 2
    assert result.stderr.strip() == (f"balltrack fit-colour: {photo}: the box {width},10,20,20 has its centre "
                                     f"outside the {width}x{height} image")


@pytest.mark.parametrize("content", [b"", b"not an image\n"])
def test_fit_colour_rejects_a_file_that_is_no_image(tmp_path, content):
    (tmp_path / "bad.png").write_bytes(content)
    result = balltrack("fit-colour", str(tmp_path / "bad.png"), "--box", "1,2,3,3")
    assert result.returncode == 2
    assert result.stderr.strip() == f"balltrack fit-colour: {tmp_path / 'bad.png'}: cannot read image (not an image OpenCV decodes)"


def test_unreadable_image_is_reported_not_fatal(tmp_path):
    good = tmp_path / "good.png"
    cv2.imwrite(str(good), floor_image(64, 48))
    (tmp_path / "text.png").write_text("not an image\n")
    tiny = tmp_path / "tiny.png"  # (a traceback, and the files after it left undone)
    cv2.imwrite(str(tiny), floor_image(7, 7))
    result = balltrack("detect", str(tmp_path / "missing.png"), str(tmp_path / "text.png"), str(tmp_path),
                       str(tiny), str(good))
    assert result.returncode == 1
    lines = [json.loads(line) for line in result.stdout.splitlines()]
    assert [line.get("error") for line in lines] == [
        "cannot read image (No such file or directory)", "cannot read image (not an image OpenCV decodes)",
        "cannot read image (Is a directory)", "cannot detect in it (image too small: 7x7)", None]
    assert lines[4]["balls"] == []
    # (the reason is in the line: no warning of OpenCV's own beside it)
    assert result.stderr == ""


def test_router_on_port_zero_prints_the_port_it_listens_on(log_dir):
    router = Process([sys.executable, "-m", "balltrack", "router", "--listen", "tcp/127.0.0.1:0"],
                     log_dir / "router.log")
    try:
        router.wait_for_output("reached at", 20)
        match = re.search(r"router (\w+) listening on tcp/127\.0\.0\.1:0 \(reached at tcp/127\.0\.0\.1:(\d+)\)",
                          router.output())
        assert match, router.output()
        port = int(match.group(2))
        assert port > 0
        session = client(f"tcp/127.0.0.1:{port}")
        try:
            assert [str(zid) for zid in session.info.routers_zid()] == [match.group(1)]
        finally:
            session.close()
    finally:
        assert router.stop() == 0


def test_no_router_is_a_clear_error(tmp_path):
    port = free_port()
    result = balltrack("status", "--connect", f"tcp/127.0.0.1:{port}", "--timeout", "1")
    assert result.returncode == 1 and f"cannot reach a Zenoh router at tcp/127.0.0.1:{port}:" in result.stderr
    # (the endpoint a --zenoh-config file dials is the one named, not the default's)
    config = tmp_path / "client.json5"
    config.write_text(f'{{mode: "client", connect: {{endpoints: ["tcp/127.0.0.1:{port}"]}}}}')
    result = balltrack("status", "--zenoh-config", str(config), "--timeout", "1")
    assert result.returncode == 1 and f"cannot reach a Zenoh router at tcp/127.0.0.1:{port}:" in result.stderr


@pytest.mark.parametrize("command", [["echo", "detected_ball"], ["topic", "list"],
                                     # (these waited it out: SIGTERM killed them, status 143)
                                     ["status"], ["config", "locator"], ["sim", "reset"]])
def test_a_command_still_waiting_for_its_router_stops_at_once_on_sigterm(log_dir, command):
    # (nothing listens on that port: the command waits for its router up to --timeout, 60 s)
    process = Process([sys.executable, "-m", "balltrack", *command, "--connect", f"tcp/127.0.0.1:{free_port()}",
                       "--timeout", "60"], log_dir / "command.log")
    process.wait_for_signal_handler(signal.SIGTERM, 30)
    process.popen.terminate()
    # (it used to wait the 60 s out, then say it could not reach a router, status 1)
    assert process.popen.wait(timeout=15) == 0, process.output()
    assert "cannot reach" not in process.output()


def test_status_config_echo_hz(router, session, log_dir):
    locator = start_service("locator", router.endpoint, log_dir)
    Liveliness(session).wait("locator")
    stats = Collector(session, "locator/stats", "Stats")
    stats.wait_count(1, 10)
    status = balltrack("status", "--connect", router.endpoint)
    assert status.returncode == 0, status.stderr
    rows = {line.split()[0]: line.split() for line in status.stdout.splitlines()[1:]}
    assert rows["locator"][1] == "yes" and rows["detector"][1] == "no"

    changed = balltrack("config", "locator", "ball_radius=0.05", "--connect", router.endpoint)
    assert changed.returncode == 0 and json.loads(changed.stdout)["ball_radius"] == 0.05
    refused = balltrack("config", "locator", "ball_radius=-2", "--connect", router.endpoint)
    assert refused.returncode == 2 and "ball_radius" in refused.stderr

    echo = Process([sys.executable, "-m", "balltrack", "echo", "camera/camera_info", "--count",
                    "2", "--connect", router.endpoint], log_dir / "echo.log")
    hz = Process([sys.executable, "-m", "balltrack", "hz", "camera/camera_info", "--window", "1",
                  "--count", "2", "--connect", router.endpoint], log_dir / "hz.log")
    # Publish until both tools have what they need (they subscribe asynchronously).
    deadline = time.monotonic() + 30
    while echo.popen.poll() is None or hz.popen.poll() is None:
        assert time.monotonic() < deadline, echo.output() + hz.output()
        session.put("camera/camera_info", encode("CameraInfo", CAMERA_INFO))
        try:
            echo.popen.wait(0.05)
        except subprocess.TimeoutExpired:
            pass
    assert echo.popen.returncode == 0 and hz.popen.returncode == 0
    printed = [json.loads(line) for line in echo.output().splitlines() if line.startswith("{")]
    assert len(printed) == 2 and printed[0]["message"]["fx"] == pytest.approx(CAMERA_INFO["fx"])
    assert "Hz" in hz.output()
    assert locator.stop() == 0


def test_echo_shows_an_images_pixels_as_their_size(router, session, log_dir):
    # (pixels of at least messages.SHARED_BIN_MIN bytes come out of decode as a memoryview of
    # the payload, not as bytes: a 640x480 frame, not a thumbnail)
    image = np.zeros((480, 640, 3), np.uint8)
    echo = Process([sys.executable, "-m", "balltrack", "echo", "camera/image_raw", "--count", "1",
                    "--connect", router.endpoint], log_dir / "echo.log")
    _publish_until_done(session, echo.popen, key="camera/image_raw",
                        payload=encode("Image", bgr_to_message(image, 10, 1)))
    assert echo.popen.returncode == 0, echo.output()
    (printed,) = [json.loads(line) for line in echo.output().splitlines() if line.startswith("{")]
    assert printed["message"]["data"] == f"<{image.nbytes} bytes>"
    assert printed["message"]["width"] == 640 and "Traceback" not in echo.output()


def _publish_until_done(session, process, deadline_seconds=30.0, key="camera/camera_info", payload=None):
    """Put ``payload`` (default: camera_info) on ``key`` until ``process`` exits (its
    subscription is declared asynchronously)."""
    payload = payload if payload is not None else encode("CameraInfo", CAMERA_INFO)
    deadline = time.monotonic() + deadline_seconds
    while process.poll() is None:
        assert time.monotonic() < deadline, "the command did not finish"
        session.put(key, payload)
        try:
            process.wait(0.05)
        except subprocess.TimeoutExpired:
            pass


@pytest.mark.parametrize("command, lines", [
    (["echo", "camera/camera_info"], 3),
    (["hz", "camera/camera_info", "--window", "0.3"], 1),
])
def test_commands_in_a_pipe_exit_quietly_when_the_reader_goes(router, session, log_dir, command, lines):
    error_log = log_dir / "command.err"
    script = (f"{sys.executable} -m balltrack {' '.join(command)} --connect {router.endpoint} "
              f"2>{error_log} | head -{lines}; echo \"status ${{PIPESTATUS[0]}}\"")
    pipeline = subprocess.Popen(["bash", "-c", script], stdout=subprocess.PIPE, text=True,
                                env=process_environment(), cwd=log_dir)
    _publish_until_done(session, pipeline)
    printed = pipeline.stdout.read().splitlines()
    assert printed[-1] == "status 0", printed
    assert len(printed[:-1]) == lines
    assert error_log.read_text() == "", error_log.read_text()


@pytest.mark.parametrize("command", [["echo", "camera/camera_info"], ["hz", "camera/camera_info"]])
def test_long_running_commands_stop_on_sigterm(router, session, log_dir, command):
    process = Process([sys.executable, "-m", "balltrack", *command, "--connect", router.endpoint],
                      log_dir / "command.log")
    # Wait until it is subscribed and printing, so the signal arrives in the running loop.
    deadline = time.monotonic() + 30
    while "camera_info" not in process.output():
        assert time.monotonic() < deadline, process.output()
        session.put("camera/camera_info", encode("CameraInfo", CAMERA_INFO))
        time.sleep(0.05)  # the publishing rate, not a synchronisation
    process.popen.terminate()
    assert process.popen.wait(timeout=10) == 0, process.output()
    assert "Traceback" not in process.output()


@pytest.mark.parametrize("command", [["run", "detector"], ["router", "--listen", "tcp/127.0.0.1:FREE"]])
def test_a_stop_while_a_service_is_still_starting_ends_it_with_status_0(log_dir, command):
    # (a SIGTERM before its imports were done killed it, status 143: a supervisor's "killed by
    # SIGTERM" for a process stopped just after it started)
    port = str(free_port())
    arguments = [item.replace("FREE", port) for item in command]
    if command[0] == "run":
        arguments += ["--connect", f"tcp/127.0.0.1:{port}"]
    process = Process([sys.executable, "-m", "balltrack", *arguments], log_dir / "starting.log")
    process.wait_for_signal_handler(signal.SIGTERM, 30)  # (the early one: the imports go on)
    process.popen.terminate()
    assert process.popen.wait(timeout=30) == 0, process.output()
    assert "Traceback" not in process.output()
