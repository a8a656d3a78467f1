"""Message schemas of the contract: explicit encode/decode with validation.

Every message is one msgpack map. ``decode(name, payload)`` returns a plain dict or raises
:class:`MessageError` with a one-line reason; ``encode(name, message)`` validates before
packing so a service never publishes what its peers would reject. Extra fields are kept
(the contract allows fields to be added), except in a ConfigRequest, whose unknown field is
refused: there it is a typo or an ask this service cannot do, and read as a plain read it would
be answered ok while nothing changed. Nothing here ever unpickles or evaluates data.

Which clock every time field carries, and what a simulator's restart does to it: docs/contract.md,
*Clocks*. In short, data messages are on the frames' clock, Stats' ``stamp``
on the wall clock.
"""

import io
import math
import reprlib
from typing import Any, Callable

import msgpack

MAX_IMAGE_SIDE = 8192
MAX_LIST = 4096
# A header is copied downstream with every derived message: it carries only its contract
# fields, and a frame id longer than this is refused (ROS frame ids are a few words).
MAX_FRAME_ID = 64
HEADER_FIELDS = ("stamp", "frame_id", "seq")
# Nesting levels a message may have (the contract's deepest, GroundTruth, has 4).
MAX_DEPTH = 32
# A refused unknown field is named, but of a map with thousands only this many: the error goes
# into a reply and a log line.
UNKNOWN_FIELDS_NAMED = 3
ENCODINGS = {"bgr8": 3, "rgb8": 3, "mono8": 1, "jpeg": 0}
SIM_OPS = ("reset", "set_light", "place_ball", "place_robot")
DISTORTION_MODELS = ("plumb_bob", "", "none")
# Bins of at least this many bytes at a message's top level (a frame's pixels) are not copied
# out of the payload by ``decode``: they come back as read-only memoryviews of it. msgpack
# copies every bin into a new bytes object, and for a frame that copy is most of the decode,
# on the path from frame to detection (all the more in a process that was idle between frames,
# its caches cold).
SHARED_BIN_MIN = 1 << 16
# msgpack's first byte and length-field size of the bin formats that can hold SHARED_BIN_MIN
# bytes (bin 16, bin 32; bin 8 holds at most 255).
_BIN_LENGTH_BYTES = {0xC5: 2, 0xC6: 4}
UNPACK_OPTIONS = {"raw": False, "strict_map_key": False, "max_array_len": 1 << 16, "max_map_len": 1 << 12}
# The Unpacker reads a payload past its shared bins in pieces of this size (bytes).
_READ_SIZE = 4096


class MessageError(ValueError):
    """A payload that does not decode or does not validate."""


class _ShortRepr(reprlib.Repr):
    """reprlib with a size summary for bytes (whose plain repr would be as long as the data)."""

    def repr_bytes(self, value, level):
        return f"<{len(value)} bytes>"

    repr_bytearray = repr_memoryview = repr_bytes


_SHORT_REPR = _ShortRepr()
_SHORT_REPR.maxlevel = 3
_SHORT_REPR.maxstring = _SHORT_REPR.maxother = 60
_SHORT_REPR.maxlong = 30


def shorten(value: Any, limit: int = 120) -> str:
    """One line of at most about ``limit`` characters describing ``value``, for error messages
    and logs: a peer's 1 MB string or 1,000-deep list must not be copied into every reply and
    log line (nor overflow the recursion limit while being formatted). A string is shown as
    itself, anything else as a bounded repr."""
    try:
        text = value if isinstance(value, str) else _SHORT_REPR.repr(value)
    except Exception as error:  # a repr that fails must not turn a rejection into a crash
        text = f"<{type(value).__name__}: unprintable ({type(error).__name__})>"
    if len(text) > limit:
        text = f"{text[:limit]}... ({len(text)} characters)"
    return text.replace("\r", "\\r").replace("\n", "\\n")


Check = Callable[[Any, str], Any]


def _fail(path: str, reason: str):
    # (a path may hold a peer's map key: ConfigReply's parameter names, any string at all)
    raise MessageError(f"{shorten(path, 200)}: {reason}")


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
            _fail(path, f"{shorten(repr(value), 60)} is not one of {', '.join(choices)}")
        return value
    return check


def boolean(value, path):
    if not isinstance(value, bool):
        _fail(path, f"expected a boolean, got {type(value).__name__}")
    return value


def binary(value, path):
    """bytes (a bytearray is copied into bytes); a memoryview of bytes, such as ``decode``
    returns for a large bin, is kept as it is."""
    if isinstance(value, memoryview):
        if value.ndim != 1 or value.itemsize != 1 or not value.c_contiguous:
            _fail(path, f"expected bytes, got a memoryview of format {value.format!r}, shape {value.shape}")
        return value
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


def record(fields: dict[str, Check], optional: dict[str, Check] | None = None,
           closed: bool = False) -> Check:
    """A map with required ``fields`` and ``optional`` ones; unknown keys pass through, or with
    ``closed`` are refused (the error names the first UNKNOWN_FIELDS_NAMED of them)."""
    optional = optional or {}
    known = {**fields, **optional}

    def check(value, path):
        if not isinstance(value, dict):
            _fail(path, f"expected a map, got {type(value).__name__}")
        if closed:
            _refuse_unknown(value, known, path)
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


def _refuse_unknown(value: dict, known: dict, path: str) -> None:
    unknown = [key for key in value if key not in known]
    if not unknown:
        return
    # (repr: a key may be any msgpack value, and quotes show a stray space in a name)
    named = ", ".join(shorten(repr(key), 40) for key in unknown[:UNKNOWN_FIELDS_NAMED])
    more = f" and {len(unknown) - UNKNOWN_FIELDS_NAMED} more" if len(unknown) > UNKNOWN_FIELDS_NAMED else ""
    plural = "s" if len(unknown) > 1 else ""
    reason = f"unknown field{plural} {named}{more} (expected only {', '.join(known) or 'nothing'})"
    raise MessageError(f"{shorten(path, 200)}: {reason}" if path else reason)


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


_HEADER_RECORD = record({"stamp": integer(0), "frame_id": text(max_length=MAX_FRAME_ID),
                         "seq": integer(0)})


def _header(value, path):
    """The header's contract fields only: services copy a header into what they derive from
    the message, so anything else it carried (say a 1 MB extra field) would travel on."""
    checked = _HEADER_RECORD(value, path)
    return {name: checked[name] for name in HEADER_FIELDS}


HEADER = _header

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


_IMAGE_RECORD = record({
    "header": HEADER,
    "width": integer(1, MAX_IMAGE_SIDE),
    "height": integer(1, MAX_IMAGE_SIDE),
    "encoding": text(tuple(ENCODINGS)),
    "data": binary,
})


def _check_image(value, path):
    message = _IMAGE_RECORD(value, path)
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


def _or_none(check: Check) -> Check:
    def checked(value, path):
        return None if value is None else check(value, path)
    return checked


_PARAMETER = record({"type": text(), "meaning": text(max_length=1024)},
                   {"low": _or_none(number()), "high": _or_none(number()), "low_open": boolean,
                    "high_open": boolean, "bounds": text(),
                    "choices": _or_none(listing(text(), max_items=256))})


def _parameters(value, path):
    """ConfigReply's ``parameters``: {name: the declaration of one parameter}."""
    checked = record({})(value, path)
    if len(checked) > MAX_LIST:
        _fail(path, f"more than {MAX_LIST} parameters")
    return {name: _PARAMETER(declared, f"{path}.{name}") for name, declared in checked.items()}


SCHEMAS: dict[str, Check] = {
    "Image": _check_image,
    "CameraInfo": record({
        "header": HEADER,
        "width": integer(1, MAX_IMAGE_SIDE), "height": integer(1, MAX_IMAGE_SIDE),
        "fx": number(1e-6), "fy": number(1e-6), "cx": number(), "cy": number(),
        "hfov": number(1e-6, math.pi), "vfov": number(1e-6, math.pi),
    }, {
        # Lens distortion, as ROS names it: "plumb_bob" with d = [k1, k2, p1, p2, k3] (up to 8
        # coefficients: k4, k5, k6 of the rational model), or "" / "none" (or absent): none.
        "distortion_model": text(DISTORTION_MODELS),
        "d": listing(number(), max_items=8),
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
    # Diagnostics of a process, not data: ``stamp`` is wall-clock time, which ``stamp_clock``
    # ("wall") names; the simulator's ``command_stamp`` and ``command_time`` are simulated time.
    "Stats": record({
        "service": text(), "stamp": integer(0),
        "received": integer(0), "published": integer(0),
        "rejected": integer(0), "dropped": integer(0),
        "p50_ms": number(0.0), "p99_ms": number(0.0),
    }, {
        "stamp_clock": text(max_length=32),
        # Added by the simulator: simulated seconds per wall second over the last ~5 s, frames
        # so far, mean render time, frames or ticks that lockstep gave up waiting for, and the
        # simulated time at which it took the last cmd_vel (the safety stop counts from there).
        "real_time_factor": number(0.0), "frames": integer(0), "render_ms": number(0.0),
        "lockstep_timeouts": integer(0), "command_time": number(), "command_stamp": integer(0),
    }),
    # The <service>/config queryable: an empty request (or {}) reads, {"set": {...}} changes,
    # {"describe": true} adds every parameter's declaration to the reply. Closed: {"sett": ...}
    # is refused rather than answered as a read that changed nothing.
    "ConfigRequest": record({}, {"set": lambda value, path: record({})(value, path),
                                 "describe": boolean}, closed=True),
    "ConfigReply": record({"ok": boolean}, {"config": record({}), "error": text(max_length=4096),
                                            "parameters": _parameters}),
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


def _check_depth(message: Any, limit: int = MAX_DEPTH) -> None:
    """Refuse values nested deeper than ``limit``: no contract message goes past 4 levels, and
    msgpack packs only 511 (it unpacks 1,024), so a deeper value could not be passed on.
    (Comprehensions with exact type tests: the generator version took 19 us of a Ball2D's
    48 us decode on this machine, 11 us this way; msgpack gives only these container types,
    its maps' array keys as tuples.)"""
    level = [message]
    for _ in range(limit + 1):
        deeper = []
        for value in level:
            if type(value) is dict:
                deeper += [item for item in value.values() if type(item) is dict or type(item) is list]
                deeper += [key for key in value if type(key) is tuple]
            elif type(value) is list or type(value) is tuple:
                deeper += [item for item in value
                           if type(item) is dict or type(item) is list or type(item) is tuple]
        if not deeper:
            return
        level = deeper
    raise MessageError(f"nested deeper than {limit} levels")


def decode(name: str, payload: bytes | bytearray | memoryview) -> dict:
    """Unpack and validate; every failure is a MessageError with a one-line reason. Bins of at
    least SHARED_BIN_MIN bytes among the message's fields are read-only memoryviews of
    ``payload`` (see ``unpack_sharing_bins``)."""
    if not payload:
        raise MessageError("empty payload")
    try:
        message = unpack_sharing_bins(bytes(payload))
    except Exception as error:  # msgpack raises several unrelated exception types
        raise MessageError(f"not msgpack ({type(error).__name__}: {shorten(str(error), 150)})") from None
    _check_depth(message)
    return validate(name, message)


def unpack_sharing_bins(payload: bytes, minimum: int = SHARED_BIN_MIN) -> Any:
    """``msgpack.unpackb(payload)`` (with this module's limits), except that the bin values of
    at least ``minimum`` bytes of a top-level map are read-only memoryviews of ``payload``
    instead of copies.

    msgpack decodes every key and every other value, reading the payload through a file
    object in _READ_SIZE pieces; only a bin's 3- or 5-byte header is read here, to step over
    its bytes. Anything else (not a map, a value cut short, bytes after the map) is left to
    ``msgpack.unpackb``, which raises as it always does.
    """
    if len(payload) < minimum:
        return msgpack.unpackb(payload, **UNPACK_OPTIONS)  # (no bin to share: the quick way)
    file = io.BytesIO(payload)  # (shares payload's memory: no copy)
    unpacker = msgpack.Unpacker(file, read_size=_READ_SIZE, **UNPACK_OPTIONS)
    base = 0  # where in payload the current unpacker started reading
    try:
        count = unpacker.read_map_header()
        if count > UNPACK_OPTIONS["max_map_len"]:
            # (read_map_header does not apply the limit; msgpack.unpackb below raises its error)
            raise ValueError("map too long")
        message = {}
        for _ in range(count):
            key = unpacker.unpack()
            start, length = _bin_at(payload, base + unpacker.tell())
            if length >= minimum:
                message[key] = memoryview(payload)[start:start + length]
                base = start + length
                file.seek(base)
                unpacker = msgpack.Unpacker(file, read_size=_READ_SIZE, **UNPACK_OPTIONS)
            else:
                message[key] = unpacker.unpack()
        if base + unpacker.tell() == len(payload):
            return message
    except Exception:  # (msgpack's error, with its message, comes from unpackb below)
        pass
    return msgpack.unpackb(payload, **UNPACK_OPTIONS)


def _bin_at(payload: bytes, position: int) -> tuple[int, int]:
    """Where the data of a bin 16 or bin 32 value at ``position`` starts and how long it is;
    length -1 when there is no such value there, or its data would run past the payload."""
    size = _BIN_LENGTH_BYTES.get(payload[position]) if position < len(payload) else None
    if size is None:
        return 0, -1
    start = position + 1 + size
    length = int.from_bytes(payload[position + 1:start], "big")
    return (start, length) if start + length <= len(payload) else (0, -1)


def header(stamp: int, seq: int, frame_id: str = "camera") -> dict:
    return {"stamp": int(stamp), "frame_id": frame_id, "seq": int(seq)}
