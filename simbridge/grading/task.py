"""Task files: what an instructor asks of a controller, and how a run of it is scored.

A task is a YAML file validated like the world files (one line naming the file and the key)::

    name: "Lab 2: heading step to 90 degrees"
    start: [0.0, 0.0, 0.0]        # x, y, theta; omitted: the robot's own start pose
    frame: world                  # goal coordinates: "world", or "start" (the start pose's frame)
    goal:
      heading: 1.5708             # one of: heading (rad), position [x, y], waypoints
      tolerance: 0.05             #   [[x, y], ...], wall {segment: [x1, y1, x2, y2], distance: d}
    time_limit: 10                # seconds from the controller's first command
    robot_params: {robot.mass: 3.0}   # optional: this robot's parameters during the run
                                      # (robot.* per-robot parameters, realism.*)
    rubric:                       # thresholds on the metrics (simbridge.grading.metrics)
      overshoot_pct: {max: 10}
      settling_time_s: {max: 4}

The task's id is its file name without ``.yaml``. :func:`load_task` reads a file,
:func:`parse_task` text (a task sent to a server by ``simbridge grade``).
"""

from __future__ import annotations

import hashlib
import math
from pathlib import Path
from typing import Annotated, Any, Literal, Self

import orjson
from pydantic import BeforeValidator, Field, model_validator

from simbridge.app.config import check_numbers
from simbridge.app.settings import Float, Record, SettingsError
from simbridge.errors import ConfigError
from simbridge.msgs.convert import finite_number


__all__ = [
    "METRICS",
    "STEP_METRICS",
    "Goal",
    "Task",
    "Threshold",
    "WallGoal",
    "load_task",
    "load_tasks",
    "parse_task",
]

#: The metrics a rubric may hold thresholds on, with their units.
METRICS: dict[str, str] = {
    "overshoot_pct": "%",
    "rise_time_s": "s",
    "settling_time_s": "s",
    "steady_state_error": "m or rad",
    "time_to_goal_s": "s",
    "path_length_m": "m",
    "min_clearance_m": "m",
    "collisions": "",
}
#: Metrics of a step response: not defined for a waypoints goal.
STEP_METRICS = frozenset({"overshoot_pct", "rise_time_s", "settling_time_s"})
#: Largest task text a server accepts (``simbridge grade`` sends the file).
MAX_TASK_BYTES = 64_000


def _pose(value: Any) -> Any:
    return check_numbers(value, 3, "[x, y, theta]")


def _point(value: Any) -> Any:
    return check_numbers(value, 2, "[x, y]")


def _points(value: Any) -> Any:
    if not isinstance(value, list) or not value:
        msg = f"must be a list of [x, y] points, got {value!r}"
        raise ValueError(msg)
    out = []
    for i, p in enumerate(value):
        try:
            out.append(check_numbers(p, 2, "[x, y]"))
        except ValueError as err:
            msg = f"[{i}] {err}"
            raise ValueError(msg) from None
    return out


def _segment(value: Any) -> Any:
    return check_numbers(value, 4, "[x1, y1, x2, y2]")


class WallGoal(Record):
    """Keep ``distance`` metres between the robot's centre and the wall ``segment``."""

    segment: Annotated[tuple[Float, Float, Float, Float], BeforeValidator(_segment)]
    distance: Float = Field(gt=0, le=100)

    @model_validator(mode="after")
    def _has_length(self) -> Self:
        """The segment has a length."""
        x1, y1, x2, y2 = self.segment
        if math.hypot(x2 - x1, y2 - y1) < 1e-9:
            msg = "segment: the two ends are the same point"
            raise ValueError(msg)
        return self


class Goal(Record):
    """What the controller must reach: exactly one of the four kinds."""

    heading: Float | None = Field(None, description="final yaw, rad")
    position: Annotated[tuple[Float, Float] | None, BeforeValidator(_point)] = None
    waypoints: Annotated[list[tuple[Float, Float]] | None, BeforeValidator(_points)] = None
    wall: WallGoal | None = None
    #: Reached when the error is within this (rad for a heading, m otherwise); 0: the kind's
    #: default (0.05 rad, 0.05 m).
    tolerance: Float = Field(0.0, ge=0, le=100)

    @model_validator(mode="after")
    def _one_kind(self) -> Self:
        """Exactly one kind of goal."""
        kinds = [k for k in ("heading", "position", "waypoints", "wall") if k in self.given]
        if len(kinds) != 1:
            msg = "give exactly one of heading, position, waypoints or wall" + (
                f" (got {', '.join(kinds)})" if kinds else ""
            )
            raise ValueError(msg)
        return self

    @property
    def kind(self) -> Literal["heading", "position", "waypoints", "wall"]:
        """Which goal this is."""
        if self.heading is not None:
            return "heading"
        if self.position is not None:
            return "position"
        if self.waypoints is not None:
            return "waypoints"
        return "wall"

    @property
    def reach(self) -> float:
        """The tolerance within which the goal counts as reached."""
        return self.tolerance or 0.05


class Threshold(Record):
    """One rubric line: the metric must be at most ``max`` and/or at least ``min``."""

    max: Float | None = None
    min: Float | None = None

    @model_validator(mode="after")
    def _a_bound(self) -> Self:
        """At least one bound."""
        if self.max is None and self.min is None:
            msg = "give max or min (e.g. {max: 10})"
            raise ValueError(msg)
        return self


def _rubric(value: Any) -> Any:
    if not isinstance(value, dict) or not value:
        msg = "must map metrics to thresholds, e.g. {overshoot_pct: {max: 10}}"
        raise ValueError(msg)
    for key in value:
        if key not in METRICS:
            msg = f"{key}: unknown metric; rubric metrics are {', '.join(METRICS)}"
            raise ValueError(msg)
    return value


def _robot_params(value: Any) -> Any:
    if not isinstance(value, dict):
        msg = f"must map parameter names to values, e.g. {{robot.mass: 3.0}}, got {value!r}"
        raise ValueError(msg)
    out = {}
    for key, v in value.items():
        if not isinstance(key, str) or "." not in key:
            msg = f"{key}: a parameter name with its section, e.g. robot.mass"
            raise ValueError(msg)
        if isinstance(v, bool):
            v = float(v)  # realism.enabled: true (a boolean setting reads 1.0 as true)
        if not finite_number(v):
            msg = f"{key}: must be a number or a boolean, got {v!r}"
            raise ValueError(msg)
        out[key] = v
    return out


class Task(Record):
    """One task file (see the module docstring)."""

    #: The task's id (its file name without ``.yaml``; set by the loader when absent).
    id: str = Field("", max_length=100)
    name: str = Field("", max_length=200)
    description: str = Field("", max_length=2000)
    #: A world file (relative to the task file); None: the world the server runs.
    world: str | None = None
    start: Annotated[tuple[Float, Float, Float] | None, BeforeValidator(_pose)] = None
    frame: Literal["world", "start"] = "world"
    goal: Goal
    time_limit: Float = Field(gt=0, le=600, description="seconds from the first command")
    #: Seconds the server waits for the controller's first (non-zero) command.
    wait_for_controller: Float = Field(60.0, gt=0, le=3600)
    #: This robot's parameters during the run (``robot.mass``...; any per-robot parameter).
    robot_params: Annotated[dict[str, Float], BeforeValidator(_robot_params)] = Field(
        default_factory=dict
    )
    rubric: Annotated[dict[str, Threshold], BeforeValidator(_rubric)]

    @model_validator(mode="after")
    def _step_metrics(self) -> Self:
        """Step metrics need a step: none on a waypoints goal."""
        if self.goal.kind == "waypoints":
            bad = sorted(STEP_METRICS & set(self.rubric))
            if bad:
                msg = f"rubric.{bad[0]}: not defined for a waypoints goal (no single step)"
                raise ValueError(msg)
        return self

    @property
    def title(self) -> str:
        """The name, or the id."""
        return self.name or self.id

    def document(self) -> dict[str, Any]:
        """The task as plain JSON data (what a report and the page show)."""
        data = self.as_dict()
        data["rubric"] = {name: th.as_dict() for name, th in self.rubric.items()}
        return data

    def digest(self) -> str:
        """A short hash of what the task asks (a modified copy has another one)."""
        data = self.document()
        data.pop("description", None)
        return hashlib.sha256(orjson.dumps(data, option=orjson.OPT_SORT_KEYS)).hexdigest()[:16]


def _describe(err: SettingsError) -> str:
    return err.errors[0][0] + ": " + err.errors[0][1] if err.errors[0][0] else err.errors[0][1]


def parse_task(text: str, *, source: str = "task", task_id: str = "") -> Task:
    """Return the task in YAML ``text`` (a file's content).

    Raises:
        ConfigError: not YAML, not a mapping, or a key or value is invalid; one line naming
            ``source`` and the key (the first refusal).
    """
    import yaml  # only when a task is read

    if len(text.encode()) > MAX_TASK_BYTES:
        msg = f"{source}: larger than {MAX_TASK_BYTES} bytes"
        raise ConfigError(msg)

    class _Loader(yaml.SafeLoader):
        """``safe_load`` without aliases: a task is sent by students (``task_yaml``).

        An alias shares a node, so eight nested lists in 360 bytes stood for 9**8 strings, which
        the refusal's ``got [...]`` then spelled out: 1 GB and the loop held 5 s.
        """

        def compose_node(self, parent: Any, index: Any) -> Any:
            if self.check_event(yaml.AliasEvent):
                msg = "aliases (*name) are not taken in a task"
                raise yaml.composer.ComposerError(None, None, msg)
            return super().compose_node(parent, index)

    try:
        data = yaml.load(text, Loader=_Loader)  # a SafeLoader, without aliases
    except yaml.YAMLError as err:
        line = " ".join(str(err).split())
        msg = f"{source}: is not valid YAML: {line}"
        raise ConfigError(msg) from None
    if not isinstance(data, dict):
        msg = f"{source}: top level must be a mapping of keys (name, goal, time_limit, rubric...)"
        raise ConfigError(msg)
    if task_id and not data.get("id"):
        data["id"] = task_id
    try:
        task = Task.parse(data)
    except SettingsError as err:
        raise ConfigError(f"{source}: {_describe(err)}") from None
    if not task.id:
        msg = f"{source}: id: required when the task does not come from a file"
        raise ConfigError(msg)
    return task


def load_task(path: Path | str) -> Task:
    """Read and validate a task file; its id defaults to the file name without ``.yaml``.

    Raises:
        ConfigError: the file cannot be read, or is invalid (one line naming the key).
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as err:
        msg = f"task file '{p}': cannot be read ({err.strerror}); check the path"
        raise ConfigError(msg) from None
    return parse_task(text, source=f"task file '{p}'", task_id=p.stem)


def load_tasks(directory: Path | str) -> dict[str, Task]:
    """Read every ``*.yaml`` task of ``directory``, by id.

    Raises:
        ConfigError: a file is invalid, or two files have the same id.
    """
    out: dict[str, Task] = {}
    for path in sorted(Path(directory).glob("*.yaml")):
        task = load_task(path)
        if task.id in out:
            msg = f"task file '{path}': id: '{task.id}' is used by another task file"
            raise ConfigError(msg)
        out[task.id] = task
    return out
