"""simbridge on the ROS 2 graph through Zenoh, wire-compatible with rmw_zenoh (``--zenoh``).

The pure parts (:mod:`.names`, :mod:`.attachment`, :mod:`.typehash`, :mod:`.config`) import
nothing beyond simbridge; :mod:`.link` (the session beside the graph) and :mod:`.router`
(``simbridge zenohd``) import eclipse-zenoh, the ``[zenoh]`` extra, when they run. Nothing
here is imported unless ``--zenoh`` or ``zenohd`` asks for it.
"""

from __future__ import annotations

from simbridge.ros2.names import Entity, Qos, dds_type, ros_type, topic_keyexpr
from simbridge.ros2.typehash import DISTROS, NO_HASH, TypeHasher
from simbridge.ros2.zenoh.attachment import Attachment
from simbridge.ros2.zenoh.config import ZenohOptions


__all__ = [
    "DISTROS",
    "NO_HASH",
    "Attachment",
    "Entity",
    "Qos",
    "TypeHasher",
    "ZenohOptions",
    "dds_type",
    "ros_type",
    "topic_keyexpr",
]
