"""The 33-byte attachment of rmw_zenoh."""

from __future__ import annotations

import pytest

from simbridge.ros2.zenoh.attachment import Attachment, pack_attachment


def test_attachment_is_sequence_timestamp_length_and_gid_little_endian() -> None:
    gid = bytes(range(16))
    data = Attachment(5, 1_700_000_000_000_000_000, gid).pack()
    assert len(data) == 33
    assert data[:8] == (5).to_bytes(8, "little")
    assert data[16] == 16 and data[17:] == gid
    assert Attachment.unpack(data) == Attachment(5, 1_700_000_000_000_000_000, gid)


@pytest.mark.parametrize("data", [b"", b"\x00" * 16, b"\x00" * 16 + b"\x10" + b"\x01" * 3])
def test_short_attachments_are_refused(data: bytes) -> None:
    with pytest.raises(ValueError, match="attachment"):
        Attachment.unpack(data)


@pytest.mark.parametrize("size", [0, 8, 16, 24])
def test_a_gid_of_any_length_is_packed_after_its_length(size: int) -> None:
    gid = bytes(range(size))
    data = pack_attachment(7, 42, gid)
    assert data == (7).to_bytes(8, "little") + (42).to_bytes(8, "little") + bytes([size]) + gid
    assert Attachment.unpack(data) == Attachment(7, 42, gid)
