from __future__ import annotations

import copy
import dataclasses
import inspect
import pickle
from typing import Annotated, Any, Literal, Self

import numpy as np
import pytest
from pydantic import BeforeValidator, ConfigDict, Field, model_validator

from simbridge.app.config import Params, RobotParams, WorldSpec
from simbridge.app.settings import (
    Budget,
    Float,
    Int,
    Port,
    Record,
    RunOptions,
    ServerSettings,
    SettingsError,
    budgets,
    check,
    environment,
    options,
)
from simbridge.errors import ConfigError
from simbridge.graph import Graph
from simbridge.rosbridge.budget import GLOBAL_LIMITS, Limits


class Inner(Record):
    """A nested record with a relation between its fields."""

    low: Float = Field(0.0, ge=0)
    high: Float = Field(1.0, le=10)

    @model_validator(mode="after")
    def _ordered(self) -> Self:
        if self.low >= self.high:
            msg = f"low ({self.low}) must be below high ({self.high})"
            raise ValueError(msg)
        return self


class Sample(Record):
    """One field of each kind the settings use."""

    count: Int = Field(1, ge=1, le=8)
    ratio: Float = Field(0.5, gt=0, lt=1, description="a share")
    flag: bool = False
    label: str = Field("x", min_length=1, max_length=5)
    level: Literal["debug", "info"] = "info"
    pose: tuple[Float, Float, Float] = (0.0, 0.0, 0.0)
    names: tuple[str, ...] | None = None
    points: list[tuple[Float, Float]] = Field(default_factory=list, max_length=3)
    tokens: dict[str, str] = Field(default_factory=dict)
    port: Port | None = None
    inner: Inner = Field(default_factory=Inner)
    items: list[Inner] = Field(default_factory=list)
    needed: Annotated[str, BeforeValidator(str.strip)]


class Frozen(Record):
    model_config = ConfigDict(frozen=True)

    value: Int = 0


def refusal(**values: Any) -> str:
    with pytest.raises(SettingsError) as err:
        Sample(needed="n", **values)
    return str(err.value)


@pytest.mark.parametrize(
    ("values", "text"),
    [
        ({"count": 0}, "count: must be greater than or equal to 1 (got 0)"),
        ({"count": 9}, "count: must be less than or equal to 8 (got 9)"),
        ({"ratio": 0}, "ratio: must be greater than 0 (got 0)"),
        ({"ratio": 1.0}, "ratio: must be less than 1 (got 1.0)"),
        ({"label": ""}, "label: must not be empty (got '')"),
        ({"label": "toolong"}, "label: must have at most 5 characters (got 7)"),
        ({"points": [[0, 0]] * 4}, "points: must have at most 3 items (got 4)"),
        ({"level": "loud"}, "level: must be 'debug' or 'info' (got 'loud')"),
        ({"port": 70000}, "port: must be less than or equal to 65535 (got 70000)"),
        ({"inner": {"low": -1}}, "inner.low: must be greater than or equal to 0 (got -1)"),
        ({"inner": {"low": 5, "high": 2}}, "inner: low (5.0) must be below high (2.0)"),
        ({"items": [{}, {"high": 11}]}, "items[1].high: must be less than or equal to 10 (got 11)"),
        ({"inner": []}, "inner: must be a mapping of keys (got [])"),
        ({"inner": {"hihg": 2}}, "inner.hihg: unknown key (check its spelling and nesting)"),
    ],
)
def test_out_of_bounds_values_are_refused_naming_the_path_and_the_bound(
    values: dict[str, Any], text: str
) -> None:
    assert refusal(**values) == text


@pytest.mark.parametrize(
    ("values", "text"),
    [
        ({"count": True}, "count: must be a number, not a boolean (got True)"),
        ({"ratio": False}, "ratio: must be a number, not a boolean (got False)"),
        ({"ratio": np.bool_(True)}, "ratio: must be a number, not a boolean"),
        ({"count": 1.5}, "count: must be a valid integer (got 1.5)"),
        ({"count": "two"}, "count: must be a valid integer (got 'two')"),
        ({"count": "1e3"}, "count: must be a valid integer (got '1e3')"),
        ({"ratio": "half"}, "ratio: must be a number (got 'half')"),
        ({"ratio": None}, "ratio: must be a number (got None)"),
        ({"ratio": float("nan")}, "ratio: must be a finite number (got nan)"),
        ({"ratio": "inf"}, "ratio: must be a finite number (got 'inf')"),
        ({"pose": [0, 0, 10**400]}, "pose[2]: must be a "),
        ({"flag": 2}, "flag: must be a valid boolean: true/false, yes/no, on/off or 1/0 (got 2)"),
        ({"flag": "maybe"}, "flag: must be a valid boolean"),
        ({"label": 5}, "label: must be a string (got 5)"),
        ({"label": False}, "label: must be a string (got False)"),  # YAML 1.1's `off`
        ({"pose": "abc"}, "pose: must be a list (got 'abc')"),
        ({"pose": [0]}, "pose: must have 3 items (got 1: [0])"),
        ({"pose": [0, "x", None]}, "pose[1]: must be a number (got 'x'); pose[2]: must be a"),
        ({"names": "ab"}, "names: must be a list (got 'ab')"),
        ({"tokens": {"a": 1}}, "tokens.a: must be a string (got 1)"),
        ({"tokens": [("a", "b")]}, "tokens: must be a mapping"),
        ({"colour": "red"}, "colour: unknown key (check its spelling and nesting)"),
    ],
)
def test_values_of_the_wrong_kind_are_refused_and_bools_are_not_numbers(
    values: dict[str, Any], text: str
) -> None:
    assert refusal(**values).startswith(text)


def test_every_refusal_of_a_record_is_reported_at_once() -> None:
    """Two bad fields and a missing one: one error listing all three, each with its path."""
    with pytest.raises(SettingsError) as err:
        Sample(count=0, label="")
    assert err.value.errors == [
        ("count", "must be greater than or equal to 1 (got 0)"),
        ("label", "must not be empty (got '')"),
        ("needed", "required, but missing"),
    ]


def test_coercions_that_files_and_the_environment_rely_on() -> None:
    """Ints for floats, lists for tuples, numeric and boolean text, numpy's scalars."""
    s = Sample(
        needed="  n  ",
        count="3",
        ratio=" 0.25 ",
        flag="Yes",
        pose=[1, np.float64(2.5), np.int64(3)],
        names=["a", "b"],
        points=[(0, 1)],
        port="8080",
        inner={"low": 1, "high": "2"},
    )
    assert (s.count, s.ratio, s.flag, s.needed) == (3, 0.25, True, "n")
    assert s.pose == (1.0, 2.5, 3.0) and all(type(v) is float for v in s.pose)
    assert (s.names, s.points, s.port) == (("a", "b"), [(0.0, 1.0)], 8080)
    assert s.inner == Inner(low=1.0, high=2.0)
    assert Sample(needed="n", count=2.0, flag=0).count == 2
    assert Sample(needed="n", flag="off").flag is False
    assert Sample(needed="n", count=np.int64(4)).count == 4


def test_a_record_validates_assignment_and_its_relations_and_keeps_the_old_value() -> None:
    inner = Inner()
    inner.high = 5
    assert inner.high == 5.0 and inner.given == {"high"}
    with pytest.raises(SettingsError, match=r"^high: must be less than or equal to 10"):
        inner.high = 11
    with pytest.raises(SettingsError, match=r"^low \(6\.0\) must be below high"):
        inner.low = 6
    assert (inner.low, inner.high) == (0.0, 5.0)
    with pytest.raises(SettingsError, match="Inner has no setting 'middle'"):
        inner.middle = 1


def test_a_key_named_self_and_numpy_arrays_are_refused_not_crashes() -> None:
    """Any key of a file is refused by name, even ``self``; an array is not a number."""
    with pytest.raises(SettingsError, match=r"^robot\.self: unknown key"):
        Params.parse({"robot": {"self": 1}})
    with pytest.raises(SettingsError, match=r"^self: unknown key"):
        RobotParams(self=1)
    with pytest.raises(SettingsError, match=r"^mass: must be a number \(got array"):
        RobotParams(mass=np.array([1.0, 2.0]))
    with pytest.raises(SettingsError, match=r"^count: must be a valid integer \(got array"):
        Sample(needed="n", count=np.array([1, 2]))


def test_a_frozen_record_refuses_every_change() -> None:
    frozen = Frozen(value=2)
    with pytest.raises(SettingsError, match="value: cannot be changed"):
        frozen.value = 3
    assert frozen.value == 2
    with pytest.raises(SettingsError, match=r"^max_clients: cannot be changed"):
        ServerSettings().max_clients = 5


def test_parse_replace_as_dict_and_given() -> None:
    """Records parse a mapping, replace validates, as_dict gives plain data back."""
    s = Sample.parse({"needed": "n", "inner": {"high": 3}})
    assert s.given == {"needed", "inner"} and s.inner.given == {"high"}
    t = s.replace(count=4)
    assert (t.count, t.inner, s.count) == (4, s.inner, 1)
    with pytest.raises(SettingsError, match=r"^count: must be less than or equal to 8"):
        s.replace(count=80)
    data = s.as_dict()
    assert data["inner"] == {"low": 0.0, "high": 3.0} and data["pose"] == (0.0, 0.0, 0.0)
    assert Sample.parse(data) == s
    with pytest.raises(SettingsError, match=r"^must be a mapping of keys \(got \[1\]\)"):
        Sample.parse([1])  # type: ignore[arg-type]
    with pytest.raises(SettingsError, match=r"^1: keys must be names"):
        Sample.parse({1: "x"})  # type: ignore[dict-item]


def test_records_copy_pickle_compare_and_show_their_values() -> None:
    p = Params()
    assert copy.deepcopy(p) == p and pickle.loads(pickle.dumps(p)) == p
    assert p != Params(robot=RobotParams(mass=2))
    assert repr(RobotParams()).startswith("RobotParams(mass=1.5, wheel_radius=0.033, ")


def test_settings_error_is_a_value_error_and_a_config_error_with_paths() -> None:
    err = SettingsError([("mass", "must be greater than 0 (got -1)"), ("", "bad pair")])
    assert isinstance(err, ValueError) and isinstance(err, ConfigError)
    assert str(err) == "mass: must be greater than 0 (got -1); bad pair"
    assert (
        str(err.within("robot")) == "robot.mass: must be greater than 0 (got -1); robot: bad pair"
    )
    assert err.within("walls").within("world").errors[0][0] == "world.walls.mass"
    assert SettingsError.one("x", "[2]").within("walls").errors == [("walls[2]", "x")]
    assert err.describe(str.upper) == "MASS: must be greater than 0 (got -1); bad pair"


def test_a_settings_error_survives_pickling_with_its_refusals() -> None:
    """A refusal crosses a process boundary (multiprocessing, a worker's result) whole."""
    err = SettingsError([("robot.mass", "must be greater than 0 (got -1)"), ("", "bad")])
    back = pickle.loads(pickle.dumps(err))
    assert type(back) is SettingsError
    assert back.errors == err.errors
    assert str(back) == str(err) == "robot.mass: must be greater than 0 (got -1); bad"


def test_every_declared_bound_of_the_parameters_is_enforced_with_its_dotted_name() -> None:
    """For each bounded parameter, a value just past each bound is refused naming it."""
    flat = Params().flat()
    checked = 0
    for name, bounds in Params.bounds().items():
        for bad, words in (
            (bounds.gt, "greater than"),
            (bounds.ge - 1 if bounds.ge is not None else None, "greater than or equal to"),
            (bounds.lt, "less than"),
            (bounds.le + 1 if bounds.le is not None else None, "less than or equal to"),
        ):
            if bad is None:
                continue
            with pytest.raises(SettingsError) as err:
                Params.from_flat({**flat, name: bad})
            assert str(err.value).startswith(f"{name}: must be {words} "), err.value
            checked += 1
    assert checked >= 30


def test_descriptions_and_bounds_come_from_the_declarations() -> None:
    """What parameter services and the admin page show is what the records declare."""
    assert Params.describe()["robot.mass"] == "chassis mass, kg"
    assert Params.bounds()["robot.mass"].text() == "> 0 and <= 1000"
    assert Params.bounds()["lidar.range_min"].text() == ">= 0"
    assert not Params.bounds()["lidar.mount"]
    assert Sample.model_fields["ratio"].description == "a share"


def test_a_world_refuses_what_it_always_refused_with_readable_paths() -> None:
    for data, text in [
        ({"boxes": [{"center": [0, 0]}]}, "boxes[0].size: required, but missing"),
        ({"circles": [{"center": [0, 0], "radius": 0}]}, "circles[0].radius: must be greater"),
        ({"circles": [{"center": [0, 0], "radius": 1, "segments": 5}]}, "circles[0].segments"),
        ({"walls": [[0, 0, 1, 1], [0, 0, 1]]}, "walls[1]: has 3 numbers, expected [x1, y1,"),
        ({"walls": [5]}, "walls[0]: is 5, not a list; expected [x1, y1, x2, y2]"),
        ({"polygons": [[[0, 0], [1, "x"]]]}, "polygons[0][1]: 'x' is not a finite number"),
        ({"polygons": [[[0, 0]]]}, "polygons[0]: must be a list of at least 2 corners"),
        ({"frames": [{"parent": "", "child": "a"}]}, "frames[0].parent: must not be empty"),
        ({"robots": [{"name": 5}]}, "robots[0].name: robot name 5 is not a valid ROS name"),
        ({"frames": [{"parent": "a", "child": "b"}] * 1001}, "frames: must have at most 1000"),
        ({"name": False}, "name: must be a string (got False)"),
    ]:
        with pytest.raises(SettingsError) as err:
            WorldSpec.parse(data)
        assert str(err.value).startswith(text), err.value


def test_a_world_without_robots_keeps_the_rest() -> None:
    """--no-sim: no robot, the same walls (the single robot: key is not kept)."""
    world = WorldSpec.parse({"walls": [[0, 0, 1, 0]], "robot": {"pose": [1, 2, 3]}})
    bare = world.without_robots()
    assert bare.robots == [] and bare.start_poses() == {} and bare.walls == world.walls


# -- one declaration: the budgets, the options and the variables come from the fields ----------


def test_the_budgets_come_from_the_settings_declared_with_a_budget() -> None:
    """Every per-client limit and pool but two fixed ones is a setting; values flow through."""
    limits, pool = budgets(ServerSettings())
    assert limits == Limits() and {k: pool.limit(k) for k in GLOBAL_LIMITS} == GLOBAL_LIMITS
    declared = [
        m
        for info in ServerSettings.model_fields.values()
        for m in info.metadata
        if isinstance(m, Budget)
    ]
    set_by_settings = {b.limit for b in declared if b.limit}
    fixed = {f.name for f in dataclasses.fields(Limits)} - set_by_settings
    assert fixed == {"fragment_timeout", "unauthenticated_frame_bytes"}
    assert {b.pool for b in declared if b.pool} == set(GLOBAL_LIMITS)
    limits, pool = budgets(
        ServerSettings(max_pending_goals=7, global_latched_bytes=5, max_message_size=1000)
    )
    assert (limits.pending_goals, pool.limit("latched_bytes")) == (7, 5)
    assert limits.fragment_bytes == limits.frame_bytes == 1000  # at most the largest message


def test_every_option_is_declared_with_a_description_a_flag_and_a_variable() -> None:
    declared = list(options(ServerSettings, RunOptions))
    flags = {d.flag: d for d in declared}
    assert len(flags) == len(declared) >= 25
    for d in declared:
        assert d.info.description, d.field
        listed = ", comma-separated" if d.item is not None else ""
        assert d.help().endswith(f"[{d.variable}{listed}]")
    assert flags["--results"].field == "results_file"
    assert flags["--results"].variable == "SIMBRIDGE_RESULTS"
    assert "(default: 200)" in flags["--max-clients"].help()
    assert check(flags["--port"], "9091") == 9091
    with pytest.raises(SettingsError, match=r"^must be greater than 0 \(got '0'\)$"):
        check(flags["--max-clients"], "0")
    with pytest.raises(SettingsError, match="not a ROS 2 role"):
        check(flags["--ros2-role"], "boss")


def test_list_valued_options_are_repeatable_and_their_variables_comma_separated() -> None:
    """--zenoh-connect, --zenoh-listen and --record-topics: each item checked, by its place."""
    flags = {d.flag: d for d in options(ServerSettings, RunOptions)}
    assert {f for f, d in flags.items() if d.item is not None} == {
        "--zenoh-connect",
        "--zenoh-listen",
        "--record-topics",
    }
    assert flags["--zenoh-connect"].help() == (
        "connect to this Zenoh endpoint instead, e.g. tcp/192.168.1.10:7447 (repeatable) "
        "[SIMBRIDGE_ZENOH_CONNECT, comma-separated]"
    )
    assert "(default: every topic, also later ones; repeatable)" in flags["--record-topics"].help()
    assert check(flags["--zenoh-listen"], "tcp/127.0.0.1:0") == "tcp/127.0.0.1:0"  # one item
    with pytest.raises(SettingsError, match=r"^must not be empty \(got ''\)$"):
        check(flags["--record-topics"], "")
    env = environment(
        {
            "SIMBRIDGE_ZENOH_CONNECT": "tcp/10.0.0.1:7447, tcp/10.0.0.2:7447",
            "SIMBRIDGE_RECORD_TOPICS": "/odom",
        }
    )
    assert env == {
        "zenoh_connect": ("tcp/10.0.0.1:7447", "tcp/10.0.0.2:7447"),
        "record_topics": ("/odom",),
    }
    with pytest.raises(ConfigError) as err:
        environment({"SIMBRIDGE_ZENOH_LISTEN": "tcp/127.0.0.1:0,"})
    assert str(err.value) == (
        "environment variable SIMBRIDGE_ZENOH_LISTEN[1]: must not be empty (got '')"
    )


def test_ros_distro_and_no_http_are_declared_as_the_front_ends_read_them() -> None:
    """--ros-distro's choices are the distributions the ROS 2 front ends speak; --no-http a flag."""
    from simbridge.ros2.dds.options import _DISTROS
    from simbridge.ros2.typehash import DISTROS

    flags = {d.flag: d for d in options(ServerSettings, RunOptions)}
    distro = flags["--ros-distro"]
    assert distro.metavar == "{" + ",".join(DISTROS) + "}" and tuple(_DISTROS) == DISTROS
    assert [check(distro, d) for d in DISTROS] == list(DISTROS)
    with pytest.raises(SettingsError, match="must be 'humble', 'jazzy' or 'kilted'"):
        check(distro, "rolling")
    assert flags["--no-http"].flag_only
    assert environment({"SIMBRIDGE_NO_HTTP": "yes", "SIMBRIDGE_ROS_DISTRO": "humble"}) == {
        "no_http": True,
        "ros_distro": "humble",
    }


def test_the_environment_is_read_with_the_options_types_naming_the_variable() -> None:
    """pydantic-settings reads SIMBRIDGE_*; blank is unset; a refusal names the variable."""
    env = environment(
        {"SIMBRIDGE_MAX_CLIENTS": "7", "SIMBRIDGE_ZENOH": "yes", "SIMBRIDGE_PORT": " "}
    )
    assert env == {"max_clients": 7, "zenoh": True}
    assert environment({"SIMBRIDGE_RESULTS": "r.jsonl"}) == {"results": "r.jsonl"}
    with pytest.raises(ConfigError) as err:
        environment({"SIMBRIDGE_STALL_TIMEOUT": "-5", "SIMBRIDGE_LOG_LEVEL": "loud"})
    assert str(err.value) == (
        "environment variable SIMBRIDGE_STALL_TIMEOUT: must be greater than 0 (got '-5'); "
        "environment variable SIMBRIDGE_LOG_LEVEL: must be 'debug', 'info', 'warning' or "
        "'error' (got 'loud')"
    )


def test_the_graphs_defaults_are_the_settings_defaults() -> None:
    """Graph takes plain parameters (no settings); a bare Graph() is as the default server's."""
    defaults = ServerSettings()
    parameters = inspect.signature(Graph).parameters
    for name in ("service_timeout", "max_parameter_names"):
        assert parameters[name].default == getattr(defaults, name), name
    graph = Graph()
    assert graph.services.default_timeout == defaults.service_timeout
    assert graph.max_parameter_names == defaults.max_parameter_names
