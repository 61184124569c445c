"""The robot's ROS graph, shared by every front end: topics, services, actions, parameters.

Topics with latched caches, services, actions and the parameters of the in-process nodes,
carrying canonical messages; the access rules every front end's peers are admitted by. No I/O.
"""

from __future__ import annotations

from simbridge.graph.graph import ROSOUT, Graph, PeerWatcher
from simbridge.graph.params import ParameterStore, ParamNode
from simbridge.graph.services import PendingCall, Service, ServiceTable, caller, typed_calls
from simbridge.graph.topics import BRIDGE_NODE, Peer, Topic, TopicTable


__all__ = [
    "BRIDGE_NODE",
    "ROSOUT",
    "Graph",
    "ParamNode",
    "ParameterStore",
    "Peer",
    "PeerWatcher",
    "PendingCall",
    "Service",
    "ServiceTable",
    "Topic",
    "TopicTable",
    "caller",
    "typed_calls",
]
