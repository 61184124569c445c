"""The grader: a node of the graph that runs a task on a robot and scores it on the true pose.

Services of node ``/simbridge_grader`` (type ``simbridge_msgs/srv/Grade``: request ``task``,
``robot``, ``attempt``, ``task_yaml``; response ``success`` and ``message``, a JSON document),
the one way in for the page, ``simbridge grade`` and any client:

=============================  =================================================================
service                        what it does
=============================  =================================================================
``/simbridge/grade/tasks``     the tasks the instructor published (an administrator: every
                               task, with ``published``)
``/simbridge/grade/start``     run ``task`` (a published task's id; or ``task_yaml``, a task
                               file's text) on ``robot``; answers the attempt id at once
``/simbridge/grade/status``    the state of ``attempt`` (or of ``robot``'s latest): ``waiting``
                               for the controller, ``running`` (seconds so far), or its report
``/simbridge/grade/results``   the caller's attempts (an administrator: everyone's)
``/simbridge/grade/cancel``    end ``robot``'s run now (recorded as ``cancelled``)
=============================  =================================================================

A run: the robot is put at the task's start pose, stopped, with the task's robot parameters;
the grader waits for the controller's first non-zero ``/cmd_vel`` (whoever sends it: the page,
roslibjs, roslibpy, a ROS 2 node), then samples the robot's **true pose** after every step
(a client's own ``/odom`` cannot change its score) and records the robot's topics into a
rosbag2 MCAP bag (as ``simbridge record`` writes them). At the time limit the robot is
stopped, its parameters restored, the run scored (:mod:`simbridge.grading.metrics`) and the
report appended to the results journal (:mod:`simbridge.grading.results`).

Admission, as the e-stop's: a connection scoped to a robot (a student's token) may start runs
on that robot only and read only that robot's attempts; one run per robot at a time. A task
sent as text is run like any other but is *official* (it counts on ``/admin`` as the published
task's) only when it asks exactly what the published task of that id asks.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import orjson

from simbridge.app.config import world_spec
from simbridge.app.settings import SettingsError
from simbridge.errors import ConfigError, ServiceError, SimbridgeError
from simbridge.grading.metrics import Trace, clearance, evaluate, resolve_goal, score, thresholds
from simbridge.grading.report import response_svg
from simbridge.grading.results import ResultsLog
from simbridge.grading.task import Goal, Task, parse_task
from simbridge.graph.graph import Graph
from simbridge.graph.rosapi import request_fields
from simbridge.graph.services import caller
from simbridge.graph.topics import Peer
from simbridge.robot.cmdvel import twist_of
from simbridge.robot.estop import connection_rights, describe_peer
from simbridge.sim import World
from simbridge.sim.parameters import RealismLike, RobotLike
from simbridge.sim.world import PER_ROBOT_PARAMS, Robot


__all__ = ["GRADE_TYPE", "Grader", "Run", "apply_robot_params", "restore_robot"]

logger = logging.getLogger(__name__)

#: Robot parameters that limit how fast a robot goes: a task sent as text by a client without
#: admin rights may lower them, never raise them (see :meth:`Grader._may_set`).
RAISABLE_LIMITS = frozenset(
    {"max_linear_velocity", "max_angular_velocity", "max_wheel_torque", "velocity_gain"}
)
#: The grader's service type: one shape for every grade service (unused fields empty); its
#: definition is in :data:`simbridge.msgs.interfaces.SERVICES`.
GRADE_TYPE = "simbridge_msgs/srv/Grade"
NODE = "/simbridge_grader"
PREFIX = "/simbridge/grade"
#: Points of a stored response (a run's steps are thinned to this many: an attempt is kept in
#: memory and in the results file with them, about 15 kB; the run's bag has every step).
MAX_POINTS = 250
#: Attempts one robot may have in the results by default (the budget of what a student can
#: make the server keep; ServerSettings.grading_max_attempts).
MAX_ATTEMPTS = 200
#: Attempts one results call answers (the newest).
MAX_LISTED = 500

Phase = Literal["waiting", "running"]


def apply_robot_params(world: World, robot: str, params: dict[str, Any]) -> None:
    """Give ``robot`` the task's parameters (dotted names), all or nothing per section.

    ``robot.*``: the per-robot parameters (:data:`PER_ROBOT_PARAMS`, the bonus task's heavier
    robot); ``realism.*``: the robot's own realism profile (``realism.enabled: true``,
    ``realism.slip``...). Anything else is refused with the reason.

    Raises:
        ValueError: a parameter is unknown, shared by every robot, or out of range.
    """
    own: dict[str, Any] = {}
    realism: dict[str, Any] = {}
    for key, value in params.items():
        section, _, name = key.partition(".")
        if section == "robot" and name in PER_ROBOT_PARAMS:
            own[name] = value
        elif section == "realism":
            realism[name] = value
        else:
            allowed = ", ".join(f"robot.{n}" for n in sorted(PER_ROBOT_PARAMS))
            msg = f"robot_params.{key}: not a parameter one robot may have ({allowed}, realism.*)"
            raise ValueError(msg)
    if own:
        world.set_robot_params(robot, own)
    if realism:
        world.set_robot_realism(robot, realism)


def restore_robot(body: Robot, overrides: dict[str, float], realism: dict[str, object]) -> None:
    """Give ``body`` back its own parameters of before a run, and a robot's fresh motors.

    A run's ``realism.*`` values drove the robot's plant (:class:`~simbridge.sim.realism.Plant`:
    its wheels' speeds, the commands waiting for the run's latency, its slip generator seeded
    by the run's ``realism.seed``, its odometry's drift): it is dropped when the profile
    changes back, and the robot's next step makes a new one at its true pose, as it would for
    a robot that never had the run.
    """
    changed = body.realism_own != realism
    body.overrides, body.cached = dict(overrides), None
    body.realism_own, body.realism_cached = dict(realism), None
    if changed:
        body.plant = None


def _thin(values: list[Any]) -> list[Any]:
    step = max(1, math.ceil(len(values) / MAX_POINTS))
    out = values[::step]
    if values and out[-1] is not values[-1]:
        out.append(values[-1])
    return out


@dataclass(eq=False)
class Run:
    """One attempt in progress."""

    attempt: str
    task: Task
    goal: Goal
    robot: str
    #: The robot run (a robot killed and spawned again under its name is another one).
    body: Robot
    student: str
    client: str
    official: bool
    start: tuple[float, float, float]
    saved: dict[str, float]
    saved_realism: dict[str, object]
    started: float
    phase: Phase = "waiting"
    #: Sim seconds waited for the controller, and run since its first command.
    waited: float = 0.0
    elapsed: float = 0.0
    trace: Trace = field(default_factory=Trace)
    bag: Any = None
    bag_path: str | None = None
    subscriptions: list[tuple[str, Callable[[Any, object], None]]] = field(default_factory=list)

    def state(self) -> dict[str, Any]:
        """The run as the status service shows it."""
        return {
            "attempt": self.attempt,
            "task_id": self.task.id,
            "robot": self.robot,
            "status": self.phase,
            "elapsed_s": round(self.elapsed, 2),
            "waited_s": round(self.waited, 2),
            "time_limit": self.task.time_limit,
            "wait_for_controller": self.task.wait_for_controller,
            "start": list(self.start),
            "goal": self.goal.as_dict(),
        }


class Grader:
    """Installs the grade services on ``graph``; :meth:`tick` after every loop tick.

    Args:
        graph: the ROS graph.
        world: whose robots are graded.
        results: where attempts and published tasks are kept.
        tasks: the instructor's tasks by id, or a function reading them (called when they are
            first needed: a server nobody grades on never reads a task file).
        bags: directory of the runs' bags (one per attempt); None: runs are not recorded.
        recorder: makes the bag of a run at a path (``BagWriter(path, registry)``: the tools
            record, the graph's nodes do not import them); None: runs are not recorded.
        clock: wall-clock seconds (Unix time).
    """

    def __init__(
        self,
        graph: Graph,
        world: World,
        results: ResultsLog,
        tasks: dict[str, Task] | Callable[[], dict[str, Task]],
        *,
        bags: Path | None = None,
        recorder: Callable[[Path], Any] | None = None,
        max_attempts: int = MAX_ATTEMPTS,
        clock: Callable[[], float] = time.time,
    ) -> None:
        self.graph = graph
        self.world = world
        self.results = results
        self._tasks_source = tasks
        self._tasks_loaded: dict[str, Task] | None = tasks if isinstance(tasks, dict) else None
        self.bags = bags
        self.max_attempts = max_attempts
        #: Makes a run's bag writer (see the arguments); set by whoever records.
        self.recorder = recorder
        self.clock = clock
        #: Runs in progress by robot name.
        self.runs: dict[str, Run] = {}
        #: Called with each finished attempt's record.
        self.on_finished: list[Callable[[dict[str, Any]], None]] = []
        self._steps = world.steps
        for name, handler in (
            ("tasks", self._tasks),
            ("start", self._start),
            ("status", self._status),
            ("results", self._results),
            ("cancel", self._cancel),
        ):
            graph.add_service(f"{PREFIX}/{name}", GRADE_TYPE, NODE, self._wrap(name, handler))

    @property
    def tasks(self) -> dict[str, Task]:
        """The instructor's tasks by id (read on first use)."""
        if self._tasks_loaded is None:
            source = self._tasks_source
            assert callable(source)
            self._tasks_loaded = source()
        return self._tasks_loaded

    # -- the instructor's side ------------------------------------------------------------

    def published(self) -> list[str]:
        """Ids of the published tasks that exist."""
        return [t for t in self.results.published if t in self.tasks]

    def publish(self, task_id: str, published: bool) -> None:
        """Publish or withdraw a task (the instructor).

        Raises:
            ServiceError: no such task.
        """
        if task_id not in self.tasks:
            known = ", ".join(sorted(self.tasks)) or "none"
            msg = f"no task '{task_id}' (tasks: {known})"
            raise ServiceError(msg)
        self.results.publish(task_id, published)
        what = "published" if published else "withdrawn"
        self.graph.log("info", f"task '{task_id}' {what} by the instructor")

    def task_summary(self, task: Task) -> dict[str, Any]:
        """A task as the page lists it."""
        return {
            "id": task.id,
            "name": task.title,
            "description": task.description,
            "goal": task.goal.kind,
            "time_limit": task.time_limit,
            "rubric": thresholds(task),
            "published": task.id in self.results.published,
            "task": task.document(),
        }

    # -- starting -------------------------------------------------------------------------

    def start(
        self, peer: Peer | None, robot: str, task: Task, *, official: bool | None = None
    ) -> Run:
        """Set up ``robot`` for ``task`` and wait for its controller; return the run.

        Raises:
            ServiceError: the caller may not drive ``robot``, it does not exist, runs already,
                the start pose is not clear, or a robot parameter is refused.
        """
        scope, _admin = connection_rights(peer)
        if scope != "*" and robot != scope:
            msg = f"this connection may run tasks on its own robot '{scope}' only, not '{robot}'"
            raise ServiceError(msg)
        if robot not in self.world.robots:
            known = ", ".join(repr(n) for n in sorted(self.world.robots)) or "none"
            msg = f"no robot '{robot}' (robots: {known})"
            raise ServiceError(msg)
        if robot in self.runs:
            busy = self.runs[robot].attempt
            msg = f"robot '{robot or '(default)'}' is already running attempt {busy}"
            raise ServiceError(msg)
        done = sum(1 for r in self.results.attempts.values() if r.get("robot") == robot)
        if done >= self.max_attempts:
            msg = (
                f"robot '{robot or '(default)'}' has {done} attempts recorded, the most a robot "
                f"may have (grading_max_attempts {self.max_attempts}); ask the instructor"
            )
            raise ServiceError(msg)
        if task.world is not None and Path(task.world).stem != world_spec(self.world).name:
            msg = (
                f"task '{task.id}' is set in world '{Path(task.world).stem}', but this server "
                f"runs world '{world_spec(self.world).name}' (start it with --world {task.world})"
            )
            raise ServiceError(msg)
        if self.world.halted(robot):
            msg = f"robot '{robot or '(default)'}' is held by an emergency stop; release it first"
            raise ServiceError(msg)
        body = self.world.robots[robot]
        start = task.start or body.start
        saved = dict(body.overrides)
        saved_realism = dict(body.realism_own)
        saved_plant = body.plant
        try:  # the parameters first: a refused one leaves the robot where and as it was
            apply_robot_params(self.world, robot, task.robot_params)
            self.world.teleport(robot, start)  # checks the pose before it moves the robot
        except (ValueError, KeyError) as err:
            restore_robot(body, saved, saved_realism)
            body.plant = saved_plant
            raise ServiceError(f"task '{task.id}': {err}") from None
        if official is None:
            published = self.tasks.get(task.id)
            official = published is not None and published.digest() == task.digest()
        student = scope if scope != "*" else (robot or "(default)")
        run = Run(
            attempt=self.results.new_id(),
            task=task,
            goal=resolve_goal(task.goal, start, task.frame),
            robot=robot,
            body=body,
            student=student,
            client="this process" if peer is None else describe_peer(peer),
            official=official,
            start=(start[0], start[1], start[2]),
            saved=saved,
            saved_realism=saved_realism,
            started=self.clock(),
        )
        self._subscribe(run)
        self.runs[robot] = run
        self.results.start(
            run.attempt,
            {
                "task_id": task.id,
                "task_name": task.title,
                "task_digest": task.digest(),
                "official": official,
                "robot": robot,
                "student": student,
                "client": run.client,
                "bag": run.bag_path,
            },
        )
        self.graph.log(
            "info",
            f"grading attempt {run.attempt}: task '{task.id}' on robot '{robot or '(default)'}' "
            f"for {run.client}; waiting for the controller's first /cmd_vel",
        )
        return run

    def _subscribe(self, run: Run) -> None:
        body = self.world.robots[run.robot]
        cmd = body.topic("cmd_vel")
        found = self.graph.topics.topics.get(cmd)
        kind = found.type if found is not None and found.type else "geometry_msgs/msg/Twist"

        def on_cmd(msg: Any, source: object) -> None:
            if run.phase != "waiting":
                return
            twist = twist_of(msg)
            if abs(twist["linear"]["x"]) > 1e-9 or abs(twist["angular"]["z"]) > 1e-9:
                self._begin(run)

        self.graph.subscribe(cmd, kind, NODE, on_cmd)
        run.subscriptions.append((cmd, on_cmd))
        if self.bags is None or self.recorder is None:
            return
        path = self.bags / run.attempt
        try:
            run.bag = self.recorder(path)
        except SimbridgeError as err:
            logger.warning("attempt %s is not recorded: %s", run.attempt, err)
            return
        run.bag_path = str(path)
        for name in (cmd, body.topic("odom"), body.topic("scan"), "/tf"):
            topic = self.graph.topics.topics.get(name)
            if topic is None or topic.type is None or not topic.known:
                continue
            type_name = topic.type

            def record(msg: Any, source: object, name: str = name, kind: str = type_name) -> None:
                if run.bag is not None:
                    run.bag.write(name, kind, msg, time.time_ns())

            self.graph.subscribe(name, type_name, NODE, record)
            run.subscriptions.append((name, record))

    def _begin(self, run: Run) -> None:
        run.phase = "running"
        run.elapsed = 0.0
        self._sample(run)
        self.graph.log("info", f"grading attempt {run.attempt}: the controller started")

    # -- the loop -------------------------------------------------------------------------

    def tick(self, now: float) -> None:
        """Sample every running robot after a step; end runs at their limits."""
        steps = self.world.steps
        stepped = steps != self._steps
        self._steps = steps
        if not self.runs:
            return
        dt = self.world.dt
        for run in list(self.runs.values()):
            if self.world.robots.get(run.robot) is not run.body:
                self._end(run, "error", "the robot was removed during the run")
                continue
            if run.bag is not None:
                run.bag.tick()
            if not stepped:
                continue
            if run.phase == "waiting":
                run.waited += dt
                if run.waited >= run.task.wait_for_controller - 1e-9:
                    reason = (
                        f"no /cmd_vel from a controller within {run.task.wait_for_controller:g} s"
                    )
                    self._end(run, "no_controller", reason)
                continue
            run.elapsed += dt
            self._sample(run)
            if run.elapsed >= run.task.time_limit - 1e-9:
                self._end(run, None, "")

    def _sample(self, run: Run) -> None:
        s = self.world.robots[run.robot].state
        radius = self.world.robot_params(run.robot).radius
        clear = clearance(s.x, s.y, radius, self.world.segments)
        run.trace.add(run.elapsed, s.x, s.y, s.theta, clear)
        run.trace.touch(run.robot in self.world.touching)

    def cancel(self, robot: str, reason: str = "cancelled") -> dict[str, Any]:
        """End ``robot``'s run now; return its record.

        Raises:
            ServiceError: no run on that robot.
        """
        run = self.runs.get(robot)
        if run is None:
            msg = f"robot '{robot or '(default)'}' runs no task"
            raise ServiceError(msg)
        return self._end(run, "cancelled", reason)

    def close(self) -> None:
        """End every run (the server stops): recorded as interrupted; close the journal."""
        for run in list(self.runs.values()):
            self._end(run, "interrupted", "the server stopped during this attempt")
        self.results.close()

    def _end(self, run: Run, status: str | None, reason: str) -> dict[str, Any]:
        self.runs.pop(run.robot, None)
        for name, callback in run.subscriptions:
            self.graph.topics.unsubscribe_internal(name, callback)
        run.subscriptions.clear()
        if run.bag is not None:
            try:
                run.bag.close()
            except Exception:  # a full disk must not lose the score
                logger.exception("attempt %s: the bag could not be finished", run.attempt)
            run.bag = None
        if self.world.robots.get(run.robot) is run.body:
            if run.phase == "running":
                self.world.command(run.robot, 0.0, 0.0)  # stopped at the time limit
            restore_robot(run.body, run.saved, run.saved_realism)
        metrics, response = score(run.goal, run.trace)
        passed, lines = evaluate(run.task.rubric, metrics)
        if status is None:
            status = "passed" if passed else "failed"
        else:
            passed = False
        response = {
            **response,
            "t": _thin([round(v, 3) for v in response["t"]]),
            "y": _thin([round(v, 5) for v in response["y"]]),
            "error": _thin([round(v, 5) for v in response.get("error", [])]),
            "tolerance": run.goal.reach,
        }
        record = {
            "status": status,
            "passed": passed,
            "reason": reason or None,
            "task": run.task.document(),
            "metrics": metrics,
            "thresholds": thresholds(run.task),
            "rubric": lines,
            "response": response,
            "start": list(run.start),
            "duration_s": round(run.elapsed, 3),
        }
        self.results.finish(run.attempt, record)
        full = self.results.attempts[run.attempt]
        failed = [line["text"] for line in lines if not line["passed"]]
        self.graph.log(
            "info",
            f"grading attempt {run.attempt} ({run.task.id}, robot '{run.robot or '(default)'}'): "
            f"{status}"
            + (f" ({reason})" if reason else "")
            + (f"; failed: {'; '.join(failed)}" if failed and status == "failed" else ""),
        )
        for notify in self.on_finished:
            notify(full)
        return full

    # -- reading results --------------------------------------------------------------------

    @staticmethod
    def may_read(peer: Peer | None, record: dict[str, Any]) -> bool:
        """Whether ``peer`` may read an attempt: an administrator, or its robot's connection."""
        scope, admin = connection_rights(peer)
        return admin or scope == "*" or record.get("robot") == scope

    @staticmethod
    def summary(record: dict[str, Any]) -> dict[str, Any]:
        """An attempt without its trace (lists)."""
        return {
            k: record.get(k)
            for k in (
                "attempt",
                "task_id",
                "task_name",
                "official",
                "robot",
                "student",
                "client",
                "time",
                "ended",
                "status",
                "passed",
                "reason",
                "metrics",
                "rubric",
                "bag",
            )
        }

    @staticmethod
    def with_plot(record: dict[str, Any]) -> dict[str, Any]:
        """An attempt with its response drawn (SVG, ``plot_svg``)."""
        if record.get("status") == "running" or "response" not in record:
            return dict(record)
        return {**record, "plot_svg": response_svg(record)}

    def best(self) -> list[dict[str, Any]]:
        """The best official attempt of each student on each task.

        Passed first, then fewer failed rubric lines, then the earliest.
        """
        best: dict[tuple[str, str], dict[str, Any]] = {}
        for record in self.results.attempts.values():
            if not record.get("official") or record.get("status") == "running":
                continue
            key = (str(record.get("student")), str(record.get("task_id")))
            old = best.get(key)
            if old is None or _rank(record) < _rank(old):
                best[key] = record
        return [self.summary(r) for _, r in sorted(best.items())]

    # -- services -------------------------------------------------------------------------

    def _wrap(
        self, name: str, handler: Callable[[Peer | None, dict[str, Any]], Any]
    ) -> Callable[[Any], dict[str, Any]]:
        service = f"{PREFIX}/{name}"

        def call(args: Any) -> dict[str, Any]:
            req = request_fields(args, ("task", "robot", "attempt", "task_yaml"), service)
            for key, value in req.items():
                if not isinstance(value, str):
                    msg = f"{service}: field '{key}' must be a string, got {value!r}"
                    raise ServiceError(msg)
            try:
                result = handler(caller.get(), req)
            except ServiceError as err:
                raise ServiceError(f"{service}: {err}") from None
            return {"success": True, "message": orjson.dumps(result).decode()}

        return call

    def _tasks(self, peer: Peer | None, req: dict[str, Any]) -> Any:
        _scope, admin = connection_rights(peer)
        ids = sorted(self.tasks) if admin else self.published()
        return {"tasks": [self.task_summary(self.tasks[i]) for i in ids]}

    def _start(self, peer: Peer | None, req: dict[str, Any]) -> Any:
        scope, admin = connection_rights(peer)
        robot = str(req.get("robot", "")).strip("/")
        if not robot and scope != "*":
            robot = scope
        text = req.get("task_yaml") or ""
        task_id = req.get("task") or ""
        if text:
            try:
                task = parse_task(text, source="task_yaml", task_id=task_id)
            except ConfigError as err:
                raise ServiceError(str(err)) from None
            official = None
            if not admin:
                self._may_set(robot, task)
        else:
            task_or_none = self.tasks.get(task_id)
            if task_or_none is None or not (admin or task_id in self.results.published):
                shown = ", ".join(self.published()) or "none"
                msg = f"no published task '{task_id}' (published: {shown})"
                raise ServiceError(msg)
            task, official = task_or_none, True
        run = self.start(peer, robot, task, official=official)
        return {**run.state(), "official": run.official}

    def _may_set(self, robot: str, task: Task) -> None:
        """Refuse a task sent as text that would raise one of ``robot``'s limits.

        A student may practise on its own robot with parameters of its own, but not lift the
        limits only an administrator may set (``…/set_parameters``): ``robot_params:
        {robot.max_linear_velocity: 20}`` made a student's robot 40 times as fast for the
        600 s a run may last. A published task's own parameters are the instructor's.
        """
        published = self.tasks.get(task.id) if task.id in self.published() else None
        if published is not None and published.robot_params == task.robot_params:
            return
        current = self.world.robot_params(robot)
        self._may_speed_up(robot, task, current)
        for key, value in task.robot_params.items():
            section, _, name = key.partition(".")
            if section == "robot" and name in RAISABLE_LIMITS and value > getattr(current, name):
                msg = (
                    f"task_yaml: robot_params.{key} {value:g} is above the robot's "
                    f"{getattr(current, name):g}: only the instructor raises a robot's limits; "
                    "a task sent as text may lower them"
                )
                raise ServiceError(msg)

    def _may_speed_up(self, robot: str, task: Task, current: RobotLike) -> None:
        """Refuse a task sent as text whose realism profile makes ``robot`` faster than now.

        Under a profile the ground moves by the true wheels (``realism.wheel_radius_*``,
        ``wheel_speed_scale``, ``wheelbase``) what the clamp allowed the nominal ones: true
        wheels of 1 m on a 0.033 m nominal radius drove a student's robot 60 times as fast as
        ``max_linear_velocity``, as raising the limit itself would have.
        """
        body = self.world.robots.get(robot)
        if body is None:
            return  # start() names the robot
        shared = self.world.params.realism
        params = task.robot_params
        own = {k.removeprefix("realism."): v for k, v in params.items() if k.startswith("realism.")}
        try:
            after = shared.replace(**{**body.realism_own, **own})
        except (SettingsError, TypeError):
            return  # start() refuses it, naming the value
        r = float(params.get("robot.wheel_radius", current.wheel_radius))
        b = float(params.get("robot.wheelbase", current.wheelbase))
        now = _speed_up(current.wheel_radius, current.wheelbase, body.realism(shared))
        then = _speed_up(r, b, after if after.enabled else None)
        for what, before, later in zip(("linear", "angular"), now, then, strict=True):
            if later > max(1.0, before) + 1e-9:
                msg = (
                    f"task_yaml: its realism values move robot '{robot}' {later:.3g} times as "
                    f"fast ({what}) as it is commanded, above the robot's {max(1.0, before):.3g}: "
                    "only the instructor raises a robot's limits"
                )
                raise ServiceError(msg)

    def _status(self, peer: Peer | None, req: dict[str, Any]) -> Any:
        attempt = req.get("attempt") or ""
        robot = str(req.get("robot", "")).strip("/")
        if attempt:
            for run in self.runs.values():
                if run.attempt == attempt:
                    if not self.may_read(peer, {"robot": run.robot}):
                        raise ServiceError(f"attempt {attempt} is not this connection's")
                    return run.state()
            record = self.results.attempts.get(attempt)
            if record is None:
                raise ServiceError(f"no attempt {attempt}")
            if not self.may_read(peer, record):
                raise ServiceError(f"attempt {attempt} is not this connection's")
            return self.with_plot(record)
        scope, _ = connection_rights(peer)
        if not robot and scope != "*":
            robot = scope
        if not self.may_read(peer, {"robot": robot}):
            raise ServiceError(f"robot '{robot}' is not this connection's")
        if robot in self.runs:
            return self.runs[robot].state()
        mine = [r for r in self.results.attempts.values() if r.get("robot") == robot]
        if not mine:
            return {"robot": robot, "status": "idle"}
        return self.with_plot(mine[-1])

    def _results(self, peer: Peer | None, req: dict[str, Any]) -> Any:
        task_id = req.get("task") or ""
        found = [
            self.summary(r)
            for r in self.results.attempts.values()
            if self.may_read(peer, r) and (not task_id or r.get("task_id") == task_id)
        ]
        return {"attempts": found[-MAX_LISTED:]}

    def _cancel(self, peer: Peer | None, req: dict[str, Any]) -> Any:
        scope, _ = connection_rights(peer)
        robot = str(req.get("robot", "")).strip("/") or ("" if scope == "*" else scope)
        if scope != "*" and robot != scope:
            raise ServiceError(f"robot '{robot}' is not this connection's")
        return self.summary(
            self.cancel(
                robot, f"cancelled by {'this process' if peer is None else describe_peer(peer)}"
            )
        )


def _speed_up(r: float, b: float, real: RealismLike | None) -> tuple[float, float]:
    """How many times as fast as commanded a robot moves under ``real``: (linear, angular)."""
    if real is None or r <= 0 or b <= 0:
        return 1.0, 1.0
    wheel = real.wheel_speed_scale * max(real.wheel_radius_left or r, real.wheel_radius_right or r)
    linear = wheel / r
    return linear, linear * b / (real.wheelbase or b)


def _rank(record: dict[str, Any]) -> tuple[int, int, float]:
    failed = sum(1 for line in record.get("rubric") or [] if not line.get("passed"))
    return (0 if record.get("passed") else 1, failed, float(record.get("time") or 0.0))
