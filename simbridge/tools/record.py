"""``simbridge record`` and ``simbridge replay``: rosbag2 MCAP bags of any rosbridge server.

``record`` subscribes (as a rosbridge client) to the given topics, or every topic with ``-a``,
and writes what arrives to a rosbag2 MCAP bag (:class:`~simbridge.tools.bag.BagWriter`), each
message stamped with its receive time as ``ros2 bag record`` does. It stops on Ctrl-C or
SIGTERM (then joins the bag into one ``NAME.mcap``) or after ``--stop-after`` seconds; killed
outright, the bag still reads up to the last second.

``replay`` publishes a bag's ``/cmd_vel`` (or ``--topic``) again with the recorded timing, to
any rosbridge URL; with ``--headless -o OUT`` it instead drives a headless simulation with them
(as fast as it runs) and records its ``/odom``, ``/tf`` and ``/cmd_vel`` into ``OUT``, stamped
on the source bag's time line: the simulated counterpart of a real run, ready for
``simbridge compare``.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import os
import signal
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from simbridge.app.config import Params, WorldSpec
from simbridge.errors import SimbridgeError
from simbridge.msgs import Converter, TypeRegistry
from simbridge.robot.cmdvel import command_type, convert_twist
from simbridge.tools.bag import BagError, BagWriter, read_messages
from simbridge.tools.client import ClientError, RosbridgeClient, run_tool
from simbridge.tools.rostool import DEFAULT_URL


__all__ = ["record", "record_main", "replay_headless", "replay_main"]


def _wall_stamp() -> tuple[int, int]:
    sec, nanosec = divmod(time.time_ns(), 1_000_000_000)
    return sec, nanosec


async def record(
    url: str,
    out: Path,
    topics: Sequence[str] | None,
    stop: asyncio.Event,
    *,
    segment_seconds: float = 1.0,
    timeout: float = 5.0,
    ready: asyncio.Event | None = None,
) -> BagWriter:
    """Record ``topics`` (None: every topic, also those appearing later) until ``stop``.

    Raises:
        ClientError: the server cannot be reached.
        BagError: ``out`` exists.
    """
    registry = TypeRegistry()
    converter = Converter(registry, _wall_stamp)
    async with RosbridgeClient.connect(url, timeout) as ros:
        writer = BagWriter(out, registry, segment_seconds=segment_seconds)
        types: dict[str, str] = {}
        skipped: set[str] = set()
        tasks: dict[str, asyncio.Task[None]] = {}

        async def drain(topic: str, inbox: asyncio.Queue[dict[str, Any]]) -> None:
            while True:
                msg = await inbox.get()
                stamp = time.time_ns()
                type_name = types.get(topic) or await ros.topic_type(topic)
                if not type_name or not registry.known(type_name):
                    if topic not in skipped:
                        skipped.add(topic)
                        why = f"type {type_name} is unknown" if type_name else "no type"
                        print(f"simbridge record: skipping {topic}: {why}", file=sys.stderr)
                    continue
                types[topic] = type_name
                try:
                    canonical = converter.from_json(type_name, msg)
                except SimbridgeError as err:
                    print(f"simbridge record: {topic}: message skipped: {err}", file=sys.stderr)
                    continue
                writer.write(topic, type_name, canonical, stamp)

        async def follow(topic: str) -> None:
            if topic in tasks:
                return
            inbox = await ros.subscribe(topic, types.get(topic) or None)
            tasks[topic] = asyncio.create_task(drain(topic, inbox))

        listed = dict(await ros.topics())
        types.update({k: v for k, v in listed.items() if v})
        for topic in listed if topics is None else topics:
            await follow(topic)
        if ready is not None:
            ready.set()
        last_poll = time.monotonic()
        try:
            while not stop.is_set() and not ros.closed.is_set():
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(stop.wait(), 0.1)
                writer.tick()
                if topics is None and time.monotonic() - last_poll > 2.0:
                    last_poll = time.monotonic()
                    for name, type_name in await ros.topics():
                        if type_name:
                            types.setdefault(name, type_name)
                        await follow(name)
        finally:
            for task in tasks.values():
                task.cancel()
            await asyncio.gather(*tasks.values(), return_exceptions=True)
            writer.close()
    return writer


def _default_name() -> str:
    return time.strftime("rosbag2_%Y_%m_%d-%H_%M_%S")


def record_main(argv: Sequence[str]) -> int:
    """Run ``simbridge record``; return the exit code."""
    parser = argparse.ArgumentParser(
        prog="simbridge record",
        description="Record topics of a rosbridge server into a rosbag2 MCAP bag "
        "(as `ros2 bag record`). Ctrl-C stops and finalises it.",
    )
    parser.add_argument("topics", nargs="*", help="topics to record")
    parser.add_argument("-a", "--all", action="store_true", help="record every topic")
    parser.add_argument("-o", "--output", help="bag directory (default: rosbag2_<date>-<time>)")
    parser.add_argument(
        "--url",
        default=os.environ.get("SIMBRIDGE_URL", DEFAULT_URL),
        help=f"rosbridge server (default: $SIMBRIDGE_URL or {DEFAULT_URL})",
    )
    parser.add_argument("--stop-after", type=float, default=None, help="stop after SECONDS")
    parser.add_argument(
        "--segment",
        type=float,
        default=1.0,
        help="seconds per closed segment: what a killed recorder may lose (default: 1)",
    )
    parser.add_argument("--timeout", type=float, default=5.0, help="connect timeout, seconds")
    args = parser.parse_args(argv)
    if not args.all and not args.topics:
        parser.error("give topics to record, or -a for all of them")
    out = Path(args.output or _default_name())

    async def main() -> BagWriter:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stop.set)
        if args.stop_after is not None:
            loop.call_later(args.stop_after, stop.set)
        ready = asyncio.Event()

        async def announce() -> None:
            await ready.wait()
            print(f"recording to {out}/ (Ctrl-C to stop)", file=sys.stderr, flush=True)

        note = asyncio.create_task(announce())
        try:
            return await record(
                args.url,
                out,
                None if args.all else args.topics,
                stop,
                segment_seconds=args.segment,
                timeout=args.timeout,
                ready=ready,
            )
        finally:
            note.cancel()

    try:
        writer = asyncio.run(main())
    except (ClientError, BagError) as err:
        print(f"simbridge: {err}", file=sys.stderr)
        return 1
    print(f"recorded {writer.count} messages to {out}/", flush=True)
    return 0


# -- replay -------------------------------------------------------------------------------------


def _commands(bag: str, topic: str) -> list[tuple[int, str, dict[str, Any]]]:
    found = [(stamp, type_name, msg) for _, type_name, stamp, msg in read_messages(bag, {topic})]
    if not found:
        msg = f"bag '{bag}' has no messages on {topic}"
        raise BagError(msg)
    return found


async def replay(url: str, bag: str, topic: str, rate: float, timeout: float) -> int:
    """Publish ``topic`` of ``bag`` to ``url`` with the recorded spacing; return the count.

    Twist commands go to a TwistStamped topic as TwistStamped (stamped now), and back.
    """
    commands = _commands(bag, topic)
    async with RosbridgeClient.connect(url, timeout) as ros:
        try:  # a Twist bag into a TwistStamped robot (or back) is converted
            target = await ros.topic_type(topic)
        except ClientError:
            target = ""
        loop = asyncio.get_running_loop()
        start = loop.time()
        first = commands[0][0]
        for stamp, type_name, msg in commands:
            due = start + (stamp - first) / 1e9 / rate
            await asyncio.sleep(max(0.0, due - loop.time()))
            kind = command_type(type_name, target)
            await ros.publish(topic, convert_twist(msg, type_name, kind, _wall_stamp()), kind)
        await asyncio.sleep(0.2)  # let the last one leave before closing
    return len(commands)


def replay_headless(
    bag: str,
    out: Path,
    *,
    topic: str = "/cmd_vel",
    world: WorldSpec | str | None = None,
    params: Params | str | None = None,
    tail: float = 2.0,
) -> BagWriter:
    """Drive a headless simulation with a bag's commands; record it into ``out``.

    Commands apply at the first step at or after their recorded time; the run lasts until
    ``tail`` seconds after the last command. Stamps are the source bag's time line.
    """
    from simbridge.headless import Simulation  # the server-less path only

    commands = _commands(bag, topic)
    base = commands[0][0]
    sim = Simulation(world, params, stamp_origin_ns=base)  # headers = log times
    writer = BagWriter(out, sim.graph.registry, segment_seconds=1e9)

    def recorder(name: str, type_name: str) -> Any:
        def on_msg(msg: Any, source: object) -> None:
            writer.write(name, type_name, msg, base + round(sim.time * 1e9))

        return on_msg

    for name in ("/odom", "/tf", topic):
        found = sim.graph.topics.topics.get(name)
        type_name = found.type if found is not None and found.type else commands[0][1]
        sim.graph.subscribe(name, type_name, "/replay", recorder(name, type_name))
    end = (commands[-1][0] - base) / 1e9 + tail
    i = 0
    found = sim.graph.topics.topics.get(topic)
    target = found.type if found is not None and found.type else None
    while sim.time < end - 1e-9:
        now_ns = base + round(sim.time * 1e9)
        while i < len(commands) and commands[i][0] <= now_ns:
            stamp, type_name, msg = commands[i]
            kind = command_type(type_name, target)
            sim.publish(topic, convert_twist(msg, type_name, kind, divmod(stamp, 10**9)), kind)
            i += 1
        sim.step()
    writer.close()
    return writer


def replay_main(argv: Sequence[str]) -> int:
    """Run ``simbridge replay``; return the exit code."""
    parser = argparse.ArgumentParser(
        prog="simbridge replay",
        description="Publish a bag's velocity commands again, with their recorded timing, to a "
        "rosbridge server, or drive a headless simulation with them (--headless -o OUT).",
    )
    parser.add_argument("bag", help="bag directory or .mcap file")
    parser.add_argument("--topic", default="/cmd_vel", help="topic to replay (default /cmd_vel)")
    parser.add_argument(
        "--url",
        default=os.environ.get("SIMBRIDGE_URL", DEFAULT_URL),
        help=f"rosbridge server (default: $SIMBRIDGE_URL or {DEFAULT_URL})",
    )
    parser.add_argument("--rate", type=float, default=1.0, help="playback speed (default 1)")
    parser.add_argument("--timeout", type=float, default=5.0, help="connect timeout, seconds")
    parser.add_argument(
        "--headless", action="store_true", help="simulate without a server, as fast as possible"
    )
    parser.add_argument("-o", "--output", help="with --headless: the bag to write")
    parser.add_argument("--world", help="with --headless: world file")
    parser.add_argument("--params", help="with --headless: parameter file")
    args = parser.parse_args(argv)
    try:
        if args.headless:
            if not args.output:
                parser.error("--headless needs -o OUT, the bag to write")
            writer = replay_headless(
                args.bag, Path(args.output), topic=args.topic, world=args.world, params=args.params
            )
            print(f"simulated: {writer.count} messages to {args.output}/")
            return 0
        if args.rate <= 0:
            parser.error("--rate must be positive")
        count = run_tool(replay(args.url, args.bag, args.topic, args.rate, args.timeout))
    except SimbridgeError as err:
        print(f"simbridge: {err}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130
    print(f"replayed {count} messages of {args.topic}")
    return 0
