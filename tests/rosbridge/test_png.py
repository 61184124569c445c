from __future__ import annotations

import base64
import json
import math
import struct
import zlib

from simbridge.rosbridge import Outgoing
from simbridge.rosbridge.frames import publish_frame
from simbridge.rosbridge.png import png_bytes


def _pixels(png: bytes) -> tuple[int, int, bytes]:
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    pos, idat, width, height = 8, b"", 0, 0
    while pos < len(png):
        (length,) = struct.unpack(">I", png[pos : pos + 4])
        kind, data = png[pos + 4 : pos + 8], png[pos + 8 : pos + 8 + length]
        if kind == b"IHDR":
            width, height, depth, color = struct.unpack(">IIBB", data[:10])
            assert (depth, color) == (8, 2)  # 8-bit RGB
        elif kind == b"IDAT":
            idat += data
        pos += 12 + length
    raw = zlib.decompress(idat)
    row = width * 3
    rows = [raw[i * (row + 1) + 1 : (i + 1) * (row + 1)] for i in range(height)]
    return width, height, b"".join(rows)


def test_png_layout_is_rosbridges() -> None:
    """Width = floor(sqrt(n/3)), height = ceil(n/3/width), newline padding."""
    payload = b'{"op":"publish","topic":"/t","msg":{"data":"' + b"x" * 100 + b'"}}'
    width, height, pixels = _pixels(png_bytes(payload))
    n = len(payload)
    assert width == math.floor(math.sqrt(n / 3)) and height == math.ceil(n / 3 / width)
    assert pixels.rstrip(b"\n") == payload


def test_png_frame_decodes_to_the_publish_message() -> None:
    """{"op": "png", "data": base64 PNG} in a text frame; the pixels are the JSON publish."""
    frame = publish_frame(Outgoing("/t", None, {"data": "hello"}), "png", "t")
    assert frame.text is True
    body = json.loads(frame.data)
    _w, _h, pixels = _pixels(base64.b64decode(body["data"]))
    assert json.loads(pixels) == {"op": "publish", "topic": "t", "msg": {"data": "hello"}}


def test_every_spelling_of_a_topic_shares_one_compression_of_the_message() -> None:
    """/t, t, /t/ and t/: one compression of the rows before the topic; each frame decodes.

    The topic comes last in the message, so the shared rows are the same for every spelling.
    """
    out = Outgoing("/t", None, {"data": "x" * 100_000})
    frames = {t: publish_frame(out, "png", t) for t in ("/t", "t", "/t/", "t/")}
    shared = out.cache["png"]
    assert len(shared.compressed) > 0 and out.cache["png"] is shared
    for spelling, frame in frames.items():
        _w, _h, pixels = _pixels(base64.b64decode(json.loads(frame.data)["data"]))
        decoded = json.loads(pixels)
        assert decoded == {"op": "publish", "topic": spelling, "msg": {"data": "x" * 100_000}}
        assert next(iter(json.loads(pixels.decode()))) == "op"
