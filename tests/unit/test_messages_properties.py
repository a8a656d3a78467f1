"""Property tests of every decoder: whatever arrives, a message comes out or MessageError.

For each schema in ``common.messages.SCHEMAS`` (and for Image payloads decoded on to pixels by
``common.images``), three kinds of input: any bytes; any msgpack-packable structure (None,
booleans, integers up to 64 bits, floats with NaN and infinities, strings, bytes, extension
types, lists and maps nested a few levels); and mutations of a valid message (truncated, bytes
flipped, a field replaced, removed or added). Whatever comes out must be a valid message (it
encodes again under the same schema, with only the header's contract fields); anything
else must be ``MessageError``, never another exception.
"""

import math

import msgpack
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from balltrack.common.images import bgr_to_message, image_to_bgr
from balltrack.common.messages import (
    HEADER_FIELDS, MAX_DEPTH, MAX_FRAME_ID, SCHEMAS, SHARED_BIN_MIN, UNPACK_OPTIONS, MessageError, decode,
    encode, header, shorten, unpack_sharing_bins,
)

PROPERTY_SETTINGS = settings(max_examples=200, deadline=None,
                             suppress_health_check=[HealthCheck.too_slow])


def _image(encoding: str) -> dict:
    pixels = np.zeros((6, 8, 3), np.uint8)
    pixels[2:4, 3:5] = (40, 235, 205)
    return bgr_to_message(pixels, 5, 7, encoding=encoding)


BALL = {"x": 0.1, "y": -0.2, "z": 0.05, "u": 352.0, "v": 192.0, "radius_px": 16.0,
        "image_width": 640, "image_height": 480, "score": 0.9}

# One valid message of every schema: the seeds of the mutations.
VALID = {
    "Image": _image("bgr8"),
    "CameraInfo": {"header": header(1, 2), "width": 640, "height": 480, "fx": 554.0,
                   "fy": 554.0, "cx": 320.0, "cy": 240.0, "hfov": 1.089, "vfov": 0.85},
    "Ball2D": {"header": header(1, 2), **BALL},
    "Ball2DArray": {"header": header(1, 2), "balls": [BALL, {**BALL, "x": -0.5}]},
    "Ball3D": {"header": header(1, 2, "camera_optical"), "x": 0.1, "y": 0.0, "z": 2.0,
               "distance": 2.0},
    "Twist": {"header": header(1, 2, "base_link"), "linear": [0.1, 0.0, 0.0],
              "angular": [0.0, 0.0, -0.3], "time": 5, "mode": "chase"},
    "Clock": {"stamp": 33_000_000},
    "GroundTruth": {"header": header(1, 2), "robot": {"x": 0.0, "y": 0.0, "yaw": 0.1},
                    "balls": [{"id": "tennis", "radius": 0.033, "position": [2.0, 1.0, 0.033],
                               "in_camera": [-1.0, 0.1, 1.7], "visible": True}]},
    "SimCommand": {"op": "place_ball", "id": "tennis", "position": [1.5, 0.2]},
    "SimReply": {"ok": False, "error": "id: no ball 'golf'"},
    "Stats": {"service": "detector", "stamp": 10, "received": 3, "published": 2, "rejected": 1,
              "dropped": 0, "p50_ms": 4.0, "p99_ms": 9.5},
    "ConfigRequest": {"set": {"min_fill_ratio": 0.4}, "describe": True},
    "ConfigReply": {"ok": True, "config": {"min_fill_ratio": 0.4, "use_sim_time": False},
                    "parameters": {"min_fill_ratio": {
                        "type": "float", "default": 0.55, "meaning": "smallest mask fraction",
                        "low": 0.0, "high": 1.0, "low_open": False, "high_open": False, "off": None,
                        "bounds": "[0, 1]", "choices": None}}},
}


def test_every_schema_has_a_seed():
    # A schema added without a seed here would escape the mutation tests below.
    assert set(VALID) == set(SCHEMAS)
    for name, message in VALID.items():
        assert decode(name, encode(name, message))


# Anything msgpack can carry, a few levels deep.
SCALARS = (st.none() | st.booleans()
           | st.integers(min_value=-(1 << 63), max_value=(1 << 64) - 1)
           | st.floats(allow_nan=True, allow_infinity=True)
           | st.text(max_size=40) | st.binary(max_size=40)
           | st.sampled_from([float("nan"), float("inf"), -float("inf"), (1 << 64) - 1,
                              -(1 << 63), "x" * 5000, b"\xff\xd8" + bytes(20)])
           | st.builds(msgpack.ExtType, st.integers(0, 127), st.binary(max_size=16)))
PACKABLE = st.recursive(
    SCALARS,
    lambda children: (st.lists(children, max_size=6)
                      | st.dictionaries(st.text(max_size=12) | st.integers(-5, 5), children,
                                        max_size=6)),
    max_leaves=40)


def pack(value) -> bytes:
    return msgpack.packb(value, use_bin_type=True)


def check_decoder(name: str, payload: bytes) -> None:
    """The property: a valid message, or MessageError; and an Image also decodes to pixels or
    MessageError."""
    try:
        message = decode(name, payload)
    except MessageError as error:
        assert "\n" not in str(error) and len(str(error)) < 1000
        return
    assert isinstance(message, dict)
    # Valid: it encodes again and decodes to the same (compared as bytes: NaN may sit in an
    # extra field, where nothing checks it, and NaN is not equal to itself).
    assert pack(decode(name, encode(name, message))) == pack(message)
    if "header" in VALID.get(name, {}):  # elsewhere "header" is an unknown key, passed through
        assert tuple(message["header"]) == HEADER_FIELDS
        assert len(message["header"]["frame_id"]) <= MAX_FRAME_ID
    if name == "Image":
        try:
            pixels = image_to_bgr(message)
        except MessageError:
            return
        assert pixels.shape == (message["height"], message["width"], 3)


@pytest.mark.parametrize("name", sorted(SCHEMAS))
@PROPERTY_SETTINGS
@given(payload=st.binary(max_size=300))
def test_any_bytes(name, payload):
    check_decoder(name, payload)


@pytest.mark.parametrize("name", sorted(SCHEMAS))
@PROPERTY_SETTINGS
@given(value=PACKABLE)
def test_any_packable_structure(name, value):
    check_decoder(name, pack(value))


@pytest.mark.parametrize("name", sorted(SCHEMAS))
@PROPERTY_SETTINGS
@given(data=st.data())
def test_byte_mutations_of_a_valid_message(name, data):
    payload = bytearray(encode(name, VALID[name]))
    kind = data.draw(st.sampled_from(["truncate", "flip", "insert", "delete"]))
    position = data.draw(st.integers(0, len(payload) - 1))
    if kind == "truncate":
        payload = payload[:position]
    elif kind == "flip":
        for offset in data.draw(st.lists(st.integers(0, len(payload) - 1), min_size=1, max_size=4)):
            payload[offset] = data.draw(st.integers(0, 255))
    elif kind == "insert":
        payload[position:position] = data.draw(st.binary(min_size=1, max_size=8))
    else:
        del payload[position:position + data.draw(st.integers(1, 8))]
    check_decoder(name, bytes(payload))


def _paths(value, prefix=()):
    """Every path (tuple of keys and indexes) into a message, containers included."""
    yield prefix
    if isinstance(value, dict):
        for key, item in value.items():
            yield from _paths(item, prefix + (key,))
    elif isinstance(value, list):
        for index, item in enumerate(value):
            yield from _paths(item, prefix + (index,))


def _replaced(message, path, new_value, delete=False):
    if not path:
        return new_value
    copy = dict(message) if isinstance(message, dict) else list(message)
    head, rest = path[0], path[1:]
    if rest:
        copy[head] = _replaced(copy[head], rest, new_value, delete)
    elif delete:
        del copy[head]
    else:
        copy[head] = new_value
    return copy


@pytest.mark.parametrize("name", sorted(SCHEMAS))
@PROPERTY_SETTINGS
@given(data=st.data())
def test_field_mutations_of_a_valid_message(name, data):
    message = VALID[name]
    path = data.draw(st.sampled_from(list(_paths(message))))
    kind = data.draw(st.sampled_from(["replace", "delete", "add"]))
    if kind == "replace" or not path:
        mutated = _replaced(message, path, data.draw(PACKABLE))
    elif kind == "delete":
        mutated = _replaced(message, path, None, delete=True)
    else:
        mutated = {**message, data.draw(st.text(max_size=12)): data.draw(PACKABLE)}
    check_decoder(name, pack(mutated))


@PROPERTY_SETTINGS
@given(width=st.integers(-3, 20_000), height=st.integers(-3, 20_000),
       encoding=st.sampled_from(["bgr8", "rgb8", "mono8", "jpeg", "png", ""]),
       data=st.binary(max_size=400) | st.sampled_from([_image("jpeg")["data"]]))
def test_image_payloads_decode_to_pixels_or_message_error(width, height, encoding, data):
    check_decoder("Image", pack({"header": header(1, 2), "width": width, "height": height,
                                 "encoding": encoding, "data": data}))


@PROPERTY_SETTINGS
@given(cut=st.integers(0, 400), offset=st.integers(0, 400), byte=st.integers(0, 255))
def test_corrupt_jpeg_images(cut, offset, byte):
    valid = _image("jpeg")
    data = bytearray(valid["data"])
    data[offset % len(data)] = byte
    check_decoder("Image", pack({**valid, "data": bytes(data[:max(4, len(data) - cut)])}))


def test_header_carries_only_its_contract_fields():
    bloated = {**VALID["Ball2D"], "header": {**header(1, 2), "extra": "x" * 1_000_000}}
    assert decode("Ball2D", pack(bloated))["header"] == header(1, 2)
    with pytest.raises(MessageError, match="frame_id: string longer than"):
        decode("Ball2D", pack({**VALID["Ball2D"], "header": header(1, 2, "f" * (MAX_FRAME_ID + 1))}))


def test_deep_nesting_is_refused_not_passed_on():
    # {"op": "reset", "scenario": [[[...]]]} 600 deep: msgpack unpacks it (up to 1,024 levels)
    # but packs only 511, so it could be neither passed on nor quoted safely.
    payload = b"\x82\xa2op\xa5reset\xa8scenario" + b"\x91" * 600 + b"\x90"
    with pytest.raises(MessageError, match="nested deeper"):
        decode("SimCommand", payload)


def test_shorten_bounds_any_value():
    deep = []
    for _ in range(1000):
        deep = [deep]
    for value in ("x" * 1_000_000, deep, {"k" * 1000: b"\x00" * 1_000_000}, 10 ** 4000,
                  "line one\nline two", float("nan")):
        text = shorten(value, 80)
        assert len(text) < 120 and "\n" not in text
    assert shorten("short") == "short"
    assert math.isnan(float(shorten(float("nan"))))


def test_lying_jpeg_is_refused_before_decoding():
    # A 100-byte file whose frame header (and message) claim 8192 x 8192: decoding it would
    # allocate the whole 200 MB frame.
    lie = (b"\xff\xd8\xff\xc0\x00\x11\x08\x20\x00\x20\x00\x03\x01\x22\x00\x02\x11\x01\x03\x11\x01"
           + bytes(80))
    message = decode("Image", pack({"header": header(1, 2), "width": 8192, "height": 8192,
                                    "encoding": "jpeg", "data": lie}))
    with pytest.raises(MessageError, match="cannot hold"):
        image_to_bgr(message)
    assert image_to_bgr(_image("jpeg")).shape == (6, 8, 3)  # a real small JPEG still decodes


def test_a_peers_map_key_in_an_error_stays_on_one_line():
    # (found by test_field_mutations_of_a_valid_message: a parameter named "\n", declared as None)
    payload = pack({**VALID["ConfigReply"], "parameters": {"\n" + "x" * 5000: None}})
    with pytest.raises(MessageError) as raised:
        decode("ConfigReply", payload)
    assert "\n" not in str(raised.value) and len(str(raised.value)) < 1000
    assert str(raised.value).startswith("parameters.\\nxxx")


@pytest.mark.parametrize("container", ["list", "map"])
def test_nesting_is_refused_just_past_the_limit(container):
    def nested(depth):
        """A value whose containers go ``depth`` levels deep."""
        value = 0
        for _ in range(depth):
            value = [value] if container == "list" else {"k": value}
        return value

    def reason(depth):
        # (the scenario field is refused by the schema, but only after the depth check)
        try:
            decode("SimCommand", pack({"op": "reset", "scenario": nested(depth)}))
        except MessageError as error:
            return str(error)
        return "accepted"

    assert "nested deeper" not in reason(MAX_DEPTH)
    assert "nested deeper" in reason(MAX_DEPTH + 1)


def test_a_payload_that_is_no_map_is_refused():
    for scalar in (5, "text", None, 1.5, b"bytes", [1, [2]]):
        with pytest.raises(MessageError, match="expected a map"):
            decode("SimCommand", pack(scalar))


# Top-level maps with bins long enough to be bin 16 (bin 8 holds at most 255 bytes), beside
# anything else: what unpack_sharing_bins shares, at the small minimums drawn below.
SHARED_MAPS = st.dictionaries(st.text(max_size=12) | st.integers(-5, 5),
                              PACKABLE | st.binary(min_size=250, max_size=700), max_size=6)


def unpacked(payload: bytes, minimum: int):
    """What unpack_sharing_bins returns, or the type of what it raises, with its shared bins
    checked (views of ``payload``, read-only, at least ``minimum`` long) and then copied, so
    that it compares with what msgpack.unpackb returns."""
    try:
        value = unpack_sharing_bins(payload, minimum)
    except Exception as error:
        return type(error)
    if isinstance(value, dict):
        for key, item in value.items():
            if isinstance(item, memoryview):
                assert item.obj is payload and item.readonly and len(item) >= minimum
                value[key] = bytes(item)
    return pack(value)  # (NaN is not equal to itself: compared packed)


def unpacked_by_msgpack(payload: bytes):
    try:
        return pack(msgpack.unpackb(payload, **UNPACK_OPTIONS))
    except Exception as error:
        return type(error)


@PROPERTY_SETTINGS
@given(value=SHARED_MAPS | PACKABLE, minimum=st.sampled_from([1, 256, 400, SHARED_BIN_MIN]))
def test_sharing_bins_unpacks_as_msgpack_does(value, minimum):
    payload = pack(value)
    assert unpacked(payload, minimum) == unpacked_by_msgpack(payload)


@PROPERTY_SETTINGS
@given(value=SHARED_MAPS, data=st.data())
def test_sharing_bins_fails_as_msgpack_does(value, data):
    # Cut short, a byte changed (a bin's length among them), bytes added or removed: the same
    # value, or the same exception, as msgpack.unpackb.
    payload = bytearray(pack(value))
    position = data.draw(st.integers(0, len(payload)))
    kind = data.draw(st.sampled_from(["truncate", "flip", "insert", "delete"]))
    if kind == "truncate":
        del payload[position:]
    elif kind == "flip" and position < len(payload):
        payload[position] = data.draw(st.integers(0, 255))
    elif kind == "insert":
        payload[position:position] = data.draw(st.binary(min_size=1, max_size=4))
    else:
        del payload[position:position + data.draw(st.integers(1, 4))]
    payload = bytes(payload)
    assert unpacked(payload, 1) == unpacked_by_msgpack(payload)


def test_sharing_bins_keeps_msgpacks_limit_on_a_maps_keys():
    payload = pack({f"key{index}": index for index in range(UNPACK_OPTIONS["max_map_len"] + 1)})
    assert unpacked(payload, 1) == unpacked_by_msgpack(payload) == ValueError
    # Past SHARED_BIN_MIN bytes a payload is unpacked the sharing way: refused all the same.
    payload = pack({f"key{index}": index for index in range(100_000)})
    assert len(payload) > SHARED_BIN_MIN
    with pytest.raises(MessageError, match="exceeds max_map_len"):
        decode("Clock", payload)


def test_a_frame_is_decoded_without_copying_its_pixels():
    pixels = np.random.default_rng(3).integers(0, 256, (480, 640, 3), np.uint8)
    payload = encode("Image", bgr_to_message(pixels, 5, 7))
    message = decode("Image", payload)
    assert isinstance(message["data"], memoryview) and message["data"].obj is payload
    assert np.array_equal(image_to_bgr(message), pixels)
    assert encode("Image", message) == payload  # passed on as it came
    small = decode("Image", encode("Image", _image("bgr8")))
    assert type(small["data"]) is bytes  # (below SHARED_BIN_MIN: msgpack's own copy)


def test_binary_fields_refuse_memoryviews_of_wider_items():
    data = memoryview(np.zeros((4, 8, 3), np.uint16)).cast("B").cast("H")
    with pytest.raises(MessageError, match="memoryview of format 'H'"):
        encode("Image", {**_image("bgr8"), "data": data})
