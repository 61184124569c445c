"""The simulator: walls, differential-drive robots, LiDAR raycasts.

numpy only, no I/O and no clock: deterministic given a seed and the sequence of steps.
"""

from __future__ import annotations

from simbridge.sim.dynamics import DynamicModel
from simbridge.sim.kinematics import RobotState, clamp_command, integrate, wrap_angle
from simbridge.sim.lidar import beam_angles, raycast, segments_array
from simbridge.sim.world import KinematicModel, MotionModel, Robot, World


__all__ = [
    "DynamicModel",
    "KinematicModel",
    "MotionModel",
    "Robot",
    "RobotState",
    "World",
    "beam_angles",
    "clamp_command",
    "integrate",
    "raycast",
    "segments_array",
    "wrap_angle",
]
