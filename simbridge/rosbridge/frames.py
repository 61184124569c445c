"""The ``publish`` frame of a message for each rosbridge compression, made once.

``compression`` of ``subscribe`` (protocol section 3.4.4): ``none`` (JSON), ``cbor``,
``cbor-raw`` (the CDR bytes, ROS 2 style) and ``png`` (the JSON in a PNG image, in a JSON
frame). A frame is kept in the message's cache per (compression, topic spelling): every
subscriber that asks for the same one shares it.
"""

from __future__ import annotations

from simbridge.errors import ProtocolError
from simbridge.rosbridge.cbor import encode_cbor_frame, encode_cbor_raw_frame
from simbridge.rosbridge.encoding import Encoder, Frame, Outgoing, encode_none
from simbridge.rosbridge.png import encode_png_frame


__all__ = ["ENCODERS", "publish_frame"]

#: The frame builder of each compression.
ENCODERS: dict[str, Encoder] = {
    "none": encode_none,
    "cbor": encode_cbor_frame,
    "cbor-raw": encode_cbor_raw_frame,
    "png": encode_png_frame,
}


def publish_frame(out: Outgoing, compression: str, topic: str) -> Frame:
    """Return the publish frame for one compression and one topic spelling (cached).

    Raises:
        ProtocolError: the compression cannot encode this message (e.g. ``cbor-raw`` of an
            unknown type), or is not available.
    """
    key = (compression, topic)
    frame: Frame | None = out.cache.get(key)
    if frame is None:
        encoder = ENCODERS.get(compression)
        if encoder is None:
            msg = f"compression '{compression}' is not available in this server"
            raise ProtocolError(msg)
        frame = out.cache[key] = encoder(out, topic)
    return frame
