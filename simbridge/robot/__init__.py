"""The robot world's nodes on the graph, and the one place that assembles them.

The robots' ROS interface (``/cmd_vel``, ``/odom``, ``/scan``, ``/tf``, ``/spawn``...), the
``/cmd_vel`` watchdog, the e-stops, the fleet, ``/walls``, the sim clock, tf2_web_republisher,
the tutorial nodes and the roles a page can take: in-process nodes on the graph's API, like any
front end. :func:`~simbridge.robot.assembly.build_robot_graph` builds them from the settings.
"""

from __future__ import annotations

from simbridge.robot.assembly import RobotGraph, build_robot_graph
from simbridge.robot.bridge import ROBOT_NODE, RobotBridge
from simbridge.robot.simclock import SIM_NODE, SimClock


__all__ = ["ROBOT_NODE", "SIM_NODE", "RobotBridge", "RobotGraph", "SimClock", "build_robot_graph"]
