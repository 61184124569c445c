"""A small asyncio rosbridge v2 client: what the command-line tools use against any server.

It speaks plain JSON rosbridge (protocol reference sections 3.3-3.5), so it works against
simbridge and against rosbridge_server on a real robot alike::

    async with RosbridgeClient.connect("ws://127.0.0.1:9090") as ros:
        inbox = await ros.subscribe("/odom")
        print(await inbox.get())
        await ros.publish("/cmd_vel", {"linear": {"x": 0.2}}, "geometry_msgs/msg/Twist")
        print(await ros.call_service("/rosapi/topics"))

``status`` messages from the server (errors about this client's ops) are kept in
:attr:`RosbridgeClient.errors` and logged at debug level.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import logging
import signal
from collections.abc import AsyncIterator, Coroutine
from typing import Any, TypeVar

from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed

from simbridge.errors import SimbridgeError


__all__ = ["ClientError", "RosbridgeClient", "run_tool"]

logger = logging.getLogger(__name__)

T = TypeVar("T")


def run_tool(main: Coroutine[Any, Any, T]) -> T:
    """Run a tool's ``main``; SIGINT (Ctrl-C) or SIGTERM cancels it.

    ``asyncio.run`` listens for SIGINT only where it finds Python's own handler. A tool started
    in the background of a script (``simbridge topic pub ... &``) inherits SIGINT ignored and
    would never end on ``kill -INT``; a SIGTERM would end it without closing its connection.
    Like the server, a tool listens to both and closes cleanly.

    Raises:
        KeyboardInterrupt: a signal ended ``main``.
    """

    async def guarded() -> T:
        task = asyncio.current_task()
        assert task is not None
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, task.cancel)
        return await main

    try:
        return asyncio.run(guarded())
    except asyncio.CancelledError:
        raise KeyboardInterrupt from None


class ClientError(SimbridgeError):
    """A rosbridge request failed: no connection, a failed service call, a timeout."""


#: Seconds a closing connection waits for the server's close frame (websockets' default is 10):
#: a Ctrl-C ends a tool at once even when the server is slow to answer.
CLOSE_TIMEOUT = 2.0


class RosbridgeClient:
    """One connection to a rosbridge server (create with :meth:`connect`)."""

    def __init__(self, conn: ClientConnection, url: str) -> None:
        self.url = url
        self._conn = conn
        self._ids = itertools.count(1)
        self._calls: dict[str, asyncio.Future[Any]] = {}
        self._inboxes: dict[str, list[asyncio.Queue[dict[str, Any]]]] = {}
        self._advertised: set[str] = set()
        #: ``status`` messages of level error/warning received so far.
        self.errors: list[str] = []
        #: Set when the connection has closed.
        self.closed = asyncio.Event()
        self._reader = asyncio.create_task(self._read(), name="rosbridge-client")

    @classmethod
    @contextlib.asynccontextmanager
    async def connect(cls, url: str, timeout: float = 5.0) -> AsyncIterator[RosbridgeClient]:
        """Connect to ``url`` (``ws://host:port``); close on exit.

        Raises:
            ClientError: the server cannot be reached within ``timeout``.
        """
        try:
            # asyncio.timeout, not wait_for: Python 3.11's wait_for can lose a cancellation (a
            # Ctrl-C) that comes as the connection opens, and the tool then runs on
            async with asyncio.timeout(timeout):
                conn = await connect(
                    url, max_size=None, open_timeout=None, close_timeout=CLOSE_TIMEOUT
                )
        except (OSError, TimeoutError, ValueError) as err:
            text = str(err) or type(err).__name__
            msg = f"cannot connect to rosbridge at {url}: {text}"
            raise ClientError(msg) from None
        except Exception as err:  # websockets' InvalidURI, InvalidHandshake...
            msg = f"cannot connect to rosbridge at {url}: {err}"
            raise ClientError(msg) from None
        client = cls(conn, url)
        try:
            yield client
        finally:
            await client.close()

    async def close(self) -> None:
        """Close the connection."""
        self._reader.cancel()
        interrupted = False
        try:
            await self._reader
        except asyncio.CancelledError:
            task = asyncio.current_task()  # the reader's cancellation, or also this task's own
            interrupted = task is not None and task.cancelling() > 0
        await self._conn.close()
        self.closed.set()
        if interrupted:  # a Ctrl-C while closing still ends the tool
            raise asyncio.CancelledError

    async def _send(self, body: dict[str, Any]) -> None:
        try:
            await self._conn.send(json.dumps(body))
        except ConnectionClosed:
            msg = f"the connection to {self.url} is closed"
            raise ClientError(msg) from None

    async def _read(self) -> None:
        try:
            async for data in self._conn:
                if isinstance(data, bytes):
                    continue  # JSON only: this client never asks for CBOR
                try:
                    body = json.loads(data)
                except ValueError:
                    continue
                self._dispatch(body)
        except ConnectionClosed:
            pass
        finally:
            self.closed.set()
            for future in self._calls.values():
                if not future.done():
                    future.set_exception(ClientError(f"the connection to {self.url} closed"))

    def _dispatch(self, body: Any) -> None:
        if not isinstance(body, dict):
            return
        op = body.get("op")
        if op == "publish":
            msg = body.get("msg")
            for queue in self._inboxes.get(str(body.get("topic")), []):
                queue.put_nowait(msg if isinstance(msg, dict) else {})
        elif op == "service_response":
            future = self._calls.pop(str(body.get("id")), None)
            if future is not None and not future.done():
                future.set_result(body)
        elif op == "status" and body.get("level") in ("error", "warning"):
            text = str(body.get("msg"))
            self.errors.append(text)
            logger.debug("server: %s", text)

    # -- requests -------------------------------------------------------------------------------

    async def call_service(
        self, service: str, args: Any = None, *, timeout: float = 10.0
    ) -> dict[str, Any]:
        """Call ``service`` with ``args`` and return its response values.

        Raises:
            ClientError: the call failed (the server's reason), or no answer in ``timeout``.
        """
        call_id = f"call:{service}:{next(self._ids)}"
        future: asyncio.Future[Any] = asyncio.get_running_loop().create_future()
        self._calls[call_id] = future
        body: dict[str, Any] = {"op": "call_service", "id": call_id, "service": service}
        if args is not None:
            body["args"] = args
        await self._send(body)
        try:
            reply = await asyncio.wait_for(future, timeout)
        except TimeoutError:
            self._calls.pop(call_id, None)
            msg = f"service {service}: no answer within {timeout:g} s"
            raise ClientError(msg) from None
        values = reply.get("values")
        if reply.get("result") is False:
            msg = f"service {service} failed: {values}"
            raise ClientError(msg)
        return values if isinstance(values, dict) else {}

    async def subscribe(
        self, topic: str, type_name: str | None = None, *, throttle_rate: int = 0
    ) -> asyncio.Queue[dict[str, Any]]:
        """Subscribe to ``topic``; return the queue its messages arrive on."""
        queue: asyncio.Queue[dict[str, Any]] = asyncio.Queue()
        self._inboxes.setdefault(topic, []).append(queue)
        body: dict[str, Any] = {"op": "subscribe", "topic": topic, "id": f"sub:{topic}"}
        if type_name:
            body["type"] = type_name
        if throttle_rate:
            body["throttle_rate"] = throttle_rate
        await self._send(body)
        return queue

    async def advertise(self, topic: str, type_name: str, *, latch: bool = False) -> None:
        """Advertise ``topic`` as ``type_name`` (once)."""
        if topic in self._advertised:
            return
        body: dict[str, Any] = {"op": "advertise", "topic": topic, "type": type_name}
        if latch:
            body["latch"] = True
        await self._send(body)
        self._advertised.add(topic)

    async def publish(self, topic: str, msg: dict[str, Any], type_name: str | None = None) -> None:
        """Publish ``msg`` on ``topic`` (advertising it first when a type is given)."""
        if type_name is not None:
            await self.advertise(topic, type_name)
        await self._send({"op": "publish", "topic": topic, "msg": msg})

    async def topics(self) -> list[tuple[str, str]]:
        """Return ``(name, type)`` of every topic (``/rosapi/topics``)."""
        values = await self.call_service("/rosapi/topics", {})
        names = values.get("topics") or []
        types = values.get("types") or [""] * len(names)
        return sorted(zip(names, types, strict=False))

    async def topic_type(self, topic: str) -> str:
        """Return the type of ``topic``, or ``""`` when the server does not know it."""
        values = await self.call_service("/rosapi/topic_type", {"topic": topic})
        return str(values.get("type") or "")
