"""graph.params: one node's parameters, typed, changed all or nothing."""

from __future__ import annotations

from typing import Any

import pytest

from simbridge.errors import ServiceError
from simbridge.graph.params import (
    PARAMETER_BOOL,
    PARAMETER_DOUBLE,
    PARAMETER_DOUBLE_ARRAY,
    PARAMETER_INTEGER,
    PARAMETER_NOT_SET,
    PARAMETER_STRING,
    ParameterStore,
    ParamNode,
    param_type,
)


class Settings:
    """A node's backing values: ``low`` must stay below ``high`` (a relation, as in Params)."""

    def __init__(self) -> None:
        self.values: dict[str, Any] = {
            "low": 1.0,
            "high": 2.0,
            "rays": 360,
            "name": "robot",
            "on": True,
            "mount": [0.0, 0.0, 0.0],
            "fixed": 7,
        }

    def read(self) -> dict[str, Any]:
        return dict(self.values)

    def write(self, new: dict[str, Any]) -> None:
        if not new["low"] < new["high"]:
            msg = "low must be below high"
            raise ValueError(msg)
        self.values = dict(new)


@pytest.fixture
def backing() -> Settings:
    return Settings()


@pytest.fixture
def store(backing: Settings) -> ParameterStore:
    params = ParameterStore()
    params.add(
        ParamNode(
            "/node",
            backing.read,
            backing.write,
            descriptions={"fixed": "set it in the file"},
            read_only=frozenset({"fixed"}),
        )
    )
    return params


@pytest.mark.parametrize(
    ("value", "kind"),
    [
        (True, PARAMETER_BOOL),
        (3, PARAMETER_INTEGER),
        (3.0, PARAMETER_DOUBLE),
        ("x", PARAMETER_STRING),
        ([1.0], PARAMETER_DOUBLE_ARRAY),
        (None, PARAMETER_NOT_SET),
    ],
)
def test_param_type_follows_the_python_value(value: object, kind: int) -> None:
    assert param_type(value) == kind


def test_values_are_coerced_to_the_type_they_have(store: ParameterStore) -> None:
    """An int for a double becomes a float; 360.0 for an integer becomes 360."""
    store.set("node", {"high": 3, "rays": 720.0, "mount": [1, 2, 3]})
    assert store.get("/node", "high") == 3.0 and isinstance(store.get("/node", "high"), float)
    assert store.get("/node", "rays") == 720 and isinstance(store.get("/node", "rays"), int)
    assert store.get("/node", "mount") == [1.0, 2.0, 3.0]


@pytest.mark.parametrize(
    ("changes", "why"),
    [
        ({"rays": 2.5}, "parameter rays is an integer; got 2.5"),
        ({"high": float("nan")}, "parameter high must be finite; got nan"),
        ({"high": "3"}, "parameter high is a number; got '3'"),
        ({"on": 1}, "parameter on has type bool; got int 1"),
        ({"mount": [0.0, 1.0]}, "parameter mount needs 3 numbers; got 2"),
        ({"mount": [0.0, float("inf"), 1.0]}, "parameter mount needs finite numbers; got inf"),
        ({"nope": 1}, "node /node has no parameter 'nope'"),
        ({"fixed": 8}, "parameter fixed of /node is read-only at run time: set it in the file"),
        ({"low": 5.0}, "invalid value for high, low: low must be below high"),
    ],
)
def test_a_refused_change_says_why_and_changes_nothing(
    store: ParameterStore, backing: Settings, changes: dict[str, Any], why: str
) -> None:
    before = backing.read()
    with pytest.raises(ServiceError) as err:
        store.set("/node", {"high": 4.0, **changes})
    assert str(err.value) == why
    assert backing.read() == before


def test_on_change_hears_the_names_that_changed(store: ParameterStore) -> None:
    heard: list[list[str]] = []
    store.node("node").on_change.append(heard.append)
    store.set("/node", {"high": 2.0, "low": 0.5})
    assert heard == [["low"]]


def test_the_store_tells_its_listeners_of_every_nodes_change(store: ParameterStore) -> None:
    """The store's on_change (a front end showing every node's parameters) hears each node."""
    heard: list[tuple[str, list[str]]] = []
    store.on_change.append(lambda node, names: heard.append((node, names)))
    store.set("/node", {"high": 2.0, "low": 0.5})
    assert heard == [("/node", ["low"])]


def test_unknown_node_lists_the_known_ones(store: ParameterStore) -> None:
    with pytest.raises(ServiceError, match=r"node /other has no parameters \(known: /node\)"):
        store.names("other")
    assert store.names("/node") == ["fixed", "high", "low", "mount", "name", "on", "rays"]


def test_adding_a_node_tells_the_listeners(store: ParameterStore, backing: Settings) -> None:
    """on_add is how rosapi offers each node's rcl_interfaces services."""
    added: list[str] = []
    store.on_add.append(lambda node: added.append(node.name))
    store.add(ParamNode("/second", backing.read, backing.write))
    assert added == ["/second"]
