"""``simbridge topic|service|param``: the ``ros2`` command line against any rosbridge URL.

The arguments are those of ``ros2`` (messages and values in YAML), so what a course sheet
says for ``ros2`` works unchanged against the simulation or the real robot's rosbridge::

    simbridge topic list -t
    simbridge topic echo /odom --once
    simbridge topic hz /scan --window 20
    simbridge topic pub /cmd_vel geometry_msgs/msg/Twist "{linear: {x: 0.2}}" --once
    simbridge service call /sim/pause std_srvs/srv/SetBool "{data: true}"
    simbridge param get /virtual_robot robot.max_linear_velocity
    simbridge param set /virtual_robot robot.max_linear_velocity 0.3

Every command takes ``--url`` (default ``$SIMBRIDGE_URL`` or ``ws://127.0.0.1:9090``). Errors
go to stderr with exit code 1; Ctrl-C ends ``echo``, ``hz`` and ``pub`` with exit code 0. ``echo``
and ``hz`` of a topic nobody publishes (and no type given) warn as ``ros2`` does and wait for it.
"""

from __future__ import annotations

import argparse
import asyncio
import itertools
import json
import math
import os
import sys
import time
from collections import deque
from collections.abc import Awaitable, Callable, Sequence
from typing import Any

import yaml

from simbridge.tools.client import ClientError, RosbridgeClient, run_tool


__all__ = ["DEFAULT_URL", "param_main", "parse_yaml", "service_main", "topic_main"]

#: Where the tools connect unless told otherwise.
DEFAULT_URL = "ws://127.0.0.1:9090"


def parse_yaml(text: str | None, what: str) -> Any:
    """Parse a YAML message or value as ``ros2`` does (empty means ``{}``).

    Raises:
        ClientError: the text is not YAML.
    """
    if text is None or not text.strip():
        return {}
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as err:
        msg = f"{what} is not valid YAML: {text!r} ({err})"
        raise ClientError(msg) from None


def _dump(value: Any) -> str:
    return yaml.safe_dump(value, sort_keys=False, default_flow_style=False, width=1000).rstrip()


def _flow(value: Any) -> str:
    return yaml.safe_dump(value, sort_keys=False, default_flow_style=True, width=1000).strip()


def _url_parent() -> argparse.ArgumentParser:
    parent = argparse.ArgumentParser(add_help=False)
    parent.add_argument(
        "--url",
        default=os.environ.get("SIMBRIDGE_URL", DEFAULT_URL),
        help=f"rosbridge server (default: $SIMBRIDGE_URL or {DEFAULT_URL})",
    )
    parent.add_argument(
        "--timeout",
        type=float,
        default=5.0,
        help="seconds to wait for the connection and for replies (default: 5)",
    )
    return parent


def _run(
    args: argparse.Namespace, work: Callable[[RosbridgeClient, argparse.Namespace], Awaitable[int]]
) -> int:
    async def main() -> int:
        async with RosbridgeClient.connect(args.url, args.timeout) as ros:
            return await work(ros, args)

    try:
        return run_tool(main())
    except ClientError as err:
        print(f"simbridge: {err}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 0
    except BrokenPipeError:  # `simbridge topic echo /odom | head`
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


# -- topic ------------------------------------------------------------------------------------


async def _topic_list(ros: RosbridgeClient, args: argparse.Namespace) -> int:
    for name, type_name in await ros.topics():
        print(f"{name} [{type_name}]" if args.show_types else name)
    return 0


def _strip_arrays(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _strip_arrays(v) for k, v in value.items()}
    if isinstance(value, list):
        return f"<sequence of length {len(value)}>"
    return value


def _field(msg: Any, path: str | None) -> Any:
    if not path:
        return msg
    value = msg
    for part in path.split("."):
        if not isinstance(value, dict) or part not in value:
            err = f"message has no field '{path}'"
            raise ClientError(err)
        value = value[part]
    return value


#: How often ``echo`` and ``hz`` ask again for the type of a topic not published yet (s).
TYPE_POLL = 0.5


async def _subscribe_when_published(
    ros: RosbridgeClient, topic: str, type_name: str | None
) -> asyncio.Queue[dict[str, Any]]:
    """Subscribe to ``topic``; without a type, wait until someone publishes it, as ``ros2``.

    ``ros2 topic echo`` and ``hz`` look the type up in the graph and, when the topic has none
    yet, warn once and poll until it appears (a typo shows at once; Ctrl-C ends the wait).
    """
    if not type_name:
        type_name = await ros.topic_type(topic)
        if not type_name:
            print(f"WARNING: topic [{topic}] does not appear to be published yet", file=sys.stderr)
            sys.stderr.flush()
        while not type_name:
            await asyncio.sleep(TYPE_POLL)
            type_name = await ros.topic_type(topic)
    return await ros.subscribe(topic, type_name)


async def _topic_echo(ros: RosbridgeClient, args: argparse.Namespace) -> int:
    inbox = await _subscribe_when_published(ros, args.topic, args.type)
    limit = 1 if args.once else args.times
    count = 0
    while limit is None or count < limit:
        getter = asyncio.ensure_future(inbox.get())
        closed = asyncio.ensure_future(ros.closed.wait())
        done, _ = await asyncio.wait({getter, closed}, return_when=asyncio.FIRST_COMPLETED)
        if getter not in done:
            getter.cancel()
            msg = "the server closed the connection"
            raise ClientError(msg)
        closed.cancel()
        value = _field(getter.result(), args.field)
        if args.no_arr:
            value = _strip_arrays(value)
        print(_dump(value) if isinstance(value, dict | list) else value)
        print("---", flush=True)
        count += 1
    return 0


def hz_report(stamps: Sequence[float]) -> str | None:
    """Return a ``ros2 topic hz`` report of receive times (seconds), or None below 2."""
    if len(stamps) < 2:
        return None
    gaps = [b - a for a, b in itertools.pairwise(stamps)]
    mean = sum(gaps) / len(gaps)
    std = math.sqrt(sum((g - mean) ** 2 for g in gaps) / len(gaps))
    rate = 1.0 / mean if mean > 0 else math.inf
    return (
        f"average rate: {rate:.3f}\n"
        f"\tmin: {min(gaps):.3f}s max: {max(gaps):.3f}s std dev: {std:.5f}s "
        f"window: {len(stamps)}"
    )


async def _topic_hz(ros: RosbridgeClient, args: argparse.Namespace) -> int:
    start = time.monotonic()
    try:
        waiting = _subscribe_when_published(ros, args.topic, args.type)
        inbox = await asyncio.wait_for(waiting, args.duration)
    except TimeoutError:
        return 0  # --duration ended before anyone published the topic
    stamps: deque[float] = deque(maxlen=args.window)
    next_report = time.monotonic() + 1.0
    reports = 0
    while args.duration is None or time.monotonic() - start < args.duration:
        remaining = next_report - time.monotonic()
        try:
            await asyncio.wait_for(inbox.get(), max(remaining, 0.0))
            stamps.append(time.monotonic())
        except TimeoutError:
            pass
        if time.monotonic() >= next_report:
            next_report += 1.0
            report = hz_report(stamps)
            print(report or "no new messages", flush=True)
            reports += 1
        if ros.closed.is_set():
            msg = "the server closed the connection"
            raise ClientError(msg)
    return 0


async def _topic_pub(ros: RosbridgeClient, args: argparse.Namespace) -> int:
    msg = parse_yaml(args.values, "message")
    if not isinstance(msg, dict):
        err = f"message must be a YAML mapping such as '{{linear: {{x: 0.2}}}}', got {msg!r}"
        raise ClientError(err)
    times = 1 if args.once else args.times
    period = 1.0 / args.rate if args.rate > 0 else 0.0
    print("publisher: beginning loop", flush=True)
    loop = asyncio.get_running_loop()
    start = loop.time()
    count = 0
    while times is None or count < times:
        if count:
            await asyncio.sleep(max(0.0, start + count * period - loop.time()))
        await ros.publish(args.topic, msg, args.type)
        count += 1
        print(f"publishing #{count}: {_flow(msg)}", flush=True)
    # a status error for a bad message comes back quickly; wait for it briefly
    await asyncio.sleep(0.2)
    if ros.errors:
        err = f"the server refused the message: {ros.errors[0]}"
        raise ClientError(err)
    return 0


def topic_main(argv: Sequence[str]) -> int:
    """Run ``simbridge topic ...``; return the exit code."""
    url = _url_parent()
    parser = argparse.ArgumentParser(
        prog="simbridge topic", description="Topics of a rosbridge server, as `ros2 topic`."
    )
    sub = parser.add_subparsers(dest="verb", required=True)
    p = sub.add_parser("list", parents=[url], help="list the topics")
    p.add_argument("-t", "--show-types", action="store_true", help="show each topic's type")
    p = sub.add_parser("echo", parents=[url], help="print a topic's messages (YAML)")
    p.add_argument("topic")
    p.add_argument("type", nargs="?", help="message type (optional)")
    p.add_argument("--once", action="store_true", help="print one message and exit")
    p.add_argument("--times", type=int, default=None, help="exit after N messages")
    p.add_argument("--field", help="print only this field, e.g. pose.pose.position")
    p.add_argument("--no-arr", action="store_true", help="do not print the array fields")
    p = sub.add_parser("hz", parents=[url], help="print a topic's rate once a second")
    p.add_argument("topic")
    p.add_argument("type", nargs="?", help="message type (optional)")
    p.add_argument("-w", "--window", type=int, default=10000, help="messages in the window")
    p.add_argument("--duration", type=float, default=None, help="exit after SECONDS")
    p = sub.add_parser("pub", parents=[url], help="publish a message (YAML)")
    p.add_argument("topic")
    p.add_argument("type", help="message type, e.g. geometry_msgs/msg/Twist")
    p.add_argument("values", nargs="?", default="", help="the message in YAML (default: {})")
    p.add_argument("-r", "--rate", type=float, default=1.0, help="Hz (default: 1)")
    p.add_argument("-1", "--once", action="store_true", help="publish once and exit")
    p.add_argument("-t", "--times", type=int, default=None, help="publish N times and exit")
    args = parser.parse_args(argv)
    work = {"list": _topic_list, "echo": _topic_echo, "hz": _topic_hz, "pub": _topic_pub}
    return _run(args, work[args.verb])


# -- service ----------------------------------------------------------------------------------


async def _service_list(ros: RosbridgeClient, args: argparse.Namespace) -> int:
    values = await ros.call_service("/rosapi/services", {})
    for name in sorted(values.get("services") or []):
        print(name)
    return 0


async def _service_call(ros: RosbridgeClient, args: argparse.Namespace) -> int:
    request = parse_yaml(args.values, "request")
    if not isinstance(request, dict):
        err = f"request must be a YAML mapping such as '{{data: true}}', got {request!r}"
        raise ClientError(err)
    print(f"requester: making request: {_flow(request)}\n", flush=True)
    response = await ros.call_service(args.service, request, timeout=args.timeout)
    print("response:")
    print(_dump(response) if response else "{}")
    return 0


def service_main(argv: Sequence[str]) -> int:
    """Run ``simbridge service ...``; return the exit code."""
    url = _url_parent()
    parser = argparse.ArgumentParser(
        prog="simbridge service", description="Services of a rosbridge server, as `ros2 service`."
    )
    sub = parser.add_subparsers(dest="verb", required=True)
    sub.add_parser("list", parents=[url], help="list the services")
    p = sub.add_parser("call", parents=[url], help="call a service (request in YAML)")
    p.add_argument("service")
    p.add_argument("type", nargs="?", help="service type, e.g. std_srvs/srv/Empty")
    p.add_argument("values", nargs="?", default="", help="the request in YAML (default: {})")
    args = parser.parse_args(argv)
    if args.verb == "call" and args.type and args.type.lstrip().startswith("{") and not args.values:
        args.values, args.type = args.type, None  # the type may be left out
    return _run(args, {"list": _service_list, "call": _service_call}[args.verb])


# -- param ------------------------------------------------------------------------------------


def describe_value(value: Any) -> str:
    """Return ``ros2 param get``'s line for ``value`` ("Double value is: 0.5")."""
    kinds = [(bool, "Boolean"), (int, "Integer"), (float, "Double"), (str, "String")]
    for kind, label in kinds:
        if isinstance(value, kind):
            return f"{label} value is: {value}"
    if isinstance(value, list):
        inner = "Double"
        for kind, label in kinds:
            if value and all(isinstance(v, kind) for v in value):
                inner = label
                break
        return f"{inner} array value is: {value}"
    return f"Value is: {json.dumps(value)}"


def _param_name(node: str, name: str) -> str:
    return f"{node if node.startswith('/') else '/' + node}:{name}"


async def _param_get(ros: RosbridgeClient, args: argparse.Namespace) -> int:
    values = await ros.call_service(
        "/rosapi/get_param", {"name": _param_name(args.node, args.name)}
    )
    if values.get("successful") is False:
        print(f"Parameter not set: {values.get('reason', '')}", file=sys.stderr)
        return 1
    print(describe_value(json.loads(values.get("value") or "null")))
    return 0


async def _param_set(ros: RosbridgeClient, args: argparse.Namespace) -> int:
    value = parse_yaml(args.value, "value")
    request = {"name": _param_name(args.node, args.name), "value": json.dumps(value)}
    values = await ros.call_service("/rosapi/set_param", request)
    if values.get("successful") is False:
        print(f"Setting parameter failed: {values.get('reason', '')}", file=sys.stderr)
        return 1
    print("Set parameter successful")
    return 0


async def _param_list(ros: RosbridgeClient, args: argparse.Namespace) -> int:
    values = await ros.call_service("/rosapi/get_param_names", {})
    by_node: dict[str, list[str]] = {}
    for full in values.get("names") or []:
        node, _, name = str(full).partition(":")
        by_node.setdefault(node, []).append(name)
    wanted = args.node and (args.node if args.node.startswith("/") else "/" + args.node)
    for node in sorted(by_node):
        if wanted and node != wanted:
            continue
        print(f"{node}:")
        for name in sorted(by_node[node]):
            print(f"  {name}")
    return 0


def param_main(argv: Sequence[str]) -> int:
    """Run ``simbridge param ...``; return the exit code."""
    url = _url_parent()
    parser = argparse.ArgumentParser(
        prog="simbridge param",
        description="Node parameters through rosapi, as `ros2 param`.",
    )
    sub = parser.add_subparsers(dest="verb", required=True)
    p = sub.add_parser("list", parents=[url], help="list parameters")
    p.add_argument("node", nargs="?", help="only this node's")
    p = sub.add_parser("get", parents=[url], help="print a parameter")
    p.add_argument("node")
    p.add_argument("name")
    p = sub.add_parser("set", parents=[url], help="set a parameter (value in YAML)")
    p.add_argument("node")
    p.add_argument("name")
    p.add_argument("value")
    args = parser.parse_args(argv)
    return _run(args, {"list": _param_list, "get": _param_get, "set": _param_set}[args.verb])
