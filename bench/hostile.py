"""Hostile input against a real simbridge process: how many frames, and did anything break.

Frames come from the same hypothesis strategies as the test (``tests/e2e/hostile.py``): wrong
types, missing fields, huge strings, deep nesting, NaN and infinities, garbage binary frames,
absurd throttle, queue and fragment values, non-finite and absurd /cmd_vel. One connection sends
them, each followed by a service call that must be answered (a frame over the size limit must
close the connection with 1009; a new one is opened). An observer counts /odom by the server's
header stamps: its rate and worst gap are shown for a quiet baseline and during the attack, side
by side. A crash is the server process dying, a probe not answered, or an ``internal error``.
"""

from __future__ import annotations

import itertools
import json
import os
import threading
import time
from typing import Any

from hypothesis import HealthCheck, given, settings
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import ClientConnection, connect

from bench._server import health, server
from tests.e2e.hostile import frames


COUNT = int(os.environ.get("HOSTILE_FRAMES", "20000"))
MAX_SIZE = 1_000_000


class Observer(threading.Thread):
    """Counts /odom arrival times and keeps the last pose."""

    def __init__(self, url: str) -> None:
        super().__init__(daemon=True)
        self.url = url
        self.times: list[float] = []
        self.last: Any = None
        self.others: list[Any] = []
        self.stop = threading.Event()

    def run(self) -> None:
        with connect(self.url, max_size=None) as ws:
            ws.send(json.dumps({"op": "subscribe", "topic": "/odom"}))
            while not self.stop.is_set():
                try:
                    msg = json.loads(ws.recv(timeout=0.5))
                except TimeoutError:
                    continue
                if msg.get("topic") == "/odom":
                    stamp = msg["msg"]["header"]["stamp"]
                    # the server's publish time: gaps of the server, not of this process
                    self.times.append(stamp["sec"] + stamp["nanosec"] * 1e-9)
                    self.last = msg["msg"]
                else:
                    self.others.append(msg)

    def window(self, start: float, end: float) -> tuple[float, float]:
        times = [t for t in self.times if start <= t <= end]
        gaps = [b - a for a, b in itertools.pairwise(times)]
        return (len(times) - 1) / (times[-1] - times[0]), max(gaps)


class Attacker:
    def __init__(self, url: str) -> None:
        self.url = url
        self.ws: ClientConnection | None = None
        self.sent = 0
        self.closed_big = 0
        self.crashes: list[str] = []
        self.probe = 0

    def send(self, frame: str | bytes) -> None:
        if self.ws is None:
            self.ws = connect(self.url, max_size=None, close_timeout=1, legacy=True)
        ws = self.ws
        self.sent += 1
        self.probe += 1
        pid = f"p{self.probe}"
        try:
            ws.send(frame)
            ws.send(json.dumps({"op": "call_service", "service": "/rosapi/topics", "id": pid}))
            deadline = time.monotonic() + 10
            while True:
                data = ws.recv(timeout=max(0.01, deadline - time.monotonic()))
                if isinstance(data, str) and "internal error" in data:
                    self.crashes.append(data[:200])
                if isinstance(data, str) and f'"{pid}"' in data:
                    return
        except ConnectionClosed as err:
            if err.rcvd is not None and err.rcvd.code == 1009 and len(frame) > MAX_SIZE:
                self.closed_big += 1
            else:
                self.crashes.append(f"connection closed: {err} after a {len(frame)}-byte frame")
            self.ws = None
        except TimeoutError:
            self.crashes.append(f"no answer to the probe after {frame[:80]!r}")
            self.ws = None


def main() -> int:
    """Run the hostile-input benchmark."""
    options = ("--max-message-size", str(MAX_SIZE), "--admin-token", "not-for-the-attacker")
    with server(*options) as (port, proc):
        url = f"ws://127.0.0.1:{port}"
        observer = Observer(url)
        observer.start()
        time.sleep(11.0)
        quiet = (observer.times[0] if observer.times else time.time(), time.time())
        attacker = Attacker(url)
        start = time.time()

        @settings(
            max_examples=COUNT,
            deadline=None,
            database=None,
            suppress_health_check=list(HealthCheck),
        )
        @given(frames)
        def attack(frame: str | bytes) -> None:
            attacker.send(frame)

        attack()
        end = time.time()
        loop = health(port)["loop"]
        time.sleep(0.5)
        observer.stop.set()
        observer.join(5)
        alive = proc.is_running() and proc.status() != "zombie"
        base_rate, base_gap = observer.window(*quiet)
        rate, gap = observer.window(start, end)
        pose = observer.last["pose"]["pose"]
        twist = observer.last["twist"]["twist"]
    moved = (pose["position"]["x"], pose["position"]["y"], pose["orientation"]["z"]) != (0, 0, 0)
    print(f"hostile: {attacker.sent} hostile frames in {end - start:.0f} s against a real server")
    print(f"  crashes (process died, probe unanswered, internal error): {len(attacker.crashes)}")
    for text in attacker.crashes[:5]:
        print(f"    {text}")
    print(f"  connections closed for max_message_size (1009, expected): {attacker.closed_big}")
    print(f"  server process alive at the end: {alive}")
    print(f"  {'':<22}{'/odom Hz':>10}{'worst gap ms':>14}")
    print(f"  {'quiet baseline':<22}{base_rate:>10.2f}{base_gap * 1e3:>14.1f}")
    print(f"  {'under attack':<22}{rate:>10.2f}{gap * 1e3:>14.1f}")
    print(
        f"  server loop: ticks {loop['ticks']}, late {loop['late_ticks']}, skipped "
        f"{loop['skipped_ticks']}, lateness p99 {loop['lateness_ms_p99']} ms (last minute)"
    )
    print(
        f"  robot moved: {moved} (twist linear.x {twist['linear']['x']}, "
        f"angular.z {twist['angular']['z']}); statuses to the observer: {len(observer.others)}"
    )
    return 1 if attacker.crashes or not alive or moved else 0


if __name__ == "__main__":
    raise SystemExit(main())
