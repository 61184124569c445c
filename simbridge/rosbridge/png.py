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

import orjson

from simbridge.rosbridge.encoding import Frame, Outgoing, encode_none, json_body


__all__ = ["encode_png_frame", "png_bytes"]

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


#: Room for the topic at the end of the publish message: ``,"topic":"NAME"}`` for a ROS name
#: of at most 256 characters (ASCII: :func:`~simbridge.rosbridge.ops.resolve_name` refuses the
#: rest).
_TOPIC_ROOM = len(b',"topic":""}') + 256
_HEAD = b'{"op":"publish","msg":'


def encode_png_frame(out: Outgoing, topic: str) -> Frame:
    """Return the ``png`` publish frame of ``out`` (the rows before the topic made once)."""
    """Return the ``png`` frame of ``out`` for one topic spelling, compressing the body once.

    The message's fields are written with the topic last (``JSON.parse`` does not care about
    the order) and the image is sized for the longest topic name, so every spelling of the
    topic (``/chatter``, ``chatter``, ``chatter/``) shares the pixel rows before the topic:
    they are compressed once, up to a full flush (RFC 1950/1951: the compressor forgets its
    window there, so what follows is compressed on its own), and each spelling compresses only
    its last rows. A 990 kB message subscribed under four spellings was compressed four times
    (200 ms of the loop); it is now compressed once.
    """
    name = orjson.dumps(topic)
    if len(name) > _TOPIC_ROOM - len(b',"topic":}'):  # not a ROS name: no shared layout
        publish = encode_none(out, topic).data
        return _png_frame(png_bytes(publish))
    shared = out.cache.get("png")
    if shared is None:
        shared = out.cache["png"] = _SharedRows.of(_HEAD + json_body(out))
    return _png_frame(shared.png(b',"topic":' + name + b"}"))


def _png_frame(png: bytes) -> Frame:
    return Frame(b'{"op":"png","data":"' + base64.b64encode(png) + b'"}', True)


class _SharedRows:
    """The compressed pixel rows every spelling of a topic shares, and the image's geometry."""

    __slots__ = ("adler", "compressed", "header", "left", "rest", "row")

    def __init__(
        self, row: int, left: int, compressed: bytes, adler: int, rest: bytes, header: bytes
    ) -> None:
        #: Bytes of a row (3 a pixel), and bytes of the rows after the shared ones.
        self.row, self.left = row, left
        #: The zlib stream of the shared rows, up to a full flush, and their Adler-32.
        self.compressed, self.adler = compressed, adler
        #: The start of the message after the last shared row (it goes with the topic).
        self.rest = rest
        #: The IHDR chunk.
        self.header = header

    @classmethod
    def of(cls, head: bytes) -> _SharedRows:
        """Compress the rows of a message whose JSON starts with ``head`` (all but its topic)."""
        n = len(head) + _TOPIC_ROOM
        width = max(1, math.floor(math.sqrt(n / 3)))
        height = math.ceil(n / 3 / width)
        row = width * 3
        full = len(head) // row
        raw = b"".join(b"\x00" + head[i * row : (i + 1) * row] for i in range(full))
        compressor = zlib.compressobj(6)
        compressed = compressor.compress(raw) + compressor.flush(zlib.Z_FULL_FLUSH)
        header = _chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0))
        rest = head[full * row :]
        return cls(row, (height - full) * row, compressed, zlib.adler32(raw), rest, header)

    def png(self, tail: bytes) -> bytes:
        """Return the PNG of the message whose JSON ends with ``tail`` (its topic)."""
        row = self.row
        last = (self.rest + tail).ljust(self.left, b"\n")
        raw = b"".join(b"\x00" + last[i : i + row] for i in range(0, len(last), row))
        deflate = zlib.compressobj(6, zlib.DEFLATED, -15)  # raw deflate: the stream goes on
        end = deflate.compress(raw) + deflate.flush()
        idat = self.compressed + end + struct.pack(">I", zlib.adler32(raw, self.adler))
        return _SIGNATURE + self.header + _chunk(b"IDAT", idat) + _chunk(b"IEND", b"")
