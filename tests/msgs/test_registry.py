from __future__ import annotations

import json
import subprocess
import sys

import pytest

from simbridge.errors import TypeNotFoundError
from simbridge.msgs import TypeRegistry, normalize_type, short_type
from tests.helpers import TIMEOUT_FACTOR


@pytest.mark.parametrize(
    ("given", "canonical"),
    [
        ("geometry_msgs/Twist", "geometry_msgs/msg/Twist"),
        ("geometry_msgs/msg/Twist", "geometry_msgs/msg/Twist"),
        ("/geometry_msgs//Twist", "geometry_msgs/msg/Twist"),
        ("std_srvs/Empty", "std_srvs/msg/Empty"),
    ],
)
def test_both_type_spellings_normalise_to_pkg_msg_type(given: str, canonical: str) -> None:
    """'pkg/Type' and 'pkg/msg/Type' name the same type, as in rosbridge."""
    assert normalize_type(given) == canonical


@pytest.mark.parametrize(
    "bad", ["Twist", "a/b/c/d", "pkg/foo/Type", "pkg/1Type", "", 3, "a/" + "b" * 300]
)
def test_malformed_type_strings_are_refused(bad: object) -> None:
    """Anything but pkg/Type or pkg/{msg,srv,action}/Type is an error with the expected form."""
    with pytest.raises(TypeNotFoundError, match="type"):
        normalize_type(bad)


def test_every_standard_message_is_known() -> None:
    """Rosbags provides the standard ROS 2 messages."""
    reg = TypeRegistry()
    for name in (
        "sensor_msgs/msg/LaserScan",
        "nav_msgs/Odometry",
        "tf2_msgs/msg/TFMessage",
        "rcl_interfaces/msg/Log",
        "visualization_msgs/msg/MarkerArray",
    ):
        assert reg.known(name)
    assert not reg.known("my_pkg/msg/Nope")
    assert not reg.known("garbage")


def test_spec_lists_fields_with_rosapi_array_lengths() -> None:
    """Fields carry -1 for scalars, 0 for sequences, N for fixed arrays."""
    spec = TypeRegistry().spec("nav_msgs/msg/Odometry")
    assert [f.name for f in spec.fields] == ["header", "child_frame_id", "pose", "twist"]
    pose = TypeRegistry().spec("geometry_msgs/msg/PoseWithCovariance")
    cov = pose.fields[1]
    assert (cov.name, cov.base, cov.arraylen) == ("covariance", "float64", 36)
    scan = TypeRegistry().spec("sensor_msgs/LaserScan")
    ranges = next(f for f in scan.fields if f.name == "ranges")
    assert (ranges.base, ranges.arraylen, ranges.nested) == ("float32", 0, False)


def test_unknown_type_spec_raises() -> None:
    """spec() of an unknown type names it."""
    with pytest.raises(TypeNotFoundError, match="my_pkg/Nope"):
        TypeRegistry().spec("my_pkg/Nope")


def test_definition_text_has_msg_sections_for_dependencies() -> None:
    """Full text: the type's fields, then each dependency once under 'MSG: pkg/Type'."""
    text = TypeRegistry().definition_text("nav_msgs/msg/Odometry")
    assert text.startswith("std_msgs/Header header\n")
    assert "\n" + "=" * 80 + "\nMSG: std_msgs/Header\n" in text
    assert text.count("MSG: geometry_msgs/Point\n") == 1
    assert "float64[36] covariance" in text


def test_registering_a_service_part_makes_it_known() -> None:
    """Interfaces rosbags lacks are registered from .msg text."""
    reg = TypeRegistry()
    reg.register_msg("example_interfaces/srv/AddTwoInts_Request", "int64 a\nint64 b\n")
    spec = reg.spec("example_interfaces/srv/AddTwoInts_Request")
    assert [(f.name, f.base) for f in spec.fields] == [("a", "int64"), ("b", "int64")]


def test_short_type_drops_the_interface_kind() -> None:
    """pkg/msg/Type -> pkg/Type (rosapi TypeDef spelling)."""
    assert short_type("std_msgs/msg/Header") == "std_msgs/Header"
    assert short_type("std_msgs/Header") == "std_msgs/Header"


def test_definition_text_is_cached_and_registration_invalidates_it() -> None:
    """The same text object comes back; a newly registered type gets its own text."""
    registry = TypeRegistry()
    first = registry.definition_text("nav_msgs/msg/Odometry")
    assert registry.definition_text("nav_msgs/Odometry") is first
    registry.register_msg("my_pkg/msg/Probe", "geometry_msgs/Point p")
    assert registry.definition_text("my_pkg/msg/Probe").startswith("geometry_msgs/Point p\n")
    assert registry.definition_text("nav_msgs/msg/Odometry") == first


def test_interfaces_are_generated_only_when_a_lookup_needs_one() -> None:
    """Standard lookups and has_service leave them pending; any interface lookup adds them all."""
    registry = TypeRegistry()
    assert registry.known("nav_msgs/Odometry")
    assert registry.has_service("std_srvs/srv/Trigger")
    assert "std_srvs/srv/Trigger_Request" not in registry._defs
    assert registry.service("std_srvs/Trigger") == (
        "std_srvs/srv/Trigger_Request",
        "std_srvs/srv/Trigger_Response",
    )
    assert registry.known("rosapi_msgs/msg/TypeDef")
    assert "example_interfaces/action/Fibonacci" in registry.actions


@pytest.mark.parametrize(
    "first",
    [
        lambda r: r.known("rosapi_msgs/TypeDef"),
        lambda r: r.spec("std_srvs/srv/SetBool_Request"),
        lambda r: r.action("example_interfaces/action/Fibonacci"),
        lambda r: r.types(),
        lambda r: r.store,
        lambda r: r.services,
    ],
)
def test_any_first_lookup_of_an_interface_finds_it(first: object) -> None:
    """Whichever lookup comes first, the interfaces are there for it and for the next ones."""
    registry = TypeRegistry()
    assert callable(first)
    first(registry)
    assert "std_srvs/srv/SetBool_Request" in registry.types()
    assert registry.spec("std_srvs/srv/SetBool_Request").fields[0].name == "data"


def test_the_interfaces_listing_does_not_generate_them() -> None:
    """Rosapi's interfaces listing names the pending interfaces without generating them."""
    registry = TypeRegistry()
    listed = registry.interface_names()
    assert "std_srvs/srv/SetBool_Request" not in registry._defs  # still pending
    assert "std_srvs/srv/SetBool" in listed and "std_srvs/srv/SetBool_Request" in listed
    assert listed == sorted([*registry.types(), *registry.services, *registry.actions])
    assert registry.interface_names() == listed


WARMUP = r"""
import json, sys, threading, time
from simbridge.msgs import registry

types = registry.TypeRegistry()
threading.Thread(target=registry.generate_interfaces, daemon=True).start()  # the server's worker
worst, last = 0.0, time.perf_counter()
while registry._INTERFACES is None:  # the loop's turns while the thread generates them
    time.sleep(0.002)
    now = time.perf_counter()
    worst, last = max(worst, now - last), now
start = time.perf_counter()
spec = types.spec("std_srvs/srv/SetBool_Request")
lookup = time.perf_counter() - start
print(json.dumps({"worst": worst, "lookup": lookup, "field": spec.fields[0].name}))
"""


def test_interfaces_are_generated_in_a_thread_that_leaves_the_loop_its_turns() -> None:
    """generate_interfaces in a worker thread: the loop's thread runs on; lookups are quick.

    Generated by a client's first rosapi call on the loop, they held it 80-300 ms.
    """
    out = subprocess.run(
        [sys.executable, "-c", WARMUP], capture_output=True, text=True, check=True, timeout=60
    )
    result = json.loads(out.stdout)
    assert result["field"] == "data"
    assert result["worst"] < 0.03 * TIMEOUT_FACTOR, result
    assert result["lookup"] < 0.01 * TIMEOUT_FACTOR, result
