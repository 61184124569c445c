"""The ROS-graph facade between the simulator and the protocol.

Topics with latched caches, services, rosapi, and the virtual robot's ROS interface. No I/O.
"""

from __future__ import annotations

from simbridge.graph.bridge import ROBOT_NODE, RobotBridge
from simbridge.graph.graph import ROSOUT, Graph
from simbridge.graph.params import ParameterStore, ParamNode
from simbridge.graph.rosapi import ROSAPI_NODE, install_rosapi, request_fields
from simbridge.graph.services import Service, ServiceTable, service_response
from simbridge.graph.simclock import SIM_NODE, SimClock
from simbridge.graph.topics import BRIDGE_NODE, Peer, Topic, TopicTable


__all__ = [
    "BRIDGE_NODE",
    "ROBOT_NODE",
    "ROSAPI_NODE",
    "ROSOUT",
    "SIM_NODE",
    "Graph",
    "ParamNode",
    "ParameterStore",
    "Peer",
    "RobotBridge",
    "Service",
    "ServiceTable",
    "SimClock",
    "Topic",
    "TopicTable",
    "install_rosapi",
    "request_fields",
    "service_response",
]
