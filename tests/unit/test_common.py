"""The shared layer: messages, keys, config, images."""

import dataclasses
import math
import re
import time
import types

import cv2
import msgpack
import numpy as np
import pytest

from balltrack.common.clock import SimClock
from balltrack.common.config import ConfigError, load_config, parse_overrides, replace_config
from balltrack.common.context import ServiceContext
from balltrack.common.images import UnreadableImage, bgr_to_message, image_to_bgr, jpeg_size, read_image
from balltrack.common.keys import Keys
from balltrack.common.messages import MessageError, decode, encode, header
from balltrack.common.status import other_figures
from tests.harness import wait_until


def ball2d(**changes):
    message = {"header": header(5, 1), "x": 0.1, "y": -0.2, "z": 0.05, "u": 352.0, "v": 192.0,
               "radius_px": 16.0, "image_width": 640, "image_height": 480, "score": 0.9}
    message.update(changes)
    return message


def test_round_trip_keeps_fields_and_extras():
    message = ball2d(extra_field="kept")
    assert decode("Ball2D", encode("Ball2D", message)) == message


@pytest.mark.parametrize("payload, reason", [
    (b"", "empty payload"),
    (b"\xc1\xc1\xc1", "not msgpack"),
    (msgpack.packb([1, 2, 3]), "expected a map"),
    (msgpack.packb({"x": 1}), "header: missing"),
])
def test_garbage_is_a_message_error(payload, reason):
    with pytest.raises(MessageError, match=reason):
        decode("Ball2D", payload)


@pytest.mark.parametrize("request_map, named", [
    ({"sett": {"param2": 18}}, "unknown field 'sett' "),
    ({"set": {"param2": 18}, "describ": True}, "unknown field 'describ' "),
    # (within the unpacker's 4,096 keys a map may have)
    ({f"typo{index}": index for index in range(4000)}, "unknown fields 'typo0', 'typo1', 'typo2' and 3997 more"),
])
def test_a_config_request_with_an_unknown_field_is_refused_naming_it(request_map, named):
    # An unknown field is a typo (or a request this service cannot do): read as a plain read,
    # it would answer ok while changing nothing.
    with pytest.raises(MessageError, match=re.escape(named)) as refused:
        decode("ConfigRequest", msgpack.packb(request_map))
    assert len(str(refused.value)) < 200
    assert decode("ConfigRequest", msgpack.packb({"set": {"param2": 18}, "describe": True})) == {
        "set": {"param2": 18}, "describe": True}


@pytest.mark.parametrize("field, value, reason", [
    ("x", float("nan"), "not finite"),
    ("x", float("inf"), "not finite"),
    ("x", 3.0, "above"),
    ("radius_px", "big", "expected a number"),
    ("image_width", 1.5, "expected an integer"),
    ("score", True, "expected a number"),
])
def test_bad_values_are_rejected(field, value, reason):
    payload = msgpack.packb(ball2d(**{field: value}), use_bin_type=True)
    with pytest.raises(MessageError, match=reason):
        decode("Ball2D", payload)


def image_message(**changes):
    message = {"header": header(1, 1), "width": 4, "height": 2, "encoding": "bgr8",
               "data": bytes(24)}
    message.update(changes)
    return msgpack.packb(message, use_bin_type=True)


@pytest.mark.parametrize("changes, reason", [
    ({"data": bytes(23)}, "needs 24"),
    ({"width": 100000, "height": 100000}, "above"),
    ({"encoding": "yuv422"}, "not one of"),
    ({"encoding": "jpeg", "data": b"not a jpeg"}, "not a JPEG"),
])
def test_bad_images_are_rejected(changes, reason):
    with pytest.raises(MessageError, match=reason):
        decode("Image", image_message(**changes))


def test_image_encodings_round_trip():
    image = np.zeros((6, 8, 3), np.uint8)
    image[:, :, 2] = 200  # red in BGR
    for encoding in ("bgr8", "rgb8", "jpeg"):
        message = decode("Image", encode("Image", bgr_to_message(image, 1, 2, encoding=encoding)))
        decoded = image_to_bgr(message)
        assert decoded.shape == image.shape
        assert abs(int(decoded[3, 4, 2]) - 200) <= 3, encoding
    mono = image_to_bgr(decode("Image", encode("Image", bgr_to_message(image, 1, 2, encoding="mono8"))))
    assert mono.shape == (6, 8, 3)


def test_corrupt_and_lying_jpegs_are_rejected_before_decoding():
    ok, buffer = cv2.imencode(".jpg", np.zeros((20, 30, 3), np.uint8))
    data = buffer.tobytes()
    assert jpeg_size(data) == (30, 20)
    lying = msgpack.packb({"header": header(1, 1), "width": 3000, "height": 2000,
                           "encoding": "jpeg", "data": data}, use_bin_type=True)
    with pytest.raises(MessageError, match="JPEG is 30x20"):
        image_to_bgr(decode("Image", lying))
    truncated = msgpack.packb({"header": header(1, 1), "width": 30, "height": 20,
                               "encoding": "jpeg", "data": data[:40]}, use_bin_type=True)
    with pytest.raises(MessageError, match="corrupt JPEG"):
        image_to_bgr(decode("Image", truncated))


def test_read_image_gives_the_file_as_imread_does_or_says_why_not(tmp_path):
    image = np.random.default_rng(3).integers(0, 256, (30, 40, 3), np.uint8)
    cv2.imwrite(str(tmp_path / "frame.png"), image)
    assert np.array_equal(read_image(tmp_path / "frame.png"), image)
    assert np.array_equal(read_image(str(tmp_path / "frame.png")), cv2.imread(str(tmp_path / "frame.png")))
    (tmp_path / "empty.png").write_bytes(b"")
    (tmp_path / "text.png").write_text("not an image")
    for path, reason in ((tmp_path / "missing.png", "No such file or directory"), (tmp_path, "Is a directory"),
                         (tmp_path / "empty.png", "not an image OpenCV decodes"),
                         (tmp_path / "text.png", "not an image OpenCV decodes")):
        with pytest.raises(UnreadableImage) as refused:
            read_image(path)
        assert str(refused.value) == reason


def test_keys_namespace():
    assert Keys("")("cmd_vel") == "cmd_vel"
    assert Keys("/robot1/")("cmd_vel") == "robot1/cmd_vel"
    assert Keys("robot1").strip("robot1/detected_ball") == "detected_ball"
    assert Keys("robot1").message_of("robot1/detected_ball_3d") == "Ball3D"
    assert Keys("").message_of("locator/stats") == "Stats"
    with pytest.raises(ValueError, match="namespace"):
        Keys("robot*")


@dataclasses.dataclass
class ExampleConfig:
    gain: float = 0.5
    count: int = 3
    enabled: bool = True
    name: str = "ball"
    levels: list[float] = dataclasses.field(default_factory=lambda: [0.1, 0.2])

    def __post_init__(self):
        if not 0 <= self.gain <= 1:
            raise ConfigError("gain: must be within [0, 1]")


def test_config_file_then_overrides(tmp_path):
    path = tmp_path / "example.toml"
    path.write_text('gain = 0.25\nname = "from-file"\n[locator]\ncount = 9\nname = "table"\n')
    config = load_config(ExampleConfig, path, ["count=7", "enabled=false", "levels=[0.5, 1]"])
    assert (config.gain, config.count, config.enabled, config.name, config.levels) == \
        (0.25, 7, False, "from-file", [0.5, 1.0])
    # the service's table on top of the top-level keys (they used to be dropped beside it)
    config = load_config(ExampleConfig, path, section="locator")
    assert (config.gain, config.count, config.name) == (0.25, 9, "table")
    # another service's table is that service's: a shared file
    assert load_config(ExampleConfig, path, section="detector").count == 3


@pytest.mark.parametrize("text, section, reason", [
    ('[detectr]\ncount = 9\n', "detector", r"\[detectr\] is not a service's table \(tables: detector, locator"),
    ('gain = 0.2\n[detectr]\ncount = 9\n', None, r"\[detectr\] is not a service's table"),
    ('[locator]\ncount = 9\n', "detector", r"no \[detector\] table and no top-level keys for detector \(its tables: \[locator\]\)"),
])
def test_a_config_file_whose_tables_are_not_the_services_is_refused(tmp_path, text, section, reason):
    path = tmp_path / "example.toml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=reason):
        load_config(ExampleConfig, path, section=section)


@pytest.mark.parametrize("overrides, reason", [
    (["gain=2"], "gain: must be within"),
    (["gain=abc"], "gain:"),
    (["gain=nan"], "gain: must be finite"),
    (["count=1.5"], "count:"),
    (["nonsense=1"], "nonsense: unknown parameter"),
    (["gain"], "expected KEY=VALUE"),
])
def test_config_errors_name_the_key(overrides, reason):
    with pytest.raises(ConfigError, match=reason):
        load_config(ExampleConfig, None, overrides)


def test_config_file_errors(tmp_path):
    with pytest.raises(ConfigError, match="no such config file"):
        load_config(ExampleConfig, tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("gain = = 1")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_config(ExampleConfig, bad)
    # (a folder, or bytes that are not text: a one-line ConfigError, not an OSError or
    # UnicodeDecodeError from the reading)
    with pytest.raises(ConfigError, match=r"cannot read the config file \(Is a directory\)"):
        load_config(ExampleConfig, tmp_path)
    (tmp_path / "binary.toml").write_bytes(b"gain = \xff\xfe")
    with pytest.raises(ConfigError, match=r"not valid TOML \(not UTF-8 text\)"):
        load_config(ExampleConfig, tmp_path / "binary.toml")


def test_replace_config_validates_and_keeps_original():
    config = ExampleConfig()
    assert replace_config(config, {"gain": 0.75}).gain == 0.75
    with pytest.raises(ConfigError):
        replace_config(config, {"gain": 5})
    assert config.gain == 0.5
    assert parse_overrides(["a=1", " b = x=y "]) == {"a": "1", "b": "x=y"}


def test_sim_clock_starts_at_zero_and_follows_updates():
    clock = SimClock()
    assert clock.now() == 0 and not clock.has_time()
    clock.update(1_500_000_000)
    assert math.isclose(clock.now(), 1.5) and clock.has_time()
    assert clock.wait_for_update(0, 0.01) == (1, 1_500_000_000)
    assert clock.wait_for_update(1, 0.01) == (1, 1_500_000_000)  # timed out: nothing new


def test_a_handlers_time_leaves_out_the_handlers_its_puts_call(monkeypatch):
    """In one process (``run_services``) the detector's put of a detection runs the locator's
    handler inside the detector's: each service's p50_ms must be its own time."""
    import threading

    from balltrack.common import context

    now = [0.0]
    monkeypatch.setattr(context.time, "perf_counter", lambda: now[0])
    stop = threading.Event()
    detector = context.ServiceContext("detector", None, "", object(), stop)
    locator = context.ServiceContext("locator", None, "", object(), stop)
    ball = encode("Ball2D", {"header": header(1, 1), "x": 0.0, "y": 0.0, "z": 0.1, "u": 320.0, "v": 240.0,
                                "radius_px": 32.0, "image_width": 640, "image_height": 480, "score": 0.9})

    def locate(_message):
        now[0] += 5.0

    def detect(_message):
        now[0] += 1.0
        locator.process("detected_ball", "Ball2D", ball, locate, True)  # (as its put would)
        now[0] += 2.0

    detector.process("camera/image_raw", "Ball2D", ball, detect, True)
    assert detector.stats.snapshot(0)["p50_ms"] == 3000.0 and locator.stats.snapshot(0)["p50_ms"] == 5000.0
    # A handler that fails is rejected and its time not recorded; the next good one counts alone.
    detector.process("camera/image_raw", "Ball2D", b"\xc1", detect, True)
    detector.process("camera/image_raw", "Ball2D", ball, lambda _message: now.__setitem__(0, now[0] + 4.0), True)
    assert detector.stats.snapshot(0)["rejected"] == 1
    assert sorted(detector.stats._durations) == [3000.0, 4000.0]


def test_stats_name_the_clock_of_their_stamp():
    from balltrack.common.context import Stats

    snapshot = decode("Stats", encode("Stats", Stats("follower").snapshot(1_796_637_533_000_000_000)))
    assert snapshot["stamp_clock"] == "wall"
    # A status line shows a service's own figures only, not the clock every one names.
    assert other_figures(snapshot) == ""


def test_other_figures_are_a_service_s_own_in_its_order():
    stats = {"service": "simulator", "stamp": 1, "received": 2, "published": 3, "rejected": 0,
             "dropped": 0, "p50_ms": 1.0, "p99_ms": 2.0, "real_time_factor": 0.998765, "frames": 40}
    assert other_figures(stats) == "real_time_factor=0.9988 frames=40"
    assert other_figures({**stats, "real_time_factor": 1.0, "frames": 0}) == "real_time_factor=1 frames=0"
    assert other_figures({"service": "locator", "received": 1}) == ""


def test_a_wall_timer_takes_a_rate_changed_live_without_waiting_out_the_old_period():
    # (it waited the old period out: a follower set to rate_hz=0.001 and back to 10 stayed
    # silent for 1000 s)
    context = ServiceContext("timer", None, "", types.SimpleNamespace())
    period, ticks = [1000.0], []
    context.every(lambda: period[0], lambda: ticks.append(time.monotonic()))
    try:
        wait_until(lambda: ticks, 5, "the first tick")
        period[0] = 0.01
        wait_until(lambda: len(ticks) >= 5, 5, "ticks at the new rate")
    finally:
        context.stop.set()
        context.close()
    assert all(later > earlier for earlier, later in zip(ticks, ticks[1:]))
