"""Hostile clients against a real simbridge process: what each attack costs the class.

Each attack in :data:`ATTACKS` runs against a fresh server process (the classroom world and
parameters, client tokens, an admin token), so that one attack's memory is not charged to the
next. The observer (``bench/odomwatch.py``, a process of its own) reads ``/r1/odom`` as a student
would and keeps probing the ``/cmd_vel`` watchdog on r2. Per attack the table gives the server's
peak RSS, the observer's /r1/odom rate and worst gap (on the server's header stamps), its p99
latency (arrival minus stamp), the watchdog's worst stop (from the tick that first showed the
command to its ``safety: stopped`` stamp on ``/rosout``), whether the server still answers a
new client afterwards, and what the server told the attacker. The first row is the same
observer with no attack.

Targets (issue 17): RSS <= 200 MB for any one-client attack; /odom >= 19 Hz; worst gap
<= 150 ms; the watchdog within its timeout (0.5 s) plus one tick (50 ms).

An attack is a function ``(Target) -> str`` registered with :func:`attack` (or an asyncio one
registered with :func:`attack_async`): it attacks until ``target.until`` (or finishes earlier)
and returns what the server answered, in a few words.
``python -m bench hostile [NAME ...]`` runs the named attacks only (``fuzz`` is the 20,000
hypothesis frames of issue 7; ``HOSTILE_FRAMES`` changes the count).
"""

from __future__ import annotations

import asyncio
import itertools
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Coroutine, Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import psutil
from websockets.exceptions import ConnectionClosed, InvalidStatus
from websockets.sync.client import ClientConnection, connect

from bench import budgetattacks, httpattacks, stateattacks
from bench._server import http_server, server
from bench.procs import ROOT, percentile


#: How long each attack runs, and the quiet baseline (seconds).
WINDOW = float(os.environ.get("HOSTILE_WINDOW", "10"))
#: What the server must still do after the attack: seconds measured after it ends.
AFTER = 3.0
COUNT = int(os.environ.get("HOSTILE_FRAMES", "20000"))
MAX_SIZE = 1_000_000
TICK = 0.05
#: The stop is stamped after the tick's publishing, the command's tick at its /odom: the
#: tick's own work (a millisecond or two) lies between them.
WORK = 0.01
WATCHDOG = 0.5
ADMIN = "bench-admin"
OBSERVER = "bench-observer"
#: Marks an attack's note when the attack got through (the row is then not 'ok').
BREACH = "BREACH:"
#: A teaching assistant's token: every topic, not an administrator.
TA = "bench-ta"
#: Student tokens: ``student-rN`` may command robot rN only.
STUDENTS = {f"student-r{n}": f"r{n}" for n in range(1, 9)}
TWIST = {"linear": {"x": 0.2, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}
#: The classroom world's frames (targets and sources of TF requests).
FRAMES = [f"r{n}/{f}" for n in range(1, 5) for f in ("odom", "base_link", "laser")]


@dataclass
class Target:
    """The server an attack runs against."""

    port: int
    proc: psutil.Process
    #: Attack until this time (``time.monotonic()``).
    until: float
    #: The HTTP port (page, /healthz, /api/admin), 0 when the attack does not use it.
    http_port: int = 0

    def url(self, token: str | None = None) -> str:
        """The rosbridge URL, with ``?token=`` when given."""
        base = f"ws://127.0.0.1:{self.port}/"
        return base if token is None else f"{base}?token={token}"

    def student(self, robot: str = "r3") -> ClientConnection:
        """Connect as the student of ``robot``."""
        return connect(self.url(f"student-{robot}"), max_size=None, open_timeout=20)

    def admin(self) -> ClientConnection:
        """Connect with the admin token."""
        return connect(self.url(ADMIN), max_size=None, open_timeout=20)

    def left(self) -> float:
        return self.until - time.monotonic()


@dataclass
class Attack:
    name: str
    #: Row of issue 17's table.
    row: str
    run: Callable[[Target], str]
    #: Extra server options.
    options: tuple[str, ...] = ()
    #: The attack needs the HTTP port (``Target.http_port``).
    http: bool = False


#: Every attack, in the order they run.
ATTACKS: dict[str, Attack] = {}


def attack(
    name: str, row: str, *options: str
) -> Callable[[Callable[[Target], str]], Callable[[Target], str]]:
    """Register an attack under ``name`` (``row``: the issue's row it reproduces)."""

    def register(run: Callable[[Target], str]) -> Callable[[Target], str]:
        ATTACKS[name] = Attack(name, row, run, options)
        return run

    return register


#: An attack written with asyncio: ``(url, stop) -> str``, where ``url(who)`` is the URL for
#: ``"student"`` (robot r1's student), ``"admin"`` or ``None`` (no token) and ``stop`` is set
#: when its time is up.
AsyncAttack = Callable[[Callable[[str | None], str], asyncio.Event], Coroutine[Any, Any, str]]


def attack_async(name: str, row: str, run: AsyncAttack, *options: str) -> None:
    """Register an asyncio attack (e.g. those of ``bench/stateattacks.py``) under ``name``."""

    def who(target: Target) -> Callable[[str | None], str]:
        tokens = {"student": "student-r1", "admin": ADMIN}
        return lambda kind: target.url(tokens.get(kind, kind) if kind is not None else None)

    def sync(target: Target) -> str:
        async def go() -> str:
            stop = asyncio.Event()
            asyncio.get_running_loop().call_later(max(0.0, target.left()), stop.set)
            return await run(who(target), stop)

        return asyncio.run(go())

    ATTACKS[name] = Attack(name, row, sync, options)


# -- helpers for attacks --------------------------------------------------------------------


def send(ws: ClientConnection, value: Any) -> None:
    ws.send(json.dumps(value))


def answer(ws: ClientConnection, match: Callable[[Any], bool], timeout: float = 5.0) -> Any:
    """The first message that ``match``es within ``timeout`` (None if none)."""
    deadline = time.monotonic() + timeout
    while (left := deadline - time.monotonic()) > 0:
        try:
            data = ws.recv(timeout=left)
        except TimeoutError:
            return None
        if isinstance(data, str) and match(msg := json.loads(data)):
            return msg
    return None


def said(msg: Any) -> str:
    """A server reply in a few words."""
    if msg is None:
        return "no answer"
    text = msg.get("msg") or msg.get("values") or msg
    return str(text)[:90]


def drain(ws: ClientConnection) -> list[Any]:
    """Every message already received (does not wait)."""
    out = []
    with suppress(TimeoutError):
        while True:
            data = ws.recv(timeout=0)
            if isinstance(data, str):
                out.append(json.loads(data))
    return out


def verdict(held: bool, text: str) -> str:
    """``text``, marked as a breach when the server did not hold (the attack got through)."""
    return text if held else f"{BREACH} {text}"


def statuses(messages: list[Any]) -> list[str]:
    return [m["msg"] for m in messages if m.get("op") == "status"]


def tf_goal(goal_id: str, sources: list[str], **extra: Any) -> dict[str, Any]:
    args = {
        "source_frames": sources,
        "target_frame": "r1/odom",
        "angular_thres": 0.0,
        "trans_thres": 0.0,
        "rate": 100.0,
    }
    args.update(extra)
    return {
        "op": "send_action_goal",
        "id": goal_id,
        "action": "/tf2_web_republisher",
        "action_type": "tf2_web_republisher_interfaces/action/TFSubscription",
        "args": args,
        "feedback": True,
    }


# -- the attacks ----------------------------------------------------------------------------


@attack("republish_tfs", "8")
def republish_forever(target: Target) -> str:
    """/republish_tfs with a 63-year timeout at 100 Hz, as fast as it is answered; caller leaves."""
    sixty_three_years = {"sec": 63 * 365 * 86400, "nanosec": 0}
    request = {
        "source_frames": FRAMES,
        "target_frame": "r1/odom",
        "angular_thres": 0.0,
        "trans_thres": 0.0,
        "rate": 100.0,
        "timeout": sixty_three_years,
    }
    ok = refused = 0
    last = None
    with target.student() as ws:
        for n in itertools.count():
            if target.left() < WINDOW / 2:
                break
            call = {"op": "call_service", "service": "/republish_tfs", "args": request}
            send(ws, {**call, "id": f"r{n}"})
            reply = answer(ws, lambda m: m.get("op") == "service_response", 5)
            if reply is not None and reply["result"]:
                ok += 1
                send(ws, {"op": "subscribe", "topic": reply["values"]["topic_name"]})
            else:
                refused += 1
                last = reply
    return f"{ok} accepted, {refused} refused ({said(last)}); caller left"


@attack("tf_goals", "8")
def tf_goals(target: Target) -> str:
    """TF goals at 100 Hz for every frame, as many as the server takes; the caller leaves."""
    refused = None
    with target.student() as ws:
        for n in range(2000):
            send(ws, tf_goal(f"g{n}", FRAMES))
        done = answer(ws, lambda m: m.get("op") in ("action_result", "status"), WINDOW / 2)
        refused = done
    text = f"2000 goals sent; first refusal: {said(refused)}; caller left"
    return verdict(refused is not None, text)


@attack("tf_goal_bad_frame", "9")
def tf_goal_bad_frame(target: Target) -> str:
    """One TF goal with a lone surrogate frame name and negative thresholds; stays connected."""
    with target.student() as ws:
        bad = "\ud800"
        goal = tf_goal("bad", [bad], target_frame=bad, angular_thres=-1.0, trans_thres=-1.0)
        ws.send(json.dumps(goal, ensure_ascii=True))
        reply = answer(ws, lambda m: m.get("op") in ("action_result", "status"), 2)
        while target.left() > 0:
            drain(ws)
            time.sleep(0.1)
    return verdict(reply is not None, said(reply))


@attack("advertise_action", "10")
def takeover(target: Target) -> str:
    """``advertise_action /tf2_web_republisher`` (every-topic token), then leave: TF for others?"""
    with connect(target.url(TA), max_size=None, open_timeout=20) as ws:
        send(
            ws,
            {
                "op": "advertise_action",
                "action": "/tf2_web_republisher",
                "type": "tf2_web_republisher_interfaces/action/TFSubscription",
            },
        )
        reply = answer(ws, lambda m: m.get("op") == "status", 1)
    with target.student("r1") as other:
        send(other, tf_goal("after", ["r1/base_link"]))
        got = answer(other, lambda m: m.get("op") in ("action_feedback", "action_result"), 3)
    works = got is not None and got["op"] == "action_feedback"
    return verdict(
        works, f"{said(reply)}; TF for others afterwards: {'works' if works else 'BROKEN'}"
    )


@attack("unauthenticated", "13")
def unauthenticated(target: Target) -> str:
    """200 token-less connections held open; then a real student connects."""
    held: list[ClientConnection] = []
    refused = 0
    for _ in range(200):
        try:
            held.append(connect(target.url(), open_timeout=5, legacy=True))
        except (InvalidStatus, OSError, TimeoutError):
            refused += 1
    try:
        with target.student("r1") as ws:
            send(ws, {"op": "call_service", "service": "/rosapi/topics", "id": "s"})
            ok = answer(ws, lambda m: m.get("op") == "service_response", 5) is not None
            student = verdict(ok, "student served" if ok else "student NOT served")
    except InvalidStatus as err:
        student = verdict(False, f"student refused: HTTP {err.response.status_code}")
    while target.left() > 0 and held:
        time.sleep(0.1)
    for ws in held:
        with suppress(Exception):
            ws.close()
    return f"{len(held)} token-less open, {refused} refused; {student}"


@attack("cancel_others", "14")
def cancel_others(target: Target) -> str:
    """r1's student has a TF goal; r3's student cancels every goal of the action."""
    with target.student("r1") as victim, target.student("r3") as ws:
        send(victim, tf_goal("mine", ["r1/base_link"]))
        answer(victim, lambda m: m.get("op") == "action_feedback", 3)
        zero = {"goal_id": {"uuid": [0] * 16}, "stamp": {"sec": 0, "nanosec": 0}}
        send(
            ws,
            {
                "op": "call_service",
                "service": "/tf2_web_republisher/_action/cancel_goal",
                "args": {"goal_info": zero},
                "id": "c",
            },
        )
        reply = answer(ws, lambda m: m.get("op") == "service_response", 3)
        ended = answer(victim, lambda m: m.get("op") == "action_result", 1)
    fate = "victim's goal CANCELED" if ended is not None else "victim's goal kept"
    return verdict(ended is None, f"{said(reply)}; {fate}")


@attack("squat", "15")
def squat(target: Target) -> str:
    """r3's student claims /r5/cmd_vel by a typed subscribe; then the instructor spawns r5."""
    with target.student("r3") as ws, target.admin() as admin:
        send(ws, {"op": "subscribe", "topic": "/r5/cmd_vel", "type": "std_msgs/String"})
        squatting = statuses([answer(ws, lambda m: m.get("op") == "status", 1) or {}])
        spawn = {"x": 0.0, "y": 1.5, "theta": 0.0, "name": "r5"}
        send(admin, {"op": "call_service", "service": "/spawn", "args": spawn, "id": "s"})
        reply = answer(admin, lambda m: m.get("op") == "service_response", 5)
    spawned = reply is not None and reply["result"]
    result = "spawned" if spawned else f"spawn FAILED {said(reply)}"
    return verdict(
        spawned, f"{squatting[0][:60] if squatting else 'typed subscribe accepted'}; {result}"
    )


@attack("teleport_out", "19")
def teleport_out(target: Target) -> str:
    """r1's student teleports r1 to (1000, -1000)."""
    with target.student("r1") as ws:
        pose = {"x": 1000.0, "y": -1000.0, "theta": 0.0}
        call = {"op": "call_service", "service": "/r1/teleport_absolute", "args": pose, "id": "t"}
        send(ws, call)
        reply = answer(ws, lambda m: m.get("op") == "service_response", 3)
    if reply is not None and reply["result"]:
        return verdict(False, "teleported to (1000, -1000)")
    return said(reply)


@attack("fuzz", "16-20", "--max-message-size", str(MAX_SIZE))
def fuzz(target: Target) -> str:
    """The hypothesis frames of issue 7 (each followed by a probe that must be answered)."""
    from hypothesis import HealthCheck, given, settings

    from tests.e2e.hostile import frames

    sent = closed = 0
    crashes: list[str] = []
    conn: list[ClientConnection] = []

    def one(frame: str | bytes) -> None:
        nonlocal sent, closed
        if not conn:
            conn.append(connect(target.url(OBSERVER), max_size=None, close_timeout=1))
        ws = conn[0]
        sent += 1
        pid = f"p{sent}"
        try:
            ws.send(frame)
            send(ws, {"op": "call_service", "service": "/rosapi/topics", "id": pid})
            deadline = time.monotonic() + 10
            while True:
                data = ws.recv(timeout=max(0.01, deadline - time.monotonic()))
                if isinstance(data, str) and "internal error" in data:
                    crashes.append(data[:200])
                if isinstance(data, str) and f'"{pid}"' in data:
                    return
        except ConnectionClosed as err:
            if err.rcvd is not None and err.rcvd.code == 1009 and len(frame) > MAX_SIZE:
                closed += 1
            else:
                crashes.append(f"closed: {err} after a {len(frame)}-byte frame")
            conn.clear()
        except TimeoutError:
            crashes.append(f"no answer to the probe after {frame[:80]!r}")
            conn.clear()

    limits = settings(
        max_examples=COUNT, deadline=None, database=None, suppress_health_check=list(HealthCheck)
    )
    given(frames)(limits(one))()
    for text in crashes[:3]:
        print(f"    fuzz crash: {text}")
    text = f"{sent} frames, {len(crashes)} crashes, {closed} closed for size (1009)"
    return verdict(not crashes, text)


# the protocol-state rows (1-7, 16-18, 20): bench/stateattacks.py, one client each (row 7: five)
for _row, (_title, _run) in stateattacks.ATTACKS.items():
    attack_async(f"state{_row}", _row, _run)


# the HTTP rows of issue 29 (2, 3, 7, 11): bench/httpattacks.py, against the HTTP port
def _http_attack(run: httpattacks.HttpAttack) -> Callable[[Target], str]:
    return lambda target: run(target.http_port, target.port, ADMIN, target.until)


for _name, (_row, _http) in httpattacks.ATTACKS.items():
    ATTACKS[_name] = Attack(_name, _row, _http_attack(_http), http=True)


# what one student makes the server hold or do (issue 29, 4-6, 10, 12): bench/budgetattacks.py
for _name, (_title, _run) in budgetattacks.ATTACKS.items():
    attack_async(_name, budgetattacks.ROWS[_name], _run)


# -- the run --------------------------------------------------------------------------------


@dataclass
class Row:
    name: str
    row: str
    rss_start: float = 0.0
    rss_peak: float = 0.0
    rate: float = float("nan")
    gap: float = float("nan")
    p99: float = float("nan")
    watchdog: list[float] = field(default_factory=list)
    missed_stops: int = 0
    healthy: bool = False
    note: str = ""
    #: The server's CPU over the window (% of one core) and the machine's load average: a gap
    #: while the server was idle and the load high is the machine's, not the attack's.
    cpu: float = 0.0
    load: float = 0.0


class RssSampler(threading.Thread):
    def __init__(self, proc: psutil.Process) -> None:
        super().__init__(daemon=True)
        self.proc = proc
        self.peak = 0
        self.stop = threading.Event()

    def run(self) -> None:
        while not self.stop.wait(0.05):
            with suppress(psutil.Error):
                self.peak = max(self.peak, self.proc.memory_info().rss)


@contextmanager
def observer(port: int) -> Iterator[Callable[[], dict[str, Any]]]:
    """Run bench/odomwatch.py; yield a function that stops it and returns its records."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "bench.odomwatch", f"ws://127.0.0.1:{port}/?token={OBSERVER}"],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout is not None
    if proc.stdout.readline().strip() != "ready":
        proc.kill()
        raise RuntimeError("the observer did not connect")
    result: dict[str, Any] = {}

    def finish() -> dict[str, Any]:
        if not result:
            proc.terminate()
            out, _ = proc.communicate(timeout=30)
            result.update(json.loads(out.strip().splitlines()[-1]))
        return result

    try:
        yield finish
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def healthy(port: int) -> bool:
    """Whether a new student is served within 5 s."""
    try:
        with connect(f"ws://127.0.0.1:{port}/?token=student-r4", open_timeout=5) as ws:
            send(ws, {"op": "call_service", "service": "/rosapi/topics", "id": "h"})
            return answer(ws, lambda m: m.get("op") == "service_response", 5) is not None
    except (InvalidStatus, OSError, TimeoutError, ConnectionClosed):
        return False


def measure(row: Row, records: dict[str, Any], start: float, end: float) -> None:
    """Fill ``row`` with the observer's figures between wall times ``start`` and ``end``."""
    odom = [(t, s) for t, s in records["odom"] if start <= s <= end]
    stamps = [s for _, s in odom]
    if len(stamps) >= 2:
        row.rate = (len(stamps) - 1) / (stamps[-1] - stamps[0])
        row.gap = max(b - a for a, b in itertools.pairwise(stamps))
        # a gap at the window's edges counts too: nothing arrived at all
        row.gap = max(row.gap, stamps[0] - start, end - stamps[-1])
    else:
        row.rate, row.gap = 0.0, end - start
    row.p99 = percentile([t - s for t, s in odom], 0.99)
    stops = sorted(records["stops"])
    for sent, seen in records["probes"]:
        if not start <= sent <= end - (WATCHDOG + 0.5):
            continue
        after = [s for s in stops if s > seen]
        if after and after[0] - seen < 1.9:
            row.watchdog.append(after[0] - seen)
        else:
            row.missed_stops += 1


def _cpu(proc: psutil.Process) -> float:
    times = proc.cpu_times()
    return float(times.user + times.system)


@contextmanager
def _server(args: tuple[str, ...], http: bool) -> Iterator[tuple[int, int, psutil.Process]]:
    if http:
        with http_server(*args) as ports:
            yield ports
    else:
        with server(*args) as (port, proc):
            yield port, 0, proc


def run_one(
    name: str, run: Callable[[Target], str] | None, options: tuple[str, ...], http: bool = False
) -> Row:
    """Run one attack (``run`` None: the quiet baseline) on a fresh server."""
    row = Row(name, ATTACKS[name].row if name in ATTACKS else "-")
    files = Path(tempfile.mkdtemp(prefix="bench-hostile-"))
    tokens = files / "tokens.yaml"
    tokens.write_text(json.dumps({"tokens": {**STUDENTS, OBSERVER: "*", TA: "*"}}))
    config = ROOT / "config"
    args = (
        *("--world", str(config / "worlds/classroom.yaml")),
        *("--params", str(config / "classroom_params.yaml")),
        *("--client-tokens", str(tokens), "--admin-token", ADMIN),
        *options,
    )
    with _server(args, http) as (port, http_port, proc), observer(port) as finish:
        sampler = RssSampler(proc)
        sampler.start()
        time.sleep(2.0)  # the observer settles; r2's first probe
        row.rss_start = proc.memory_info().rss / 2**20
        start = time.time()
        cpu = _cpu(proc)
        target = Target(port, proc, time.monotonic() + WINDOW, http_port)
        try:
            row.note = run(target) if run is not None else "no attack"
        except Exception as err:  # an attack that breaks is a figure too
            row.note = f"attack raised {type(err).__name__}: {err}"[:120]
        # every row is watched as long (quick attacks too): the same number of watchdog probes
        time.sleep(max(0.0, target.left()) + AFTER)
        end = time.time()
        row.cpu = (_cpu(proc) - cpu) / (end - start) * 100
        row.load = os.getloadavg()[0]
        row.healthy = proc.is_running() and proc.status() != "zombie" and healthy(port)
        sampler.stop.set()
        sampler.join()
        row.rss_peak = sampler.peak / 2**20
        measure(row, finish(), start, end)
    return row


def report(rows: list[Row]) -> bool:
    base = rows[0]
    print(
        f"hostile: one attack per fresh server (classroom world, tokens, watchdog {WATCHDOG} s); "
        f"each row watched {WINDOW:g} s (the attack runs in it, or less) + {AFTER:g} s after; "
        f"{os.cpu_count()} cores"
    )
    head = (
        f"  {'attack':<18}{'row':>6}{'RSS MB':>14}{'/odom Hz':>10}{'gap ms':>8}{'p99 ms':>8}"
        f"{'watchdog ms':>13}{'CPU %':>7}{'load':>6}{'ok':>4}"
    )
    print(head)
    ok = True
    for r in rows:
        worst = max(r.watchdog) * 1e3 if r.watchdog else float("nan")
        dog = f"{worst:.0f}" + (f" {r.missed_stops}x" if r.missed_stops else "")
        rss = f"{r.rss_start:.0f}->{r.rss_peak:.0f}"
        good = (
            r.rss_peak <= 200
            and r.rate >= 19
            and r.gap <= 0.150
            and not r.missed_stops
            and worst <= (WATCHDOG + TICK + WORK) * 1e3
            and r.healthy
            and BREACH not in r.note
        )
        ok = ok and good
        print(
            f"  {r.name:<18}{r.row:>6}{rss:>14}{r.rate:>10.2f}{r.gap * 1e3:>8.0f}"
            f"{r.p99 * 1e3:>8.1f}{dog:>13}{r.cpu:>7.0f}{r.load:>6.1f}{'yes' if good else 'NO':>4}"
        )
        print(f"  {'':<18}  server said: {r.note}")
    print(
        "  ratios to the quiet baseline: "
        + ", ".join(
            f"{r.name} /odom {r.rate / base.rate:.2f}x p99 {r.p99 / base.p99:.1f}x"
            for r in rows[1:]
        )
    )
    print(
        "  targets: RSS <= 200 MB, /odom >= 19 Hz, gap <= 150 ms, watchdog <= "
        f"{(WATCHDOG + TICK) * 1e3:.0f} ms (timeout + one tick, + {WORK * 1e3:.0f} ms of the "
        "tick's own work) and never missed ('Nx'), server "
        f"serves a new student afterwards, and the attack did not get through ({BREACH}); 'ok' "
        "says all held"
    )
    return ok


def main(names: list[str] | None = None) -> int:
    """Run the hostile benchmark (the attacks in ``names``, default all)."""
    chosen = names or [*ATTACKS]
    rows = [run_one("quiet", None, ())]
    for name in chosen:
        a = ATTACKS[name]
        rows.append(run_one(name, a.run, a.options, a.http))
    return 0 if report(rows) else 1


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
