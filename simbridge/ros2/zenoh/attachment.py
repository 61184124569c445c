"""The attachment rmw_zenoh puts on every sample, request and reply.

Little-endian: sequence number (int64), source timestamp in ns (int64), then the 16-byte GID as
zenoh-ext serializes an array: one length byte (16) and the bytes, 33 bytes in all
(rmw_zenoh_cpp ``attachment_helpers.cpp``). A service reply carries the request's sequence
number and the client's GID, so that the client can match it.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass


__all__ = ["Attachment", "pack_attachment"]

_HEAD = struct.Struct("<qqB")
#: The whole attachment with rmw_zenoh's 16-byte GID, packed by one call (every sample has one).
_GID16 = struct.Struct("<qqB16s")


def pack_attachment(sequence: int, timestamp_ns: int, gid: bytes) -> bytes:
    """Return the wire bytes of an attachment (what :meth:`Attachment.pack` returns)."""
    if len(gid) == 16:
        return _GID16.pack(sequence, timestamp_ns, 16, gid)
    return _HEAD.pack(sequence, timestamp_ns, len(gid)) + gid


@dataclass(frozen=True, slots=True)
class Attachment:
    """Sequence number, source timestamp (ns) and source GID of a sample or request."""

    sequence: int
    timestamp_ns: int
    gid: bytes

    def pack(self) -> bytes:
        """Return the wire bytes."""
        return pack_attachment(self.sequence, self.timestamp_ns, self.gid)

    @classmethod
    def unpack(cls, data: bytes) -> Attachment:
        """Read the wire bytes.

        Raises:
            ValueError: too short, or the GID length does not match the bytes.
        """
        if len(data) < _HEAD.size:
            msg = f"attachment of {len(data)} bytes, expected at least {_HEAD.size}"
            raise ValueError(msg)
        sequence, stamp, size = _HEAD.unpack_from(data)
        gid = bytes(data[_HEAD.size : _HEAD.size + size])
        if len(gid) != size:
            msg = f"attachment GID says {size} bytes, {len(gid)} present"
            raise ValueError(msg)
        return cls(sequence, stamp, gid)
