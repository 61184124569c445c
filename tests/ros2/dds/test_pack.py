"""The DDS link's writers sharing one transmit pack, on Cyclone DDS itself.

Whether samples sent through it reach other processes' readers (Fast DDS, Cyclone) is
test_link.py's part; this is its life cycle on a real participant: lent, written through,
given back before a writer or the participant is deleted (a writer deleted with the shared
pack would free it under the others).
"""

from __future__ import annotations

import importlib.metadata

import pytest

from tests.ros2.dds.harness import NetNamespace


pytestmark = pytest.mark.skipif(
    importlib.metadata.version("cyclonedds") not in ("11.0.1",),
    reason="the shared pack is made for the binding 11.0.1 only",
)


def test_writers_write_through_the_shared_pack_and_are_deleted_with_their_own(
    netns: NetNamespace, dds_domain: int
) -> None:
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.pub import DataWriter
    from cyclonedds.topic import Topic

    from simbridge.msgs import TypeRegistry
    from simbridge.ros2.dds.link import _write_raw
    from simbridge.ros2.dds.pack import SharedPack
    from simbridge.ros2.dds.types import IdlTypes

    string = IdlTypes(TypeRegistry()).get("std_msgs/msg/String")
    data = b"\x00\x01\x00\x00" + (3).to_bytes(4, "little") + b"hi\x00"
    with netns.entered():
        participant = DomainParticipant(dds_domain)
        try:
            first, second, third = (
                DataWriter(participant, Topic(participant, f"rt/t{k}", string)) for k in range(3)
            )
            pack = SharedPack.create(first)
            assert pack is not None
            assert pack.adopt(first) and pack.adopt(second)
            assert not pack.adopt(first), "a writer that batches already is not taken twice"
            for writer in (first, second, third):
                _write_raw(writer, data)
            pack.flush()
            pack.release(second)
            second.__del__()  # its own pack is freed, not the shared one
            _write_raw(first, data)
            pack.close()  # the first gets its own back; the pack is freed, once
            pack.close()
            _write_raw(first, data)  # unbatched again: it sends it at once
        finally:
            participant.__del__()
