"""ROS 2 over DDS (``simbridge --dds``, the ``[dds]`` extra): the graph as DDS participants see it.

:mod:`~simbridge.ros2.dds.wire` holds what the ROS 2 DDS middlewares put on the wire besides
the messages (pure), :mod:`~simbridge.ros2.dds.options` the environment and Cyclone's
configuration, :mod:`~simbridge.ros2.dds.link` the front end itself (imports Cyclone DDS),
:mod:`~simbridge.ros2.dds.pack` the transmit pack its writers share (a step's samples in a few
datagrams).
"""

from simbridge.ros2.dds.options import DdsOptions


__all__ = ["DdsOptions"]
