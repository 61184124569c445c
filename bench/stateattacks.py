"""Protocol-state attacks of issue 17 (one client each), for ``python -m bench hostile``.

Each attack is an ``async`` function ``attack(url, stop) -> str`` that drives one hostile
client (row 7: five) against a running server until ``stop`` is set or it has sent everything,
and returns a one-line account of what it sent and what the server answered. ``url(who)`` is
the rosbridge URL for ``"student"`` (a student's token, robot r1), ``"admin"`` or ``None`` (no
token). The rows are those
of the issue's table:

1. never-completed fragments with fresh ids, before authenticating;
2. 44,000 subscribe ids on one topic (student token);
3. advertise ids on one topic, fresh ids without end;
4. calls with ``timeout: 0`` to a service the attacker provides and never answers;
5. 100 latched 9.9 MB messages;
6. a client that reads nothing and floods ``/rosapi/interfaces`` calls;
7. fragment sets of 4-byte characters from five clients;
16. lone surrogates in a latched message, then a new subscriber;
17. 10 MB frames back to back;
18. float32 ``1e308`` published to a cbor-raw subscriber;
20. a topic name with a NUL.

``python -m bench hostile`` runs them as ``state1`` .. ``state20`` beside the other rows of the
issue; ``python -m bench.stateattacks [ROW ...]`` runs them alone (a server process per attack, an
observer thread counting /odom by its header stamps), as the before/after figures of issue 17.
"""

from __future__ import annotations

import asyncio
import itertools
import json
import os
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Coroutine
from pathlib import Path
from typing import Any

from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect as sync_connect

from bench._server import server
from tests.helpers import unread_socket


#: The attacker's student token (scope r1) and the observer's admin token.
STUDENT = "student-token-r1"
ADMIN = "admin-token-observer"
#: ``who`` ("student", "admin" or None) -> the URL to connect to with that token.
Url = Callable[[str | None], str]
Attack = Callable[[Url, asyncio.Event], Coroutine[Any, Any, str]]
MB = 1_000_000


async def _drain(ws: ClientConnection, answers: dict[str, int]) -> None:
    """Read (and count by kind) what the server sends, so the attacker is not a slow reader."""
    try:
        async for data in ws:
            if isinstance(data, bytes):
                answers["binary"] = answers.get("binary", 0) + 1
                continue
            msg = json.loads(data)
            kind = msg.get("op", "?")
            if kind == "status":
                text = str(msg.get("msg", ""))
                kind = "status: " + text[:90]
            answers[kind] = answers.get(kind, 0) + 1
    except ConnectionClosed:
        pass


def _summary(sent: int, what: str, answers: dict[str, int]) -> str:
    top = sorted(answers.items(), key=lambda kv: -kv[1])[:3]
    said = "; ".join(f"{n} x {k!r}" for k, n in top) or "nothing"
    return f"sent {sent} {what}; answers: {said}"


async def _flood(
    url: str,
    stop: asyncio.Event,
    frames: Callable[[int], str | bytes],
    what: str,
    limit: int,
    per_frame: int = 1,
) -> str:
    """Send ``frames(i)`` for i = 0.. until ``limit`` or ``stop``; read replies meanwhile.

    ``per_frame`` ops go in one WebSocket message (rosbridge reads concatenated JSON; the
    server's message_rate counts messages, not ops).
    """
    answers: dict[str, int] = {}
    sent = 0
    try:
        async with connect(url, max_size=None, open_timeout=10, close_timeout=1) as ws:
            reader = asyncio.create_task(_drain(ws, answers))
            for i in range(0, limit, per_frame):
                if stop.is_set() or reader.done():
                    break
                if per_frame == 1:
                    await ws.send(frames(i))
                else:
                    end = min(limit, i + per_frame)
                    await ws.send("".join(str(frames(k)) for k in range(i, end)))
                sent += min(per_frame, limit - i)
                if i % (32 * per_frame) == 0:
                    await asyncio.sleep(0)
            while not stop.is_set() and not reader.done():
                await asyncio.sleep(0.05)
            reader.cancel()
    except (ConnectionClosed, OSError) as err:
        answers[f"closed: {err}"[:80]] = 1
    return _summary(sent, what, answers)


def _dumps(obj: Any) -> str:
    return json.dumps(obj)


async def row1_fragments_before_auth(url: Url, stop: asyncio.Event) -> str:
    """Small fragments with fresh ids, never completed, on a connection without a token."""
    data = "x" * 200
    return await _flood(
        url(None),
        stop,
        lambda i: _dumps({"op": "fragment", "id": f"f{i}", "data": data, "num": 0, "total": 2}),
        "fragments (200 B, fresh ids, no token, 100 a frame)",
        10**7,
        per_frame=100,
    )


async def row2_subscribe_ids(url: Url, stop: asyncio.Event) -> str:
    """44,000 subscribe ids on /odom with a student token."""
    return await _flood(
        url("student"),
        stop,
        lambda i: _dumps({"op": "subscribe", "topic": "/odom", "id": f"s{i}"}),
        "subscribe ids on /odom (100 a frame)",
        44_000,
        per_frame=100,
    )


async def row3_advertise_ids(url: Url, stop: asyncio.Event) -> str:
    """Advertise ids on one topic, without end."""
    return await _flood(
        url("student"),
        stop,
        lambda i: _dumps(
            {
                "op": "advertise",
                "topic": "/r1/chatter",
                "type": "std_msgs/String",
                "id": f"advertise:/r1/chatter:{i}" + "x" * 200,
            }
        ),
        "advertise ids on /r1/chatter (100 a frame)",
        10**7,
        per_frame=100,
    )


async def row4_pending_calls(url: Url, stop: asyncio.Event) -> str:
    """Calls with ``timeout: 0`` (and 10 kB args) to its own service, never answered."""
    args = {"blob": "y" * 10_000}
    first = _dumps({"op": "advertise_service", "service": "/r1/sink", "type": "r1pkg/Sink"})

    def frame(i: int) -> str:
        if i == 0:
            return first
        call: dict[str, Any] = {"op": "call_service", "service": "/r1/sink", "id": f"c{i}"}
        call |= {"args": args, "timeout": 0}
        return _dumps(call)

    return await _flood(url("student"), stop, frame, "unanswered calls (timeout 0)", 10**7)


async def row5_latched(url: Url, stop: asyncio.Event) -> str:
    """100 latched 9.9 MB std_msgs/String messages on 100 topics."""
    data = "z" * 9_900_000

    def frame(i: int) -> str:
        return _dumps(
            {
                "op": "publish",
                "topic": f"/r1/big{i}",
                "type": "std_msgs/String",
                "latch": True,
                "msg": {"data": data},
            }
        )

    return await _flood(url("student"), stop, frame, "latched 9.9 MB messages", 100)


async def row6_unread_interfaces(url: Url, stop: asyncio.Event) -> str:
    """A client that never reads floods ``/rosapi/interfaces`` calls."""
    address, _, target = url("student").removeprefix("ws://").partition("/")
    host, port = address.split(":")
    sock = await unread_socket(host, int(port), f"/{target}")
    loop = asyncio.get_running_loop()
    sent = 0
    try:
        while not stop.is_set():
            payload = _dumps(
                {"op": "call_service", "service": "/rosapi/interfaces", "id": f"i{sent}"}
            ).encode()
            mask = os.urandom(4)
            masked = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
            await asyncio.wait_for(
                loop.sock_sendall(sock, bytes([0x81, 0x80 | len(payload)]) + mask + masked), 1.0
            )
            sent += 1
            if sent % 32 == 0:
                await asyncio.sleep(0)
    except (TimeoutError, OSError) as err:
        blocked = f"the server stopped reading ({type(err).__name__})"
    else:
        blocked = "the server kept reading"
    finally:
        sock.close()
    return f"sent {sent} /rosapi/interfaces calls without reading; {blocked}"


async def row7_wide_fragments(url: Url, stop: asyncio.Event) -> str:
    """Five clients: never-completed fragment sets of 4-byte characters (fresh ids).

    Each frame stays under a student's max_frame_bytes (1 MB): 80,000 characters, 320 kB of
    UTF-8, 960 kB of JSON (json.dumps escapes each as a surrogate pair); 30 pieces a message
    (9.6 MB, one short of complete), so each client fills its byte budget, not its 16 sets.
    """
    data = "\U0001f600" * 80_000

    async def one(k: int) -> str:
        return await _flood(
            url("student"),
            stop,
            lambda i: _dumps(
                {"op": "fragment", "id": f"w{k}-{i // 30}", "data": data}
                | {"num": i % 30, "total": 31},
            ),
            "fragments",
            10**7,
        )

    texts = await asyncio.gather(*(one(k) for k in range(5)))
    return "5 clients: " + texts[0]


async def row16_surrogates(url: Url, stop: asyncio.Event) -> str:
    """A latched message with a lone surrogate, then a fresh subscriber of the topic."""
    answers: dict[str, int] = {}
    pub = (
        '{"op":"publish","topic":"/r1/poison","type":"poison_msgs/Blob","latch":true,'
        '"msg":{"text":"\\ud800"}}'
    )
    async with connect(url("student"), open_timeout=10) as ws:
        reader = asyncio.create_task(_drain(ws, answers))
        await ws.send(pub)
        await ws.send('{"op":"subscribe","topic":"/r1/\\udfff"}')
        await ws.send('{"op":"advertise","topic":"/r1/x","type":"std_msgs/String","id":"\\ud800"}')
        await asyncio.sleep(0.5)
        async with connect(url("admin"), open_timeout=10) as late:
            late_answers: dict[str, int] = {}
            late_reader = asyncio.create_task(_drain(late, late_answers))
            await late.send('{"op":"subscribe","topic":"/r1/poison"}')
            await asyncio.sleep(1.0)
            late_reader.cancel()
        reader.cancel()
    return (
        f"{_summary(3, 'frames with lone surrogates', answers)}; "
        f"a later subscriber got: {late_answers or 'nothing'}"
    )


async def row17_big_frames(url: Url, stop: asyncio.Event) -> str:
    """10 MB publish frames back to back (a float64 array of a known type)."""
    body = _dumps(
        {
            "op": "publish",
            "topic": "/r1/big",
            "type": "std_msgs/Float64MultiArray",
            "msg": {"data": [0.123456789] * 700_000},
        }
    )
    assert len(body) < 10_000_000
    return await _flood(
        url("student"), stop, lambda i: body, f"{len(body) / MB:.1f} MB frames", 10**7
    )


async def row18_float32(url: Url, stop: asyncio.Event) -> str:
    """float32 1e308 published while a cbor-raw client subscribes."""
    answers: dict[str, int] = {}
    async with (
        connect(url("student"), open_timeout=10) as ws,
        connect(url("admin"), open_timeout=10) as sub,
    ):
        readers = [
            asyncio.create_task(_drain(ws, answers)),
            asyncio.create_task(_drain(sub, answers)),
        ]
        await sub.send(_dumps({"op": "subscribe", "topic": "/r1/f32", "compression": "cbor-raw"}))
        await sub.send(_dumps({"op": "subscribe", "topic": "/r1/f32", "compression": "cbor"}))
        for value in (1e308, -1e300, 3.5e38):
            msg: dict[str, Any] = {"op": "publish", "topic": "/r1/f32", "type": "std_msgs/Float32"}
            msg["msg"] = {"data": value}
            await ws.send(_dumps(msg))
        await asyncio.sleep(1.0)
        for task in readers:
            task.cancel()
    return _summary(3, "float32 publishes out of range", answers)


async def row20_nul_name(url: Url, stop: asyncio.Event) -> str:
    """Topic, service and id strings with a NUL."""
    frames = [
        '{"op":"subscribe","topic":"/\\u0000"}',
        '{"op":"publish","topic":"/r1/a\\u0000b","type":"std_msgs/String","msg":{}}',
        '{"op":"call_service","service":"/%00","id":"c1"}',
        '{"op":"subscribe","topic":"/odom","id":"a\\u0000b"}',
        '{"op":"publish","topic":"/r1/s","type":"std_msgs/String","msg":{"data":"a\\u0000"}}',
    ]
    return await _flood(
        url("student"), stop, lambda i: frames[i], "frames with NUL names", len(frames)
    )


ATTACKS: dict[str, tuple[str, Attack]] = {
    "1": ("fragments before auth, fresh ids", row1_fragments_before_auth),
    "2": ("44,000 subscribe ids on /odom", row2_subscribe_ids),
    "3": ("advertise ids on one topic", row3_advertise_ids),
    "4": ("unanswered calls, timeout 0", row4_pending_calls),
    "5": ("100 latched 9.9 MB messages", row5_latched),
    "6": ("non-reading /rosapi/interfaces flood", row6_unread_interfaces),
    "7": ("4-byte-char fragments, 5 clients", row7_wide_fragments),
    "16": ("lone surrogates, latched", row16_surrogates),
    "17": ("10 MB frames back to back", row17_big_frames),
    "18": ("float32 1e308 to cbor-raw", row18_float32),
    "20": ("NUL in names and ids", row20_nul_name),
}


class Observer(threading.Thread):
    """A well-behaved client: /odom arrival times and header stamps (wall seconds)."""

    def __init__(self, url: str) -> None:
        super().__init__(daemon=True)
        self.url = url
        self.samples: list[tuple[float, float]] = []
        self.stop = threading.Event()
        self.ready = threading.Event()

    def run(self) -> None:
        with sync_connect(f"{self.url}/?token={ADMIN}", max_size=None) as ws:
            ws.send(_dumps({"op": "subscribe", "topic": "/odom"}))
            self.ready.set()
            while not self.stop.is_set():
                try:
                    data = ws.recv(timeout=0.5)
                except TimeoutError:
                    continue
                except ConnectionClosed:
                    return
                msg = json.loads(data)
                if msg.get("topic") == "/odom":
                    s = msg["msg"]["header"]["stamp"]
                    self.samples.append((time.time(), s["sec"] + s["nanosec"] * 1e-9))

    def figures(self, start: float, end: float) -> tuple[float, float, float]:
        """Return (rate Hz, worst gap ms, p99 latency ms) of the stamps in [start, end]."""
        chosen = [(a, s) for a, s in self.samples if start <= s <= end]
        if len(chosen) < 2:
            return 0.0, (end - start) * 1e3, math_inf()
        stamps = [s for _, s in chosen]
        gaps = [b - a for a, b in itertools.pairwise(stamps)] or [0.0]
        edge = max(stamps[0] - start, end - stamps[-1])
        lat = sorted(a - s for a, s in chosen)
        p99 = lat[min(len(lat) - 1, int(0.99 * len(lat)))]
        return (len(stamps) - 1) / (stamps[-1] - stamps[0]), max(*gaps, edge) * 1e3, p99 * 1e3


def math_inf() -> float:
    return float("inf")


def tokens_file() -> Path:
    """A client-token file with the attacker's and the observer's tokens."""
    path = Path(tempfile.mkdtemp()) / "tokens.yaml"
    path.write_text(f'tokens:\n  "{STUDENT}": r1\n  "{ADMIN}": admin\n', encoding="utf-8")
    return path


def run_one(row: str, seconds: float, rss_cap_mb: float) -> dict[str, Any]:
    """Run one attack against a fresh server; return its figures."""
    title, attack = ATTACKS[row]
    options = ("--client-tokens", str(tokens_file()), "--admin-token", ADMIN)
    with server(*options) as (port, proc):
        base = f"ws://127.0.0.1:{port}"
        tokens = {"student": STUDENT, "admin": ADMIN}

        def url(who: str | None) -> str:
            return base if who is None else f"{base}/?token={tokens[who]}"

        observer = Observer(base)
        observer.start()
        observer.ready.wait(10)
        time.sleep(3.0)
        quiet_end = time.time()
        quiet = observer.figures(quiet_end - 2.5, quiet_end)
        rss0 = proc.memory_info().rss / 2**20
        peak = rss0
        capped = False
        start = time.time()

        async def drive() -> str:
            nonlocal peak, capped
            stop = asyncio.Event()
            task: asyncio.Task[str] = asyncio.create_task(attack(url, stop))
            while not task.done():
                await asyncio.sleep(0.1)
                try:
                    rss = proc.memory_info().rss / 2**20
                except Exception:
                    break
                peak = max(peak, rss)
                if rss > rss_cap_mb:
                    capped = True
                if time.time() - start > seconds or capped:
                    stop.set()
                    try:
                        return await asyncio.wait_for(task, 20)
                    except TimeoutError:
                        task.cancel()
                        return "attack did not stop within 20 s"
            return task.result()

        account = asyncio.run(drive())
        end = time.time()
        time.sleep(0.3)
        observer.stop.set()
        observer.join(5)
        alive = proc.is_running() and proc.status() != "zombie"
    rate, gap, p99 = observer.figures(start, end)
    return {
        "row": row,
        "title": title,
        "seconds": end - start,
        "rss0": rss0,
        "peak": peak,
        "capped": capped,
        "quiet": quiet,
        "attack": (rate, gap, p99),
        "alive": alive,
        "account": account,
    }


def report(result: dict[str, Any]) -> None:
    q, a = result["quiet"], result["attack"]
    cap = " (cap hit: attack stopped)" if result["capped"] else ""
    print(
        f"row {result['row']:>2} {result['title']:<38} {result['seconds']:5.1f} s  "
        f"RSS {result['rss0']:.0f} -> peak {result['peak']:.0f} MB{cap}"
    )
    print(
        f"       /odom quiet {q[0]:5.2f} Hz gap {q[1]:6.0f} ms p99 {q[2]:6.1f} ms | "
        f"attack {a[0]:5.2f} Hz gap {a[1]:6.0f} ms p99 {a[2]:6.1f} ms | alive {result['alive']}"
    )
    print(f"       {result['account']}")


def main(argv: list[str] | None = None) -> int:
    rows = (argv if argv is not None else sys.argv[1:]) or list(ATTACKS)
    seconds = float(os.environ.get("ATTACK_SECONDS", "10"))
    cap = float(os.environ.get("ATTACK_RSS_CAP_MB", "900"))
    for row in rows:
        report(run_one(row, seconds, cap))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
