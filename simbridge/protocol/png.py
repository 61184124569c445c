"""The ``png`` compression: a ``publish`` message's JSON packed into the pixels of a PNG.

Layout (protocol reference section 2.17, rosbridge ``pngcompression.py``): the UTF-8 JSON text of
the whole publish message, padded with newlines to ``width * height * 3`` bytes where
``width = floor(sqrt(len / 3))`` and ``height = ceil(len / 3 / width)``, stored as an 8-bit RGB
PNG, base64-encoded and sent as ``{"op": "png", "data": ...}`` in a text frame. The padding is
harmless because ``JSON.parse`` ignores trailing whitespace. roslibjs 1.x and 2.x decode it;
roslibpy and Lichtblick do not.
"""

from __future__ import annotations

import base64
import math
import struct
import zlib

from simbridge.protocol.encoding import Frame, Outgoing, encode_json


__all__ = ["png_bytes", "register"]

_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def png_bytes(payload: bytes) -> bytes:
    """Return an RGB PNG whose pixel bytes are ``payload`` padded with newlines."""
    n = max(len(payload), 3)
    width = max(1, math.floor(math.sqrt(n / 3)))
    height = math.ceil(n / 3 / width)
    row = width * 3
    padded = payload.ljust(row * height, b"\n")
    raw = b"".join(b"\x00" + padded[i : i + row] for i in range(0, len(padded), row))
    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return (
        _SIGNATURE
        + _chunk(b"IHDR", header)
        + _chunk(b"IDAT", zlib.compress(raw, 6))
        + _chunk(b"IEND", b"")
    )


def _encode_png(out: Outgoing, topic: str) -> Frame:
    publish = out.frame("none", topic).data
    data = base64.b64encode(png_bytes(publish)).decode("ascii")
    return Frame(encode_json({"op": "png", "data": data}), True)


def register() -> None:
    """Make ``png`` available to every :class:`Outgoing`."""
    Outgoing.encoders["png"] = _encode_png
