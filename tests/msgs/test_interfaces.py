from __future__ import annotations

import pytest

from simbridge.errors import TypeNotFoundError
from simbridge.msgs import TypeRegistry
from simbridge.msgs.interfaces import ACTIONS, SERVICES


def test_every_service_and_action_is_registered_with_its_parts() -> None:
    """Each .srv gives _Request/_Response, each .action _Goal/_Result/_Feedback messages."""
    registry = TypeRegistry()
    for name in SERVICES:
        request, response = registry.service(name)
        assert registry.known(request) and registry.known(response)
    for name in ACTIONS:
        assert all(registry.known(part) for part in registry.action(name))


@pytest.mark.parametrize(
    ("service", "request_fields", "response_fields"),
    [
        ("std_srvs/Empty", [], []),
        ("std_srvs/srv/Trigger", [], ["success", "message"]),
        ("example_interfaces/AddTwoInts", ["a", "b"], ["sum"]),
        ("rcl_interfaces/srv/GetParameters", ["names"], ["values"]),
        ("rosapi_msgs/srv/TopicsAndRawTypes", [], ["topics", "types", "typedefs_full_text"]),
        (
            "tf2_web_republisher/RepublishTFs",
            ["source_frames", "target_frame", "angular_thres", "trans_thres", "rate", "timeout"],
            ["topic_name"],
        ),
    ],
)
def test_service_field_lists(
    service: str, request_fields: list[str], response_fields: list[str]
) -> None:
    """Field names and order are the public interfaces' (list args are zipped in this order)."""
    registry = TypeRegistry()
    request, response = registry.service(service)
    assert [f.name for f in registry.spec(request).fields] == request_fields
    assert [f.name for f in registry.spec(response).fields] == response_fields


def test_fibonacci_and_unknown_types() -> None:
    """Fibonacci: order -> sequence; unknown interfaces raise TypeNotFoundError."""
    registry = TypeRegistry()
    goal, _result, feedback = registry.action("example_interfaces/Fibonacci")
    assert [f.name for f in registry.spec(goal).fields] == ["order"]
    assert registry.spec(feedback).fields[0].arraylen == 0
    with pytest.raises(TypeNotFoundError):
        registry.service("my_pkg/srv/Nope")
    with pytest.raises(TypeNotFoundError):
        registry.action("my_pkg/Nope")
