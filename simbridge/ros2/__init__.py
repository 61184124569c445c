"""What the ROS 2 transports share, and each of them: Zenoh (:mod:`.zenoh`) and DDS (:mod:`.dds`).

The pure parts: ROS 2 names on the wire and QoS (:mod:`.names`), the RIHS01 type hashes of each
distro (:mod:`.typehash`); the CDR of a message is made once by :mod:`simbridge.msgs.cdr`.
What every link keeps on the event loop's side (the bounded inbox of samples from the library's
threads, rate-limited log lines, the ROS 2 peers' refusals, what of the graph goes outward) is
:mod:`.link`. A
transport's package imports its library only when its option (``--zenoh``, ``--dds``) asks for
it.
"""

from __future__ import annotations

from simbridge.ros2.names import Entity, Qos, dds_type, ros_type
from simbridge.ros2.typehash import DISTROS, NO_HASH, TypeHasher


__all__ = ["DISTROS", "NO_HASH", "Entity", "Qos", "TypeHasher", "dds_type", "ros_type"]
