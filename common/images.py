"""Image messages <-> numpy arrays (BGR, OpenCV's order), with the checks a camera stream needs.

A JPEG's own header is read before decoding, so a small file that claims a huge frame, or a
size that disagrees with the message, is rejected without allocating the frame.
"""

import struct
from pathlib import Path

import cv2
import numpy as np

from balltrack.common.messages import MAX_IMAGE_SIDE, MessageError, header as make_header

_SOF_MARKERS = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}
# Pixels one byte of JPEG can hold at most: a uniform frame from OpenCV's encoder has 64, the
# entropy coder's best case a few hundred. A file that claims far more (100 bytes for 8192x8192)
# is a lie that would still cost the decoder the whole frame, 200 MB and a second.
MAX_PIXELS_PER_JPEG_BYTE = 1024


def jpeg_size(data: bytes) -> tuple[int, int]:
    """(width, height) from a JPEG's start-of-frame segment; MessageError if there is none."""
    position = 2
    length = len(data)
    while position + 4 <= length:
        if data[position] != 0xFF:
            raise MessageError("data: corrupt JPEG (bad marker)")
        marker = data[position + 1]
        if marker == 0xFF:
            position += 1
            continue
        if marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7:
            position += 2
            continue
        segment_length = struct.unpack(">H", data[position + 2:position + 4])[0]
        if marker in _SOF_MARKERS:
            if position + 9 > length:
                break
            height, width = struct.unpack(">HH", data[position + 5:position + 9])
            return width, height
        position += 2 + segment_length
    raise MessageError("data: corrupt JPEG (no frame header)")


class UnreadableImage(ValueError):
    """A file that ``read_image`` cannot make an image of; the text is the reason."""


def read_image(path) -> np.ndarray:
    """The image file at ``path`` as HxWx3 uint8 BGR; UnreadableImage saying why not (no such
    file, a folder, not an image OpenCV decodes).

    Read here, then decoded: ``cv2.imread`` gives only None and prints a warning of its own
    (``[ WARN:0@0.4] global loadsave.cpp ... can't open/read file``) beside the command's error.
    """
    try:
        data = Path(path).read_bytes()
    except OSError as error:
        raise UnreadableImage(error.strerror or str(error)) from None
    # (imdecode asserts on an empty buffer)
    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR) if data else None
    if image is None:
        raise UnreadableImage("not an image OpenCV decodes")
    return image


def image_to_bgr(message: dict) -> np.ndarray:
    """Decode a validated Image message to an HxWx3 uint8 BGR array."""
    width, height, encoding, data = (message["width"], message["height"],
                                     message["encoding"], message["data"])
    if encoding == "jpeg":
        jpeg_width, jpeg_height = jpeg_size(data)
        if (jpeg_width, jpeg_height) != (width, height):
            raise MessageError(f"data: JPEG is {jpeg_width}x{jpeg_height}, message says {width}x{height}")
        if width * height > MAX_PIXELS_PER_JPEG_BYTE * len(data):
            raise MessageError(f"data: {len(data)} bytes cannot hold a {width}x{height} JPEG")
        image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
        if image is None or image.shape[:2] != (height, width):
            raise MessageError("data: corrupt JPEG (decoder failed)")
        return image
    if encoding == "mono8":
        gray = np.frombuffer(data, np.uint8).reshape(height, width)
        return cv2.cvtColor(gray, cv2.COLOR_GRAY2BGR)
    array = np.frombuffer(data, np.uint8).reshape(height, width, 3)
    return cv2.cvtColor(array, cv2.COLOR_RGB2BGR) if encoding == "rgb8" else array


def bgr_to_message(image: np.ndarray, stamp: int, seq: int, frame_id: str = "camera",
                   encoding: str = "bgr8", jpeg_quality: int = 90) -> dict:
    """An Image message from a BGR (or single-channel) array."""
    if image.ndim == 2:
        if encoding == "mono8":
            data = np.ascontiguousarray(image).tobytes()
        else:
            image = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    height, width = image.shape[:2]
    if width > MAX_IMAGE_SIDE or height > MAX_IMAGE_SIDE:
        raise MessageError(f"image {width}x{height} exceeds {MAX_IMAGE_SIDE} px")
    if encoding == "jpeg":
        ok, buffer = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality])
        if not ok:
            raise MessageError("JPEG encoding failed")
        data = buffer.tobytes()
    elif encoding == "rgb8":
        data = np.ascontiguousarray(cv2.cvtColor(image, cv2.COLOR_BGR2RGB)).tobytes()
    elif encoding == "mono8":
        if image.ndim == 3:
            data = np.ascontiguousarray(cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)).tobytes()
    elif encoding == "bgr8":
        data = np.ascontiguousarray(image).tobytes()
    else:
        raise MessageError(f"encoding: unknown {encoding!r}")
    return {"header": make_header(stamp, seq, frame_id), "width": int(width),
            "height": int(height), "encoding": encoding, "data": data}
