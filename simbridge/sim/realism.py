"""The sim-to-real gap: a robot that moves as the real one does, and odometry from its encoders.

Under a realism profile (:class:`~simbridge.sim.parameters.RealismLike`, ``enabled``) a robot has
two poses: the *truth* (:attr:`Robot.state <simbridge.sim.world.Robot.state>`, which collisions
and the LiDAR use, published on ``/ground_truth``) and its *odometry* (:attr:`Plant.odom`,
published on ``/odom`` and ``/tf``), integrated from its encoders with the nominal geometry
``robot.wheel_radius`` ``r`` and ``robot.wheelbase`` ``b``, as the real robot's driver does.

Per step ``dt``, from the command ``(v, omega)`` (clamped to the limits)::

    command in effect at t:   the last one that arrived at or before t - cmd_latency
    wheel targets:            u_r = v + omega b/2,  u_l = v - omega b/2     (the driver's b)
    deadband:                 |u_i| < deadband  ->  u_i = 0
    scale:                    u_i *= wheel_speed_scale
    motor lag (first order):  du_i/dt = (u_i - w_i) / motor_time_constant   (exact exponential
                              over each piece of the step between command changes)

``w_i`` is each wheel's rim speed as its encoder sees it (rotation times ``r``); over a step
each wheel turns ``s_i = integral of w_i``. The ground moves under the wheel by::

    g_i = s_i * (R_i / r) * (1 - slip_i)        slip_i = clip(slip + N(0, slip_stddev), 0, 1)

with ``R_i`` the true radius (``wheel_radius_left``/``right``, 0 = nominal) and ``slip`` the
floor patch's own where the robot stands on one (a rug). The truth then moves by
``ds = (g_r + g_l) / 2`` along its heading and turns by ``(g_r - g_l) / B`` (``B`` the true
``wheelbase``); the odometry by the same equations from the encoder counts
(``encoder_ticks`` per revolution: whole ticks only; 0 = exact ``s_i``) and ``r``, ``b``:
the systematic errors of Borenstein's UMBmark square test, and slip it cannot see.

With every value at its default the equations reduce to the kinematic model
(:mod:`simbridge.sim.kinematics`): ``/odom`` is the truth. The draws come from the plant's own
generator, seeded from ``realism.seed`` and the robot's name: the same seed and the same
commands give the same run.
"""

from __future__ import annotations

import math
import zlib
from collections import deque
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from simbridge.sim.kinematics import RobotState, clamp_command, wrap_angle
from simbridge.sim.parameters import RealismLike, RobotLike


if TYPE_CHECKING:
    from collections.abc import Sequence

    from simbridge.sim.parameters import FloorPatchLike


__all__ = ["Floor", "Plant"]

#: Commands waiting for their latency at most (one per step at 1 kHz for 2 s is 2000).
MAX_PENDING = 4096


class Floor:
    """The floor patches of a world: where a robot's slip is the patch's own."""

    def __init__(self, patches: Sequence[FloorPatchLike]) -> None:
        self.patches = [
            (np.array(p.polygon, dtype=np.float64).reshape(-1, 2), p.slip) for p in patches
        ]

    def slip_at(self, x: float, y: float, default: float) -> float:
        """Return the slip of the first patch that holds ``(x, y)``, else ``default``."""
        for poly, slip in self.patches:
            if _inside(poly, x, y):
                return slip
        return default


def _inside(poly: npt.NDArray[np.float64], x: float, y: float) -> bool:
    """Whether ``(x, y)`` is inside the polygon (even-odd rule)."""
    xs, ys = poly[:, 0], poly[:, 1]
    xj, yj = np.roll(xs, 1), np.roll(ys, 1)
    crosses = (ys > y) != (yj > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        at = (xj - xs) * (y - ys) / (yj - ys) + xs
    return bool(np.count_nonzero(crosses & (x < at)) % 2)


class Plant:
    """One robot's motors, wheels and encoders under a realism profile (module doc)."""

    def __init__(self, name: str, state: RobotState, seed: int) -> None:
        #: The odometry pose and twist (what ``/odom`` and ``/tf`` publish).
        self.odom = RobotState(x=state.x, y=state.y, theta=state.theta)
        #: Each wheel's rim speed (right, left), m/s: what the motor lag holds.
        self.wheel = [0.0, 0.0]
        #: Commands waiting for the latency: (time it takes effect, v, omega).
        self.pending: deque[tuple[float, float, float]] = deque()
        #: The command in effect (not clamped: limits may change).
        self.cmd = (0.0, 0.0)
        #: Wheel rotation so far (rad, right and left) and the encoder counts last read.
        self.angle = [0.0, 0.0]
        self.counts = [0, 0]
        self._name = name
        self._seed = seed
        self._rng: np.random.Generator | None = None

    @property
    def rng(self) -> np.random.Generator:
        """The slip draws' generator: ``realism.seed`` and the robot's name (made on first use)."""
        if self._rng is None:
            self._rng = np.random.default_rng([self._seed, zlib.crc32(self._name.encode())])
        return self._rng

    def place(self, state: RobotState) -> None:
        """Start again at the truth's pose (a reset, a teleport): stopped, nothing pending."""
        self.odom = RobotState(x=state.x, y=state.y, theta=state.theta)
        self.wheel = [0.0, 0.0]
        self.pending.clear()
        self.cmd = (0.0, 0.0)
        self.angle = [0.0, 0.0]
        self.counts = [0, 0]
        self._rng = None

    def halt(self) -> None:
        """Stop at once (an emergency stop): wheels still, no command in effect or pending."""
        self.wheel = [0.0, 0.0]
        self.pending.clear()
        self.cmd = (0.0, 0.0)
        self.odom.v = self.odom.omega = 0.0

    def command(self, now: float, v: float, omega: float, real: RealismLike) -> None:
        """Take a command that arrived at sim time ``now``: in effect at ``now + cmd_latency``."""
        if real.cmd_latency <= 0.0:
            self.pending.clear()
            self.cmd = (v, omega)
            return
        if len(self.pending) >= MAX_PENDING:
            self.pending.popleft()  # a flood of commands: the oldest waiting one is dropped
        self.pending.append((now + real.cmd_latency, v, omega))

    def step(
        self,
        state: RobotState,
        t0: float,
        dt: float,
        limits: RobotLike,
        real: RealismLike,
        slip: float,
    ) -> None:
        """Advance the truth ``state`` and :attr:`odom` over ``[t0, t0 + dt]``.

        ``slip`` is the mean slip where the robot stands (``realism.slip`` or its patch's).
        """
        r, b = limits.wheel_radius, limits.wheelbase
        half_b = b / 2.0
        tau, band, scale = real.motor_time_constant, real.deadband, real.wheel_speed_scale
        max_v, max_omega = limits.max_linear_velocity, limits.max_angular_velocity
        pending = self.pending
        wheel = self.wheel
        travel = [0.0, 0.0]
        t, end = t0, t0 + dt
        while True:
            while pending and pending[0][0] <= t + 1e-12:
                _, pv, pw = pending.popleft()
                self.cmd = (pv, pw)
            upto = min(end, pending[0][0]) if pending else end
            h = upto - t
            if h > 0.0:
                v, omega = clamp_command(self.cmd[0], self.cmd[1], max_v, max_omega)
                for i, u in enumerate((v + omega * half_b, v - omega * half_b)):
                    target = 0.0 if abs(u) < band else u * scale
                    if tau > 0.0:
                        decay = math.exp(-h / tau)
                        travel[i] += target * h + (wheel[i] - target) * tau * (1.0 - decay)
                        wheel[i] = target + (wheel[i] - target) * decay
                    else:
                        travel[i] += target * h
                        wheel[i] = target
            t = upto
            if upto >= end:
                break
        # the ground under each wheel: true radius, slip
        radii = (real.wheel_radius_right or r, real.wheel_radius_left or r)
        lost = [slip, slip]
        if real.slip_stddev > 0.0:
            draws = self.rng.standard_normal(2)
            lost = [slip + real.slip_stddev * float(d) for d in draws]
        ground = [travel[i] * (radii[i] / r) * (1.0 - min(1.0, max(0.0, lost[i]))) for i in (0, 1)]
        _move(state, ground[0], ground[1], real.wheelbase or b, dt)
        # the encoders: the wheels' rotation, in whole ticks when they have ticks
        ticks = real.encoder_ticks
        seen = travel
        if ticks:
            per_tick = 2.0 * math.pi / ticks
            seen = [0.0, 0.0]
            for i in (0, 1):
                self.angle[i] += travel[i] / r
                count = math.floor(self.angle[i] / per_tick + 1e-9)
                seen[i] = (count - self.counts[i]) * per_tick * r
                self.counts[i] = count
        _move(self.odom, seen[0], seen[1], b, dt)


def _move(state: RobotState, right: float, left: float, wheelbase: float, dt: float) -> None:
    """Move ``state`` by wheel travels ``right``, ``left`` (m) in ``dt``: explicit Euler."""
    ds = (right + left) / 2.0
    turn = (right - left) / wheelbase
    state.x += ds * math.cos(state.theta)
    state.y += ds * math.sin(state.theta)
    state.theta = wrap_angle(state.theta + turn)
    state.v = ds / dt
    state.omega = turn / dt
