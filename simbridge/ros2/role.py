"""Who the ROS 2 peers are: the access of what reaches the graph from Zenoh or DDS.

A ROS 2 node shows no credential: every peer of one transport is admitted as one peer whose
:class:`~simbridge.graph.access.Access` the instructor chooses with ``--ros2-role``.
"""

from __future__ import annotations

from simbridge.app.settings import ServerSettings
from simbridge.graph.access import ANY_SCOPE, NO_ROBOT


__all__ = ["ros2_access"]


def ros2_access(settings: ServerSettings) -> tuple[str, bool]:
    """Return ``(scope, admin)`` of ROS 2 peers (what reaches the graph from Zenoh or DDS).

    ``ros2_role`` decides: ``none`` (:data:`NO_ROBOT`: it reads, drives nothing),
    ``robot:NAME``, ``robots`` (every robot, no administration), ``admin``. Unset: what a
    client without a token gets, except in class mode (client tokens or a rosauth secret),
    where it is ``none``: a peer that shows no credential is no student's and no instructor's.
    """
    role = settings.ros2_role
    if role is None:
        if settings.auth_required:
            return NO_ROBOT, False
        return ANY_SCOPE, settings.admin_token is None
    if role == "admin":
        return ANY_SCOPE, True
    if role == "robots":
        return ANY_SCOPE, False
    if role.startswith("robot:"):
        return role.removeprefix("robot:"), False
    return NO_ROBOT, False
