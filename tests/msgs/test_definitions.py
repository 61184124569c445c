from __future__ import annotations

import asyncio
import json
import subprocess
import sys
from typing import Any

import cbor2
import pytest
from rosbags.typesys import Stores, TypesysError, get_typestore
from rosbags.typesys.msg import get_types_from_msg
from websockets.asyncio.client import ClientConnection, connect

from simbridge.app.runner import App
from simbridge.errors import TypeNotFoundError
from simbridge.headless import Simulation
from simbridge.msgs import TypeRegistry
from simbridge.msgs.cdr import CdrReader, CdrWriter
from simbridge.msgs.definitions import standard
from tests.helpers import ROOT, TIMEOUT_FACTOR, recv_until, send_json, ws_url


def _plain(value: Any) -> Any:
    """A definition in one form whatever holds it: tuples, nodetypes as ints."""
    if isinstance(value, list | tuple):
        return tuple(_plain(v) for v in value)
    if isinstance(value, int) and not isinstance(value, bool):
        return int(value)
    return value


def _rosbags_store(texts: dict[str, str]) -> Any:
    """The latest rosbags store with ``texts`` registered as the registry did before issue 16."""
    store = get_typestore(Stores.LATEST)
    for name, text in texts.items():
        pkg, _kind, typename = name.split("/")
        key = f"{pkg}/msg/{typename}"
        types = get_types_from_msg(text or "\n", key)
        store.register({name if k == key else k: v for k, v in types.items()})
    return store


def test_the_shipped_file_is_what_the_script_makes_from_the_installed_rosbags() -> None:
    """scripts/definitions.py --check: rosbags upgraded or a text edited fails here until rerun."""
    proc = subprocess.run(
        [sys.executable, "scripts/definitions.py", "--check"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120 * TIMEOUT_FACTOR,
        check=False,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_every_definition_of_a_default_run_is_what_a_rosbags_store_holds() -> None:
    """Standard messages, the robot graph's and the interfaces': fields, constants, full texts."""
    registry = Simulation().graph.registry
    ours = registry.fielddefs  # adds the interfaces
    store = _rosbags_store(registry.texts)
    assert set(ours) == set(store.fielddefs)
    for name in sorted(store.fielddefs):
        assert _plain(ours[name]) == _plain(store.fielddefs[name]), name
        try:
            expected, _md5 = store.generate_msgdef(name, ros_version=2)
        except TypesysError:  # example_interfaces/msg/WString: rosbags reads 'wstring' as a type
            with pytest.raises(TypeNotFoundError):
                registry.definition_text(name)
            continue
        assert registry.definition_text(name) == expected, name


def test_every_standard_message_is_shipped() -> None:
    """Every message of rosbags' latest ROS 2 store, and nothing else, is in the file."""
    assert set(standard()) == set(get_typestore(Stores.LATEST).fielddefs)


TEXTS = {
    "my_pkg/msg/Consts": (
        "int32 A=3\nfloat64 PI=3.14159\nbool ON=true\nstring NAME=robot\n"
        "uint64 BIG=18446744073709551615\nint8 x"
    ),
    "my_pkg/msg/Bounded": (
        "string<=5 s\nstring<=3[2] pair\nint32[<=4] few\nfloat32[9] k\nbyte[] raw\nchar c"
    ),
    "my_pkg/msg/Nested": "Header header\ngeometry_msgs/Point[] points\nConsts c\nBounded[<=2] b",
    "my_pkg/msg/Nothing": "",
    "my_pkg/srv/Do_Request": "# a comment only\n",
}


def test_a_text_not_shipped_is_registered_as_rosbags_registers_it() -> None:
    """Parsed by rosbags: constants, bounds, nested and relative names, empty messages."""
    registry = TypeRegistry()
    for name, text in TEXTS.items():
        registry.register_msg(name, text)
    store = _rosbags_store(TEXTS)
    for name in TEXTS:
        assert _plain(registry.fielddefs[name]) == _plain(store.fielddefs[name]), name
        expected, _md5 = store.generate_msgdef(name, ros_version=2)
        assert registry.definition_text(name) == expected, name
    assert [c[0] for c in registry.spec("my_pkg/Consts").constants][:2] == ["A", "PI"]
    assert registry.spec("my_pkg/msg/Nothing").fields == ()


def test_a_name_registered_again_with_other_fields_is_refused_as_rosbags_refuses_it() -> None:
    """The same fields again are taken (kept as they were); other fields raise rosbags' error."""
    registry = TypeRegistry()
    registry.register_msg("my_pkg/msg/Twice", "int32 a")
    registry.register_msg("my_pkg/msg/Twice", "int32 A")
    with pytest.raises(TypesysError, match="'my_pkg/msg/Twice' is already present"):
        registry.register_msg("my_pkg/msg/Twice", "int64 a")
    with pytest.raises(TypesysError, match="'geometry_msgs/msg/Point' is already present"):
        registry.register_msg("geometry_msgs/msg/Point", "float64 x")
    assert [f.base for f in registry.spec("my_pkg/Twice").fields] == ["int32"]


def test_the_type_store_is_made_on_first_use_with_every_type_registered_before_and_after() -> None:
    """A type registered before the store was made, and one after, both serialized by rosbags."""
    registry = TypeRegistry()
    registry.register_msg("my_pkg/msg/Before", "string name\nint32 n")
    assert registry._store is None
    store = registry.store
    registry.register_msg("my_pkg/msg/After", "my_pkg/Before[] items")
    writer, reader = CdrWriter(registry), CdrReader(registry)
    msg = {"items": [{"name": "a", "n": 1}, {"name": "b", "n": 2}]}
    data = writer.serialize_with_rosbags("my_pkg/msg/After", msg)
    assert data == writer.serialize("my_pkg/msg/After", msg)
    assert reader.read_with_rosbags("my_pkg/msg/After", data) == msg
    assert store.deserialize_cdr(data, "my_pkg/msg/After").items[1].name == "b"
    assert registry.store is store


WITHOUT_STORE = r"""
import json, sys
from simbridge.msgs import Converter, TypeRegistry, typedefs
from simbridge.msgs.cdr import CdrReader, CdrWriter

registry = TypeRegistry()
convert = Converter(registry, lambda: (0, 0))
writer, reader = CdrWriter(registry), CdrReader(registry)
out = {}
for name in ("nav_msgs/msg/Odometry", "sensor_msgs/msg/LaserScan", "tf2_msgs/msg/TFMessage",
             "visualization_msgs/msg/MarkerArray", "rosapi_msgs/srv/Topics_Response",
             "trajectory_msgs/msg/JointTrajectory"):
    msg = convert.from_json(name, {})
    assert reader.read(name, writer.serialize(name, msg)).keys() == msg.keys()
    out[name] = len(typedefs(registry, name))
    registry.definition_text(name)
out["listed"] = len(registry.interface_names())
out["before"] = sorted(m for m in sys.modules if m.startswith("rosbags"))
registry.register_srv("my_pkg/srv/Add", "int64 a\nint64 b\n---\nint64 sum")
out["after"] = sorted(m for m in sys.modules if m.startswith("rosbags"))
print(json.dumps(out))
"""


def test_lookups_validation_rosapi_and_cdr_import_no_rosbags() -> None:
    """Standard and interface types: typedefs, full texts, CDR both ways, without rosbags.

    Only a new text imports rosbags' parser (to parse it), never its type store.
    """
    proc = subprocess.run(
        [sys.executable, "-c", WITHOUT_STORE],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60 * TIMEOUT_FACTOR,
        check=True,
    )
    out = json.loads(proc.stdout)
    assert out["nav_msgs/msg/Odometry"] == 10
    assert out["listed"] > 300
    assert out["before"] == []
    assert "rosbags.typesys.msg" in out["after"]  # my_pkg/srv/Add's texts were parsed
    assert [m for m in out["after"] if m.startswith("rosbags.typesys.stores.")] == []


async def _call(conn: ClientConnection, service: str, args: Any) -> Any:
    await send_json(conn, {"op": "call_service", "id": service, "service": service, "args": args})
    reply = await recv_until(conn, lambda m: m.get("op") == "service_response", 10)
    assert reply["result"] is True, reply
    return reply["values"]


PROBE_TEXT = "int32 LIMIT=3\nstring<=8 name\ngeometry_msgs/Point[] path\nstd_msgs/Header header"


async def test_a_type_not_shipped_works_end_to_end(app: App) -> None:
    """A type registered from a text simbridge does not ship parsed works like any other.

    rosbags parses the text; a client publishes it, another receives it in JSON and cbor-raw
    (rosbags' bytes), rosapi gives its typedef and raw definition (rosbags' text).
    """
    app.graph.registry.register_msg("my_pkg/msg/Probe", PROBE_TEXT)
    sent = {
        "name": "probe",
        "path": [{"x": 1.0, "y": 2.0, "z": 0.0}],
        "header": {"frame_id": "map"},
    }
    async with (
        connect(ws_url(app)) as page,
        connect(ws_url(app)) as raw,
        connect(ws_url(app)) as other,
    ):
        await send_json(other, {"op": "advertise", "topic": "/probe", "type": "my_pkg/Probe"})
        await send_json(page, {"op": "subscribe", "topic": "/probe", "type": "my_pkg/Probe"})
        await send_json(raw, {"op": "subscribe", "topic": "/probe", "compression": "cbor-raw"})
        for conn in (other, page, raw):  # each one's op is carried out before the publication
            await _call(conn, "/rosapi/topics", {})
        await send_json(other, {"op": "publish", "topic": "/probe", "msg": sent})
        received = (await recv_until(page, lambda m: m.get("topic") == "/probe", 10))["msg"]
        data = cbor2.loads(await asyncio.wait_for(raw.recv(), 10 * TIMEOUT_FACTOR))["msg"]["bytes"]
        details = await _call(page, "/rosapi/message_details", {"type": "my_pkg/Probe"})
        listed = await _call(page, "/rosapi/topics_and_raw_types", {})
    assert received["path"] == sent["path"] and received["header"]["frame_id"] == "map"
    decoded = app.graph.registry.store.deserialize_cdr(data, "my_pkg/msg/Probe")
    assert (decoded.name, decoded.path[0].y, decoded.header.frame_id) == ("probe", 2.0, "map")
    probe = details["typedefs"][0]
    assert (probe["type"], probe["constnames"], probe["constvalues"]) == (
        "my_pkg/Probe",
        ["LIMIT"],
        ["3"],
    )
    assert [t["type"] for t in details["typedefs"][1:]] == [
        "geometry_msgs/Point",
        "std_msgs/Header",
        "builtin_interfaces/Time",
    ]
    text = listed["typedefs_full_text"][listed["topics"].index("/probe")]
    store = _rosbags_store({"my_pkg/msg/Probe": PROBE_TEXT})
    assert text == store.generate_msgdef("my_pkg/msg/Probe", ros_version=2)[0]
