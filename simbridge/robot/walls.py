"""The world's walls as a latched ROS topic, so any page or tool can draw them.

``/walls`` (visualization_msgs/msg/Marker, latched, frame ``odom``): one ``LINE_LIST`` marker
(namespace ``walls``, id 0) whose ``points`` hold each wall and obstacle edge as a pair of
points, the same segments the LiDAR and collisions use. A page subscribes once and receives it at
once (latched replay); Foxglove and RViz draw it as is. The robots' ``odom`` frame coincides with
the world frame in simbridge (odometry has no drift), so no further transform is needed.
"""

from __future__ import annotations

from typing import Any

from simbridge.graph.graph import Graph
from simbridge.sim import World


__all__ = ["WALLS_TOPIC", "WallsPublisher", "walls_marker"]

WALLS_TOPIC = "/walls"
LINE_LIST = 5


def walls_marker(world: World, stamp: tuple[int, int], frame: str = "odom") -> dict[str, Any]:
    """Return the ``LINE_LIST`` marker of every segment of ``world``."""
    points = []
    for x1, y1, x2, y2 in world.segments.tolist():
        points.append({"x": x1, "y": y1, "z": 0.0})
        points.append({"x": x2, "y": y2, "z": 0.0})
    zero = {"x": 0.0, "y": 0.0, "z": 0.0}
    return {
        "header": {"stamp": {"sec": stamp[0], "nanosec": stamp[1]}, "frame_id": frame},
        "ns": "walls",
        "id": 0,
        "type": LINE_LIST,
        "action": 0,
        "pose": {"position": zero, "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}},
        "scale": {"x": 0.03, "y": 0.0, "z": 0.0},
        "color": {"r": 0.2, "g": 0.2, "b": 0.25, "a": 1.0},
        "lifetime": {"sec": 0, "nanosec": 0},
        "frame_locked": False,
        "points": points,
        "colors": [],
        "texture_resource": "",
        "texture": {
            "header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": ""},
            "format": "",
            "data": [],
        },
        "uv_coordinates": [],
        "text": "",
        "mesh_resource": "",
        "mesh_file": {"filename": "", "data": []},
        "mesh_use_embedded_materials": False,
    }


class WallsPublisher:
    """Advertises ``/walls`` on ``graph`` and latches the walls of ``world``."""

    def __init__(self, graph: Graph, world: World) -> None:
        self.graph = graph
        self.world = world
        self.topic = graph.advertise(
            WALLS_TOPIC, "visualization_msgs/msg/Marker", "/virtual_robot", latch=True
        )

    def publish(self, now: float) -> None:
        """Publish (latch) the current walls."""
        self.graph.publish(self.topic, walls_marker(self.world, self.graph.stamp()), now)
