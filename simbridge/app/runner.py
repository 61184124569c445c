"""The simbridge process: the fixed-rate simulation loop, the servers, start and stop.

The loop runs on absolute deadlines ``start + k * dt`` of the monotonic clock, so it does not
drift however long it runs: a late tick does not push the later ones back. If the process falls
more than :data:`MAX_CATCH_UP` ticks behind (a suspended laptop, a stalled Pi), it skips ahead
instead of bursting, and counts the skipped ticks.
"""

from __future__ import annotations

import asyncio
import contextlib
import ipaddress
import logging
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from simbridge import __version__
from simbridge.app.build import build, offload
from simbridge.app.config import Params, WorldSpec, world_spec
from simbridge.app.settings import ServerSettings
from simbridge.rosbridge.server import tls_context
from simbridge.web import serve_http
from simbridge.web.pool import Pool


if TYPE_CHECKING:
    from simbridge.ros2.dds.options import DdsOptions
    from simbridge.ros2.zenoh.config import ZenohOptions


__all__ = ["MAX_CATCH_UP", "App", "LoopStats", "offload"]

logger = logging.getLogger(__name__)

#: Ticks the loop may run back to back to catch up before it skips ahead.
MAX_CATCH_UP = 5


def _loopback(host: str) -> bool:
    if host in ("localhost", ""):
        return host == "localhost"
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


#: The part of a period a simulator's tick moves by at most per tick towards its turn.
TURN_STEP = 0.1
#: Seconds off its turn a simulator's tick is left alone.
TURN_TOLERANCE = 0.0001


def _turn_shift(share: tuple[int, int], dt: float, wall: float) -> float:
    """Return the seconds to move the next tick by, towards this simulator's turn.

    ``share``: this simulator's rank among ``n`` simulators; its ticks fall ``rank / n`` of the
    period after each multiple of the period in wall-clock time (``wall``: the next tick's
    wall-clock time), so the simulators of one machine take turns. At most a tenth of the
    period a tick, either way (a simulator joining or leaving moves the others' ticks over a
    few ticks: no gap between two ticks longer than 1.1 periods); none under 0.1 ms.
    """
    rank, count = share
    error = (rank / count * dt - wall + dt / 2.0) % dt - dt / 2.0
    if abs(error) < TURN_TOLERANCE:
        return 0.0
    return max(-dt * TURN_STEP, min(dt * TURN_STEP, error))


def _percentile(values: list[float], q: float) -> float:
    if not values:
        return 0.0
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


@dataclass(slots=True)
class LoopStats:
    """Timing of the simulation loop (the last minute of ticks kept for percentiles)."""

    ticks: int = 0
    late_ticks: int = 0
    skipped_ticks: int = 0
    #: Seconds past its deadline at which each tick started.
    lateness: deque[float] = field(default_factory=lambda: deque(maxlen=1200))
    #: Seconds each tick's work took (step, publish, encode, write).
    work: deque[float] = field(default_factory=lambda: deque(maxlen=1200))

    def summary(self) -> dict[str, Any]:
        """Return the figures for ``/healthz`` (milliseconds)."""
        late = list(self.lateness)
        work = list(self.work)
        return {
            "ticks": self.ticks,
            "late_ticks": self.late_ticks,
            "skipped_ticks": self.skipped_ticks,
            "lateness_ms_p50": round(_percentile(late, 0.5) * 1000, 3),
            "lateness_ms_p99": round(_percentile(late, 0.99) * 1000, 3),
            "lateness_ms_max": round(max(late, default=0.0) * 1000, 3),
            "work_ms_p50": round(_percentile(work, 0.5) * 1000, 3),
            "work_ms_p99": round(_percentile(work, 0.99) * 1000, 3),
            "work_ms_max": round(max(work, default=0.0) * 1000, 3),
        }


class App:
    """One simbridge process: world, graph, servers and the loop.

    The parts are made by :func:`simbridge.app.build.build` (the order and what is wired to
    what are there); the App starts and stops them and runs the loop.
    """

    def __init__(
        self,
        settings: ServerSettings | None = None,
        *,
        world: WorldSpec | Path | str | None = None,
        params: Params | Path | str | None = None,
        static_dir: Path | None = None,
        seed: int = 0,
        zenoh: ZenohOptions | None = None,
        no_sim: bool = False,
        dds: DdsOptions | None = None,
        record: tuple[Path | str, Sequence[str] | None] | None = None,
        run_bags: bool = False,
    ) -> None:
        #: Network settings.
        self.settings = settings or ServerSettings()
        #: ``--no-sim``: the bridge alone (no robot, no /clock, /reset...; with ``--zenoh``, a
        #: rosbridge in front of the ROS 2 graph).
        self.no_sim = no_sim
        parts = build(
            self.settings,
            health=lambda: self.health(),
            world=world,
            params=params,
            static_dir=static_dir,
            seed=seed,
            no_sim=no_sim,
            zenoh=zenoh,
            dds=dds,
            record=record,
            run_bags=run_bags,
        )
        core = parts.core
        #: The simulation.
        self.world = core.world
        #: The robot world's ROS graph (the same as the headless API's).
        self.robot = core.robot
        #: The ROS graph.
        self.graph = core.graph
        #: The virtual robot's ROS interface.
        self.bridge = self.robot.bridge
        #: Sim time: /clock, pause, single step, real-time factor, sim-time stamps.
        self.simclock = self.robot.simclock
        #: The latching emergency stop (/estop, /estop/reset, /estop/state).
        self.estop = self.robot.estop
        #: The walls as a latched /walls marker, for pages and tools.
        self.walls = self.robot.walls
        #: tf2_web_republisher for web TF clients (/republish_tfs, /tf2_web_republisher).
        self.tf_republisher = self.robot.tf_republisher
        #: The robots' safety watchdog (docs/security.md).
        self.safety = self.robot.safety
        #: The ROS tutorial nodes (``--demo-nodes`` or ``demo_nodes: true``), else None.
        self.tutorials = self.robot.tutorials
        #: What each connection may do (/simbridge/access), for pages.
        self.roles = self.robot.roles
        #: The tick: step, publish, timeouts, then the hooks in order.
        self.steps = core.steps
        #: The hooks run after each tick's publishing, with ``now``, in order (the one list of
        #: :attr:`steps`; an extension may add its own).
        self.tick_hooks = self.steps.hooks
        #: HTTP answers (page, /healthz).
        self.web = parts.web
        #: Access control: who each peer of every front end is (docs/security.md).
        self.guard = parts.guard
        #: The rosbridge clients: their sessions, budgets and ops.
        self.rosbridge = parts.rosbridge
        #: The WebSocket server.
        self.server = parts.server
        #: The grader: task runs scored on the true pose, the class's results (/admin).
        self.grader = core.grader
        #: ``--record DIR``: the graph's topics into a bag, or None.
        self.recorder = parts.recorder
        #: The ROS 2 graph through Zenoh (``--zenoh``), or None.
        self.zenoh = parts.zenoh
        #: The ROS 2 graph through DDS (``--dds``), or None.
        self.dds = parts.dds
        #: The Foxglove WebSocket protocol (``--foxglove-port``), or None.
        self.foxglove = parts.foxglove
        #: Loop timing.
        self.stats = LoopStats()
        self._http: asyncio.Server | None = None
        #: The HTTP port's connections and their budgets (``/healthz`` ``http``).
        self.http_pool = Pool(
            self.settings.max_http_connections, self.settings.max_http_connections_per_address
        )
        self._loop_task: asyncio.Task[None] | None = None
        self._started = time.monotonic()
        #: Set once the servers listen and the loop runs.
        self.ready = asyncio.Event()
        if self.settings.admin_token is None and not _loopback(self.settings.host):
            logger.warning(
                "no admin token: anyone who can reach %s may reset the world and change "
                "parameters (set --admin-token or SIMBRIDGE_ADMIN_TOKEN)",
                self.settings.host,
            )

    # -- facts ----------------------------------------------------------------------------

    @property
    def ws_port(self) -> int:
        """Bound WebSocket port."""
        return self.server.port

    @property
    def http_port(self) -> int | None:
        """Bound HTTP port, or None when HTTP is off."""
        if self._http is None:
            return None
        return int(self._http.sockets[0].getsockname()[1])

    def health(self) -> dict[str, Any]:
        """Return the ``/healthz`` document."""
        return {
            "status": "ok",
            "version": __version__,
            "uptime_s": round(time.monotonic() - self._started, 3),
            "world": world_spec(self.world).name,
            "sim_time_s": round(self.world.time, 3),
            "loop_rate_hz": self.world.params.sim.rate,
            **self.server.stats(),
            "loop": {**self.stats.summary(), "failures": self.steps.failures},
            **({"http": self.http_pool.stats()} if self._http is not None else {}),
            **({"zenoh": self.zenoh.health()} if self.zenoh is not None else {}),
            **({"dds": self.dds.health()} if self.dds is not None else {}),
            **({"foxglove": self.foxglove.health()} if self.foxglove is not None else {}),
        }

    # -- lifecycle --------------------------------------------------------------------------

    async def start(self) -> None:
        """Start the servers and the simulation loop."""
        await self.server.start()
        s = self.settings
        if s.http_port is not None:
            tls = tls_context(s.certfile, s.keyfile) if s.certfile else None
            self._http = await serve_http(
                self.web, s.host, s.http_port, ssl=tls, pool=self.http_pool
            )
        if self.recorder is not None:  # the bag, once the ports listen
            self.recorder.start()
        loop = asyncio.get_running_loop()
        if not self.no_sim:
            self.robot.publish_static(loop.time())
        self._loop_task = asyncio.create_task(self._run_loop(), name="simulation")
        if self.zenoh is not None:
            await self.zenoh.start()
        if self.dds is not None:
            await self.dds.start()
        if self.foxglove is not None:
            await self.foxglove.start()
        self.graph.log(
            "info", f"simbridge {__version__} started: world '{world_spec(self.world).name}'"
        )
        self.ready.set()

    async def stop(self) -> None:
        """Stop the loop, close every connection and the servers."""
        if self._loop_task is not None:
            self._loop_task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._loop_task
        self.grader.close()  # runs in progress are recorded as interrupted
        if self.zenoh is not None:
            await self.zenoh.close()
        if self.dds is not None:
            await self.dds.close()
        if self.foxglove is not None:
            await self.foxglove.close()
        if self._http is not None:
            self._http.close()
            await self._http.wait_closed()
        await self.server.close()
        if self.recorder is not None:
            self.recorder.close()

    async def _run_loop(self) -> None:
        loop = asyncio.get_running_loop()
        clock = loop.time
        start = clock()
        k = 0
        period = self.world.dt
        while True:
            # one step per period of wall time: dt / real-time factor; a new period (factor or
            # sim.rate changed) restarts the deadlines from the last one
            simclock = self.simclock
            dt = self.world.dt / (simclock.real_time_factor if simclock is not None else 1.0)
            if dt != period:
                start, k, period = start + k * period, 0, dt
            k += 1
            deadline = start + k * dt
            share = self.zenoh.tick_share if self.zenoh is not None else None
            if share is not None:  # this simulator's turn (see ZenohLink.tick_share)
                shift = _turn_shift(share, dt, time.time() + deadline - clock())
                start, deadline = start + shift, deadline + shift
            delay = deadline - clock()
            if delay > 0:
                await asyncio.sleep(delay)
            now = clock()
            late = now - deadline
            # the catch-up allowance is in sim steps of wall time, whatever the speed-up
            if late > MAX_CATCH_UP * self.world.dt:
                skipped = int(late / dt)
                self.stats.skipped_ticks += skipped
                start += skipped * dt  # skip ahead: no burst of catch-up ticks
                logger.warning(
                    "simulation loop %.0f ms late: skipping %d ticks", late * 1e3, skipped
                )
            elif late > dt:
                self.stats.late_ticks += 1
            try:
                self.tick(now)
            except Exception:
                logger.exception("simulation tick failed")
            self.stats.ticks += 1
            self.stats.lateness.append(max(late, 0.0))
            self.stats.work.append(clock() - now)
            if delay <= 0:
                await asyncio.sleep(0)  # let clients run even when the loop is behind

    def tick(self, now: float) -> None:
        """Run one tick of :attr:`steps`: step and publish (unless paused), timeouts, hooks."""
        self.steps.tick(now)
