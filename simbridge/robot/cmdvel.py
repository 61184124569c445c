"""The velocity-command topic's type: ``geometry_msgs/msg/Twist`` or ``TwistStamped``.

Newer ROS 2 stacks (ros2_control's ``diff_drive_controller`` since Jazzy) expect
``TwistStamped`` on ``cmd_vel``. Parameter ``robot.cmd_vel_stamped`` (default false) gives the
simulated robots' ``cmd_vel`` that type, so a page or node written for such a robot works on
the simulation unchanged. The robot then reads ``msg.twist``; the header is not used.

The parameter is read at startup only: a topic's type is fixed by its first typed user
(rosbridge's TypeConflictException) and clients hold publishers and subscriptions of the old
type, so it is read-only at run time (see :data:`STARTUP_ONLY`); change it in the parameter
file and restart.
"""

from __future__ import annotations

from typing import Any

from simbridge.app.config import Params


__all__ = [
    "STAMPED_PARAM",
    "STARTUP_ONLY",
    "TWIST",
    "TWIST_STAMPED",
    "cmd_vel_type",
    "command_type",
    "convert_twist",
    "twist_of",
]

TWIST = "geometry_msgs/msg/Twist"
TWIST_STAMPED = "geometry_msgs/msg/TwistStamped"
#: The dotted parameter name.
STAMPED_PARAM = "robot.cmd_vel_stamped"
#: Parameters of ``/virtual_robot`` that cannot change at run time.
STARTUP_ONLY = frozenset({STAMPED_PARAM})
#: Whether each spelling of the two types is the stamped one.
_KINDS = {
    TWIST: False,
    TWIST_STAMPED: True,
    "geometry_msgs/Twist": False,
    "geometry_msgs/TwistStamped": True,
}


def cmd_vel_type(params: Params) -> str:
    """Return the type of the robots' ``cmd_vel`` topics under ``params``."""
    return TWIST_STAMPED if params.robot.cmd_vel_stamped else TWIST


def command_type(recorded: str, target: str | None) -> str:
    """Return the type to send a ``recorded`` command as to a topic of type ``target``.

    ``target`` when both are Twist or TwistStamped (the command is converted), else
    ``recorded`` (unknown target, or other types: sent as they are).
    """
    if target and recorded in _KINDS and target in _KINDS:
        return target
    return recorded


def twist_of(msg: Any) -> Any:
    """Return the Twist part of a Twist or TwistStamped message (a dict with ROS field names)."""
    if isinstance(msg, dict) and "twist" in msg:
        return msg["twist"]
    return msg


def convert_twist(
    msg: Any, from_type: str, to_type: str, stamp: tuple[int, int], frame_id: str = "base_link"
) -> Any:
    """Return ``msg`` (of ``from_type``) as a message of ``to_type``.

    Twist <-> TwistStamped: the Twist part is kept; a new header gets ``stamp`` (sec,
    nanosec) and ``frame_id``. Any other pair of types is returned unchanged.
    """
    if from_type not in _KINDS or to_type not in _KINDS:
        return msg
    if _KINDS[from_type] == _KINDS[to_type]:
        return msg
    twist = twist_of(msg)
    if not _KINDS[to_type]:
        return twist
    sec, nanosec = stamp
    header = {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": frame_id}
    return {"header": header, "twist": twist}
