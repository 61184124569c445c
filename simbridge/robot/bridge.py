"""The virtual robot's ROS interface: simulation state in, ROS messages out.

Node ``/virtual_robot`` publishes, per robot (REP-105 frames, wall-clock header stamps):

* ``/odom`` (nav_msgs/Odometry) every step: frame ``odom``, child ``base_link``, the pose with
  quaternion ``z = sin(theta/2), w = cos(theta/2)``, and the applied (clamped) velocity;
* ``/tf`` (tf2_msgs/TFMessage) every step: ``odom -> base_link``, the same pose;
* ``/ground_truth`` (nav_msgs/Odometry) every step: the true pose and velocity in the same
  frame, the pose collisions and the LiDAR use. Equal to ``/odom`` under the ideal model; under a
  realism profile (:mod:`simbridge.sim.realism`) ``/odom`` and ``/tf`` are the encoders'
  estimate and drift from it, as a real robot's do;
* ``/tf_static``, latched: ``base_link -> laser`` from the LiDAR mount;
* ``/scan`` (sensor_msgs/LaserScan) at ``lidar.rate`` (each robot at its own phase of the scan
  period, as unsynchronised LiDARs are): frame ``laser``, ``angle_min = 0``,
  ``angle_increment = 2 pi / rays``, ``angle_max = angle_min + (rays - 1) * increment``;

and subscribes ``/cmd_vel`` (geometry_msgs/Twist, or TwistStamped with parameter
``robot.cmd_vel_stamped``: :mod:`simbridge.robot.cmdvel`). It serves ``/reset`` (std_srvs/Empty).

Named robots (``robots:`` in the world file, or spawned at run time) have the same topics under
their name (``/r1/odom``, frames ``r1/odom``, ``r1/base_link``, ``r1/laser``) on the shared
``/tf`` and ``/tf_static``, plus ``contact`` (``simbridge_msgs/msg/Contact``, each step in which
an obstacle stopped the robot; the start of each contact also goes to ``/rosout``). The
run-time services (spawn, kill, teleport) are in :mod:`simbridge.robot.fleet`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from simbridge.app.config import Params, world_params, world_spec
from simbridge.app.settings import SettingsError
from simbridge.errors import ProtocolError
from simbridge.graph.graph import Graph
from simbridge.graph.params import ParameterRefused, ParamNode
from simbridge.graph.rosapi import request_fields
from simbridge.graph.topics import Peer, Topic
from simbridge.robot.cmdvel import STARTUP_ONLY, cmd_vel_type, twist_of
from simbridge.robot.fleet import (
    CONTACT_TYPE,
    Elsewhere,
    add_robot_services,
    install_fleet,
    remove_robot_services,
)
from simbridge.sim import Robot, RobotState, World


__all__ = ["ROBOT_NODE", "RobotBridge"]

ROBOT_NODE = "/virtual_robot"
_ZERO36 = np.zeros(36, dtype=np.float64)
_EMPTY32 = np.zeros(0, dtype=np.float32)


def _stamp(sec: int, nanosec: int) -> dict[str, int]:
    return {"sec": sec, "nanosec": nanosec}


def _quaternion(yaw: float) -> dict[str, float]:
    return {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2.0), "w": math.cos(yaw / 2.0)}


def _rpy_quaternion(roll: float, pitch: float, yaw: float) -> dict[str, float]:
    """Fixed-axis roll, pitch, yaw (as tf2's ``setRPY``) as a quaternion."""
    cr, sr = math.cos(roll / 2.0), math.sin(roll / 2.0)
    cp, sp = math.cos(pitch / 2.0), math.sin(pitch / 2.0)
    cy, sy = math.cos(yaw / 2.0), math.sin(yaw / 2.0)
    return {
        "x": sr * cp * cy - cr * sp * sy,
        "y": cr * sp * cy + sr * cp * sy,
        "z": cr * cp * sy - sr * sp * cy,
        "w": cr * cp * cy + sr * sp * sy,
    }


def _odometry(stamp: dict[str, int], frame: str, child: str, s: RobotState) -> dict[str, Any]:
    """A nav_msgs/Odometry of pose and twist ``s``."""
    return {
        "header": {"stamp": stamp, "frame_id": frame},
        "child_frame_id": child,
        "pose": {
            "pose": {
                "position": {"x": s.x, "y": s.y, "z": 0.0},
                "orientation": _quaternion(s.theta),
            },
            "covariance": _ZERO36,
        },
        "twist": {
            "twist": {
                "linear": {"x": s.v, "y": 0.0, "z": 0.0},
                "angular": {"x": 0.0, "y": 0.0, "z": s.omega},
            },
            "covariance": _ZERO36,
        },
    }


@dataclass(eq=False, slots=True)
class _RobotTopics:
    robot: Robot
    odom: Topic
    scan: Topic
    cmd_vel: Topic
    #: The true pose (``/ground_truth``).
    truth: Topic
    #: Contacts of this robot (``simbridge_msgs/msg/Contact``).
    contact: Topic | None = None
    #: The ``/cmd_vel`` callback (to remove it with the robot).
    on_cmd_vel: Any = None
    #: Its place in the scan turns (robots take turns)...
    scan_turn: int = 0
    #: ...and where in the scan period its LiDAR fires, in [0, 1): ``_spread(scan_turn)``.
    scan_offset: float = 0.0


def _spread(k: int) -> float:
    """Return the ``k``-th point of the van der Corput sequence in base 2 (0, 1/2, 1/4, 3/4...).

    Robots' scan offsets: any number of robots fills the scan period evenly, each half of it
    holding half of them, whatever the ratio of LiDAR rate to step rate.
    """
    value, unit = 0.0, 0.5
    while k:
        if k & 1:
            value += unit
        k >>= 1
        unit /= 2.0
    return value


class RobotBridge:
    """Publishes the world's robots as ROS topics and feeds ``/cmd_vel`` into the world."""

    def __init__(self, graph: Graph, world: World) -> None:
        #: Where the topics live.
        self.graph = graph
        #: What is simulated.
        self.world = world
        #: The node that provides the robots' topics and services.
        self.node = ROBOT_NODE
        graph.nodes[ROBOT_NODE] = "the simulated robot"
        self.tf = graph.advertise("/tf", "tf2_msgs/msg/TFMessage", ROBOT_NODE)
        self.tf_static = graph.advertise(
            "/tf_static", "tf2_msgs/msg/TFMessage", ROBOT_NODE, latch=True
        )
        self.robots: dict[str, _RobotTopics] = {}
        #: Called with the name of each robot removed, after its topics are gone (extensions).
        self.on_robot_removed: list[Callable[[str], None]] = []
        #: Called with a robot's name after its topics are created (spawned robots too).
        self.on_robot_added: list[Callable[[str], None]] = []
        #: Where the current scan period is, in [0, 1) (None before the first step, which scans
        #: every robot; then each robot at its own offset in the period).
        self._scan_clock: float | None = None
        for robot in world.robots.values():
            self.add_robot(robot)
        graph.add_service("/reset", "std_srvs/srv/Empty", ROBOT_NODE, self._reset)
        self.params = ParamNode(
            ROBOT_NODE,
            read=lambda: world_params(self.world).flat(),
            write=self._write_params,
            descriptions=Params.describe(),
            bounds=Params.bounds(),
            read_only=STARTUP_ONLY,
        )
        self.params.on_change.append(self._params_changed)
        graph.params.add(self.params)
        #: Robots that were in contact at the previous step (a new contact is logged once).
        self._touching: set[str] = set()
        #: Who simulates robots in other processes of the classroom (the composition root adds
        #: the ROS 2 front end that sees them): their names are taken, the pages list them.
        self.elsewhere: list[Elsewhere] = []
        install_fleet(self)

    def _write_params(self, flat: dict[str, Any]) -> None:
        try:
            self.world.params = Params.from_flat(flat)
        except SettingsError as err:  # it names each refused parameter
            raise ParameterRefused(str(err)) from None

    def _params_changed(self, names: list[str]) -> None:
        self.graph.log("info", f"{ROBOT_NODE} parameters changed: {', '.join(names)}")
        if "lidar.mount" in names:
            self.publish_static(0.0)

    def add_robot(self, robot: Robot) -> None:
        """Create the topics of one robot."""
        g = self.graph

        def on_cmd_vel(msg: Any, source: Peer | None, name: str = robot.name) -> None:
            self._on_cmd_vel(name, msg)

        # all or nothing: a name a client holds with another type leaves no half-made robot
        made: list[str] = []

        def advertise(topic: str, type_name: str) -> Topic:
            made.append(robot.topic(topic))
            return g.advertise(robot.topic(topic), type_name, ROBOT_NODE)

        try:
            odom = advertise("odom", "nav_msgs/msg/Odometry")
            scan = advertise("scan", "sensor_msgs/msg/LaserScan")
            contact = advertise("contact", CONTACT_TYPE)
            truth = advertise("ground_truth", "nav_msgs/msg/Odometry")
            kind = cmd_vel_type(world_params(self.world))
            cmd_vel = g.subscribe(robot.topic("cmd_vel"), kind, ROBOT_NODE, on_cmd_vel)
        except ProtocolError as err:
            for name in made:
                g.topics.unadvertise(name, ROBOT_NODE)
            msg = f"{err} (a client holds that name; it must unadvertise it or disconnect)"
            raise ProtocolError(msg) from None
        # the first place no robot has: robots killed and spawned leave the turns even
        taken = {rt.scan_turn for rt in self.robots.values()}
        turn = next(k for k in range(len(taken) + 1) if k not in taken)
        self.robots[robot.name] = _RobotTopics(
            robot, odom, scan, cmd_vel, truth, contact, on_cmd_vel, turn, _spread(turn)
        )
        add_robot_services(self, robot)
        for callback in self.on_robot_added:
            callback(robot.name)

    def remove_robot(self, name: str) -> None:
        """Remove the topics and services of one robot (the world keeps its own list)."""
        rt = self.robots.pop(name)
        topics = self.graph.topics
        for topic in (rt.odom, rt.scan, rt.contact, rt.truth):
            if topic is not None:
                topics.unadvertise(topic.name, ROBOT_NODE)
        topics.unsubscribe_internal(rt.cmd_vel.name, rt.on_cmd_vel)
        remove_robot_services(self, rt.robot)
        self._touching.discard(name)
        for callback in self.on_robot_removed:
            callback(name)

    def _on_cmd_vel(self, name: str, msg: Any) -> None:
        twist = twist_of(msg)
        v = twist["linear"]["x"]
        omega = twist["angular"]["z"]
        try:
            self.world.command(name, v, omega)
        except ValueError as err:
            topic = self.robots[name].robot.topic("cmd_vel")
            text = f"{topic} refused: {err}; the robot keeps its previous command"
            raise ProtocolError(text) from None

    def _reset(self, args: Any) -> dict[str, Any]:
        request_fields(args, (), "/reset")
        self.world.reset()
        self.graph.log("info", "world reset: every robot back at its start pose, stopped")
        return {}

    # -- publishing ------------------------------------------------------------------------

    def publish_static(self, now: float) -> None:
        """Publish (latch) ``/tf_static``: robots' ``base_link -> laser``, the world's frames."""
        sec, nanosec = self.graph.stamp()
        mx, my, myaw = self.world.params.lidar.mount
        transforms = [
            {
                "header": {"stamp": _stamp(sec, nanosec), "frame_id": rt.robot.frame("base_link")},
                "child_frame_id": rt.robot.frame("laser"),
                "transform": {
                    "translation": {"x": mx, "y": my, "z": 0.0},
                    "rotation": _quaternion(myaw),
                },
            }
            for rt in self.robots.values()
        ]
        for frame in world_spec(self.world).frames:
            x, y, z, roll, pitch, yaw = frame.xyz_rpy()
            transforms.append(
                {
                    "header": {"stamp": _stamp(sec, nanosec), "frame_id": frame.parent},
                    "child_frame_id": frame.child,
                    "transform": {
                        "translation": {"x": x, "y": y, "z": z},
                        "rotation": _rpy_quaternion(roll, pitch, yaw),
                    },
                }
            )
        self.graph.publish(self.tf_static, {"transforms": transforms}, now)

    def publish(self, now: float) -> None:
        """Publish one step's messages: /odom and /tf always, /scan when one is due.

        /odom and /tf go first, so that their timing does not depend on how many scans are
        cast in the step: what holds messages back to send them together (the Zenoh link) sends
        them before the scans are cast (:meth:`TopicTable.flush`).
        """
        g = self.graph
        sec, nanosec = g.stamp()
        stamp = _stamp(sec, nanosec)
        tf = self.tf
        tf_wanted = tf.wanted()
        transforms = []
        for rt in self.robots.values():
            odom_wanted = rt.odom.wanted()
            robot = rt.robot
            if rt.truth.wanted():
                truth = _odometry(stamp, robot.frame("odom"), robot.frame("base_link"), robot.state)
                g.publish(rt.truth, truth, now)
            if not (odom_wanted or tf_wanted):
                continue  # nobody listens to this robot's pose: no message is built
            s = robot.state if robot.plant is None else robot.plant.odom
            odom_frame = robot.frame("odom")
            base = robot.frame("base_link")
            odom = _odometry(stamp, odom_frame, base, s)
            if odom_wanted:
                g.publish(rt.odom, odom, now)
            if tf_wanted:
                pose = odom["pose"]["pose"]
                transforms.append(
                    {
                        "header": {"stamp": stamp, "frame_id": odom_frame},
                        "child_frame_id": base,
                        "transform": {
                            "translation": pose["position"],
                            "rotation": pose["orientation"],
                        },
                    }
                )
        if tf_wanted:
            g.publish(tf, {"transforms": transforms}, now)
        self.publish_contacts(now, stamp)
        due = self._scans_due()
        if due:
            g.topics.flush()
            self.publish_scans(now, stamp, due)

    def _scans_due(self) -> list[_RobotTopics]:
        """Return the robots whose LiDAR fires this step (lidar.rate out of sim.rate steps).

        Each robot at its own offset in the scan period (like real LiDARs, which are not
        synchronised): with 300 robots at 10 Hz and 20 steps a second, 150 scans every step
        instead of 300 every other step, so that no step carries twice the work of the next
        (``bench.zenoh classroom``: the tail of the latency was in the steps that cast them all).
        """
        robots = list(self.robots.values())
        if self._scan_clock is None:
            self._scan_clock = 0.0
            return robots
        ratio = min(world_params(self.world).lidar.rate / self.world.params.sim.rate, 1.0)
        before = self._scan_clock + 1e-9
        after = before + ratio
        self._scan_clock = (self._scan_clock + ratio) % 1.0  # small: no rounding drift
        return [
            rt
            for rt in robots
            if math.floor(before + rt.scan_offset) != math.floor(after + rt.scan_offset)
        ]

    def publish_contacts(self, now: float, stamp: dict[str, int]) -> None:
        """Publish this step's contacts; log each new one to ``/rosout``."""
        touching = self.world.touching
        for name, other, c in self.world.contacts:
            rt = self.robots.get(name)
            if rt is None:
                continue
            if name not in self._touching:
                who = f"robot '{name}'" if name else "the robot"
                what = "a wall" if other == "wall" else f"robot '{other}'"
                self.graph.log(
                    "info",
                    f"{who} hit {what} at ({c.point[0]:.2f}, {c.point[1]:.2f}): "
                    "motion into it stopped",
                    name=ROBOT_NODE.lstrip("/"),
                )
            topic = rt.contact
            if topic is not None and topic.wanted():
                msg = {
                    "header": {"stamp": stamp, "frame_id": rt.robot.frame("odom")},
                    "robot": name,
                    "other": other,
                    "point": {"x": c.point[0], "y": c.point[1], "z": 0.0},
                    "normal": {"x": c.normal[0], "y": c.normal[1], "z": 0.0},
                }
                self.graph.publish(topic, msg, now)
        self._touching = set(touching)

    def publish_scans(self, now: float, stamp: dict[str, int], robots: list[_RobotTopics]) -> None:
        """Raycast and publish the /scan of ``robots``, of those listened to, in one batch."""
        lidar = world_params(self.world).lidar
        increment = 2.0 * math.pi / lidar.rays
        wanted = [rt for rt in robots if rt.scan.wanted()]
        if not wanted:
            return
        all_ranges = self.world.scans([rt.robot.name for rt in wanted])
        for rt, ranges in zip(wanted, all_ranges, strict=True):
            scan = {
                "header": {"stamp": stamp, "frame_id": rt.robot.frame("laser")},
                "angle_min": 0.0,
                "angle_max": (lidar.rays - 1) * increment,
                "angle_increment": increment,
                "time_increment": 0.0,
                "scan_time": 1.0 / lidar.rate,
                "range_min": lidar.range_min,
                "range_max": lidar.range_max,
                "ranges": ranges,
                "intensities": _EMPTY32,
            }
            self.graph.publish(rt.scan, scan, now)
