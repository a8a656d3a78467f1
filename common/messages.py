"""Message schemas of the contract: explicit encode/decode with validation.

Every message is one msgpack map. ``decode(name, payload)`` returns a plain dict or raises
:class:`MessageError` with a one-line reason; ``encode(name, message)`` validates before
packing so a service never publishes what its peers would reject. Extra fields are kept
(the contract allows fields to be added). Nothing here ever unpickles or evaluates data.
"""

import math
from typing import Any, Callable

import msgpack

MAX_IMAGE_SIDE = 8192
MAX_LIST = 4096
ENCODINGS = {"bgr8": 3, "rgb8": 3, "mono8": 1, "jpeg": 0}
SIM_OPS = ("reset", "set_light", "place_ball", "place_robot")


class MessageError(ValueError):
    """A payload that does not decode or does not validate."""


Check = Callable[[Any, str], Any]


def _fail(path: str, reason: str):
    raise MessageError(f"{path}: {reason}")


def integer(minimum: int | None = None, maximum: int | None = None) -> Check:
    def check(value, path):
        if isinstance(value, bool) or not isinstance(value, int):
            _fail(path, f"expected an integer, got {type(value).__name__}")
        if minimum is not None and value < minimum:
            _fail(path, f"{value} is below {minimum}")
        if maximum is not None and value > maximum:
            _fail(path, f"{value} is above {maximum}")
        return value
    return check


def number(minimum: float | None = None, maximum: float | None = None) -> Check:
    def check(value, path):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            _fail(path, f"expected a number, got {type(value).__name__}")
        value = float(value)
        if not math.isfinite(value):
            _fail(path, f"not finite ({value})")
        if minimum is not None and value < minimum:
            _fail(path, f"{value} is below {minimum}")
        if maximum is not None and value > maximum:
            _fail(path, f"{value} is above {maximum}")
        return value
    return check


def text(choices: tuple[str, ...] | None = None, max_length: int = 256) -> Check:
    def check(value, path):
        if not isinstance(value, str):
            _fail(path, f"expected a string, got {type(value).__name__}")
        if len(value) > max_length:
            _fail(path, f"string longer than {max_length}")
        if choices is not None and value not in choices:
            _fail(path, f"{value!r} is not one of {', '.join(choices)}")
        return value
    return check


def boolean(value, path):
    if not isinstance(value, bool):
        _fail(path, f"expected a boolean, got {type(value).__name__}")
    return value


def binary(value, path):
    if not isinstance(value, (bytes, bytearray)):
        _fail(path, f"expected bytes, got {type(value).__name__}")
    return bytes(value)


def vector(length: int, item: Check | None = None) -> Check:
    item = item or number()

    def check(value, path):
        if not isinstance(value, (list, tuple)) or len(value) != length:
            _fail(path, f"expected a list of {length} numbers")
        return [item(element, f"{path}[{index}]") for index, element in enumerate(value)]
    return check


def record(fields: dict[str, Check], optional: dict[str, Check] | None = None) -> Check:
    """A map with required ``fields`` and ``optional`` ones; unknown keys pass through."""
    optional = optional or {}

    def check(value, path):
        if not isinstance(value, dict):
            _fail(path, f"expected a map, got {type(value).__name__}")
        result = dict(value)
        for name, field_check in fields.items():
            if name not in value:
                _fail(f"{path}.{name}" if path else name, "missing")
            result[name] = field_check(value[name], f"{path}.{name}" if path else name)
        for name, field_check in optional.items():
            if name in value:
                result[name] = field_check(value[name], f"{path}.{name}" if path else name)
        return result
    return check


def listing(item: Check, max_items: int = MAX_LIST) -> Check:
    def check(value, path):
        if not isinstance(value, (list, tuple)):
            _fail(path, f"expected a list, got {type(value).__name__}")
        if len(value) > max_items:
            _fail(path, f"more than {max_items} items")
        return [item(element, f"{path}[{index}]") for index, element in enumerate(value)]
    return check


def identifier(value, path):
    if isinstance(value, bool) or not isinstance(value, (int, str)):
        _fail(path, "expected an integer or string id")
    return value


HEADER = record({"stamp": integer(0), "frame_id": text(), "seq": integer(0)})

BALL2D_FIELDS = {
    "x": number(-1.0001, 1.0001),
    "y": number(-1.0001, 1.0001),
    "z": number(0.0, 10.0),
    "u": number(),
    "v": number(),
    "radius_px": number(0.0, 4.0 * MAX_IMAGE_SIDE),
    "image_width": integer(1, MAX_IMAGE_SIDE),
    "image_height": integer(1, MAX_IMAGE_SIDE),
    "score": number(),
}


def _check_image(value, path):
    message = record({
        "header": HEADER,
        "width": integer(1, MAX_IMAGE_SIDE),
        "height": integer(1, MAX_IMAGE_SIDE),
        "encoding": text(tuple(ENCODINGS)),
        "data": binary,
    })(value, path)
    channels = ENCODINGS[message["encoding"]]
    size = len(message["data"])
    if channels:
        expected = message["width"] * message["height"] * channels
        if size != expected:
            _fail("data", f"{size} bytes, but {message['width']}x{message['height']} "
                          f"{message['encoding']} needs {expected}")
    elif size < 4 or message["data"][:2] != b"\xff\xd8":
        _fail("data", "not a JPEG file (no SOI marker)")
    return message


SCHEMAS: dict[str, Check] = {
    "Image": _check_image,
    "CameraInfo": record({
        "header": HEADER,
        "width": integer(1, MAX_IMAGE_SIDE), "height": integer(1, MAX_IMAGE_SIDE),
        "fx": number(1e-6), "fy": number(1e-6), "cx": number(), "cy": number(),
        "hfov": number(1e-6, math.pi), "vfov": number(1e-6, math.pi),
    }),
    "Ball2D": record({"header": HEADER, **BALL2D_FIELDS}),
    "Ball2DArray": record({"header": HEADER, "balls": listing(record(BALL2D_FIELDS))}),
    "Ball3D": record({
        "header": HEADER, "x": number(), "y": number(), "z": number(), "distance": number(0.0),
    }),
    "Twist": record({"header": HEADER, "linear": vector(3), "angular": vector(3)}),
    "Clock": record({"stamp": integer(0)}),
    "GroundTruth": record({
        "header": HEADER,
        "robot": record({"x": number(), "y": number(), "yaw": number()}),
        "balls": listing(record({
            "id": identifier, "radius": number(0.0), "position": vector(3),
            "in_camera": vector(3), "visible": boolean,
        })),
    }),
    "SimCommand": record({"op": text(SIM_OPS)}),
    "SimReply": record({"ok": boolean}, {"error": text(max_length=4096)}),
    "Stats": record({
        "service": text(), "stamp": integer(0),
        "received": integer(0), "published": integer(0),
        "rejected": integer(0), "dropped": integer(0),
        "p50_ms": number(0.0), "p99_ms": number(0.0),
    }, {
        # Added by the simulator: simulated seconds per wall second over the last ~5 s, frames
        # so far, mean render time, frames or ticks that lockstep gave up waiting for.
        "real_time_factor": number(0.0), "frames": integer(0), "render_ms": number(0.0),
        "lockstep_timeouts": integer(0),
    }),
    # The <service>/config queryable: an empty request (or {}) reads, {"set": {...}} changes.
    "ConfigRequest": record({}, {"set": lambda value, path: record({})(value, path)}),
    "ConfigReply": record({"ok": boolean}, {"config": record({}), "error": text(max_length=4096)}),
}


def validate(name: str, message: Any) -> dict:
    """Validate a decoded message against schema ``name``; returns the normalised dict."""
    try:
        schema = SCHEMAS[name]
    except KeyError:
        raise MessageError(f"unknown message type {name!r}") from None
    return schema(message, "")


def encode(name: str, message: dict) -> bytes:
    """Validate and pack ``message`` as schema ``name``."""
    return msgpack.packb(validate(name, message), use_bin_type=True)


def decode(name: str, payload: bytes | bytearray | memoryview) -> dict:
    """Unpack and validate; every failure is a MessageError with a one-line reason."""
    if not payload:
        raise MessageError("empty payload")
    try:
        message = msgpack.unpackb(bytes(payload), raw=False, strict_map_key=False,
                                  max_array_len=1 << 16, max_map_len=1 << 12)
    except Exception as error:  # msgpack raises several unrelated exception types
        raise MessageError(f"not msgpack ({type(error).__name__}: {error})"[:200]) from None
    return validate(name, message)


def header(stamp: int, seq: int, frame_id: str = "camera") -> dict:
    return {"stamp": int(stamp), "frame_id": frame_id, "seq": int(seq)}
