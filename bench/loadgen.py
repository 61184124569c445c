"""A load-generator process: many rosbridge WebSocket clients on one asyncio loop.

    python -m bench.loadgen SPEC_JSON      (prints one JSON line of results on stdout)

SPEC: ``{"url", "clients": [{"subscribe": [topics], "drive": topic or null}], "start", "end"}``
(``"protocol": "foxglove"``: Foxglove WebSocket clients instead, subscribing to the channels of
those topics on a Foxglove port: :class:`_FoxgloveClient`; ``drive`` is not taken there)
with ``start``/``end`` wall-clock seconds (``time.time()``): only messages stamped inside the
window are counted; a client reads until each of its topics has delivered a message stamped
after the window (at most 60 s more). Each client subscribes (``queue_length`` 0: the server's
default bound) and, if ``drive`` is set, publishes a Twist on it at 10 Hz (a slowly turning
command).

The clients are the measuring instrument, so they are kept light: each is websockets' Sans-I/O
protocol on a plain asyncio ``Protocol``, and a message's arrival time is taken when its bytes
are read from the socket, before any of it is parsed (with websockets' asyncio client, a client
read its message only after the loop had handed every other client's frames of the same burst
through a queue and a task switch, adding milliseconds of the load generator's own delay).
websockets makes the handshake and every frame the client sends (masked, as RFC 6455 wants);
once the connection is open, the frames the server sends are cut from the bytes by
:class:`_Frames` (RFC 6455 section 5.2: the server's frames are not masked and simbridge
negotiates no extension), which costs a few microseconds a frame instead of websockets' general
parser (about 4x as much: the load generators shared the 2 cores of the classroom benchmark
with the servers they measure).

Latency is arrival time minus the message's ``header.stamp`` (wall clock of the same host, set
by the server when it publishes). The stamp is read with a regular expression from the head of
the frame. Per client and topic the result lists the stamps received (as integer nanoseconds),
so the caller can find losses by comparing clients with each other.
"""

from __future__ import annotations

import asyncio
import json
import math
import re
import struct
import sys
import time
from typing import Any
from urllib.parse import urlsplit

from websockets.client import ClientProtocol
from websockets.frames import Frame, Opcode
from websockets.http11 import Response
from websockets.protocol import State
from websockets.typing import Subprotocol
from websockets.uri import parse_uri


#: Bytes read from the socket at a time. asyncio's default, 256 kB, is above glibc's mmap
#: threshold (128 kB): each read mapped a fresh 256 kB buffer, faulted its first page in and
#: unmapped it again (mmap, page fault, munmap and a TLB shootdown per read). In the 2 x 300
#: classroom that was half of a load generator's CPU (0.23 -> 0.11 cores each, its kernel part
#: 0.15 -> 0.04). A buffer under the threshold comes from the heap, and a read still takes
#: everything that waits, up to this size.
READ_SIZE = 64 * 1024

_TOPIC = re.compile(rb'"topic":\s*"([^"]+)"')
_STAMP = re.compile(rb'"stamp":\s*\{\s*"sec":\s*(\d+),\s*"nanosec":\s*(\d+)')
_U16 = struct.Struct("!H")
_U64 = struct.Struct("!Q")


class _Frames:
    """Cut a server's WebSocket frames from a byte stream (RFC 6455 section 5.2).

    Frames of the server are not masked; a message in several frames (FIN clear) is joined.
    ``feed`` returns the complete frames as (opcode, payload); continuation frames come out with
    their first frame's opcode.
    """

    def __init__(self) -> None:
        self.buffer = bytearray()
        self.parts: list[bytes] = []
        self.opcode = 0

    def feed(self, data: bytes) -> list[tuple[int, bytes]]:
        buf = self.buffer
        buf += data
        out: list[tuple[int, bytes]] = []
        pos, end = 0, len(buf)
        while end - pos >= 2:
            b0, b1 = buf[pos], buf[pos + 1]
            length, head = b1 & 0x7F, 2
            if length == 126:
                if end - pos < 4:
                    break
                length, head = _U16.unpack_from(buf, pos + 2)[0], 4
            elif length == 127:
                if end - pos < 10:
                    break
                length, head = _U64.unpack_from(buf, pos + 2)[0], 10
            if b1 & 0x80:
                msg = "the server masked a frame (RFC 6455 section 5.1 forbids it)"
                raise ConnectionError(msg)
            if end - pos - head < length:
                break
            payload = bytes(buf[pos + head : pos + head + length])
            pos += head + length
            opcode = b0 & 0x0F
            if opcode >= 0x8:  # control frames are never fragmented
                out.append((opcode, payload))
            elif not b0 & 0x80:  # a first or middle fragment
                if opcode:
                    self.opcode = opcode
                self.parts.append(payload)
            elif opcode == 0 and self.parts:  # the last fragment
                self.parts.append(payload)
                out.append((self.opcode, b"".join(self.parts)))
                self.parts = []
            else:
                out.append((opcode, payload))
        del buf[:pos]
        return out


class _Client(asyncio.Protocol):
    """One rosbridge client: subscribes, optionally drives, records what arrives."""

    def __init__(self, url: str, spec: dict[str, Any], start: float, end: float) -> None:
        self.ws = ClientProtocol(parse_uri(url), max_size=None)
        self.spec = spec
        self.start, self.end = start, end
        self.stamps: dict[str, list[int]] = {t: [] for t in spec["subscribe"]}
        self.arrivals: dict[str, list[float]] = {t: [] for t in spec["subscribe"]}
        self.latencies: list[float] = []
        #: Reads of the socket inside the window (each a system call, and its CPU).
        self.reads = 0
        #: Bytes read inside the window (frames and their WebSocket headers).
        self.bytes = 0
        #: Topics that delivered a message stamped after the window (frames arrive in order).
        self.done: set[str] = set()
        self.finished = asyncio.get_running_loop().create_future()
        self.transport: asyncio.Transport | None = None
        self.open = False
        #: The server's frames once the handshake is done (websockets parses the handshake).
        self.frames: _Frames | None = None
        self.driver: asyncio.Task[None] | None = None

    # -- asyncio.Protocol --------------------------------------------------------------------

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport
        if isinstance(getattr(type(transport), "max_size", None), int):
            transport.max_size = READ_SIZE  # type: ignore[attr-defined]
        self.ws.send_request(self.ws.connect())
        self._flush()

    def data_received(self, data: bytes) -> None:
        now = time.time()
        if self.start <= now < self.end:
            self.reads += 1
            self.bytes += len(data)
        if self.frames is not None:
            self._frames_received(self.frames.feed(data), now)
            return
        self.ws.receive_data(data)
        for event in self.ws.events_received():
            if isinstance(event, Response):
                self._opened()
            elif isinstance(event, Frame) and event.opcode in (Opcode.TEXT, Opcode.BINARY):
                self._message(event.data, now)
        self._flush()  # pongs, close frames
        if self.ws.state is State.CLOSED:
            self._finish(ConnectionError("the server closed the connection"))
        elif self.ws.state is State.OPEN:
            # the handshake's bytes are consumed: from here on, frames are cut by _Frames
            self.frames = _Frames()

    def _frames_received(self, frames: list[tuple[int, bytes]], now: float) -> None:
        for opcode, payload in frames:
            if opcode in (0x1, 0x2):
                self._message(payload, now)
            elif opcode == 0x9:  # ping: pong with the same payload
                self.ws.send_pong(payload)
                self._flush()
            elif opcode == 0x8:
                self.open = False
                self._finish(ConnectionError("the server closed the connection"))

    def connection_lost(self, exc: Exception | None) -> None:
        self._finish(exc or ConnectionError("connection lost"))

    # -- rosbridge -------------------------------------------------------------------------------

    def _send(self, op: dict[str, Any]) -> None:
        self.ws.send_text(json.dumps(op).encode())
        self._flush()

    def _flush(self) -> None:
        assert self.transport is not None
        for chunk in self.ws.data_to_send():
            if chunk:
                self.transport.write(chunk)

    def _opened(self) -> None:
        if self.ws.state is not State.OPEN:
            self._finish(ConnectionError(f"handshake refused: {self.ws.handshake_exc}"))
            return
        self.open = True
        for topic in self.spec["subscribe"]:
            self._send({"op": "subscribe", "topic": topic})
        drive = self.spec.get("drive")
        if drive:
            self._send({"op": "advertise", "topic": drive, "type": "geometry_msgs/msg/Twist"})
            self.driver = asyncio.get_running_loop().create_task(self._drive(drive))

    async def _drive(self, topic: str) -> None:
        k = 0
        t0 = time.monotonic()
        while self.open:
            k += 1
            w = 0.8 * math.sin(k / 15.0)
            msg = {"linear": {"x": 0.2, "y": 0, "z": 0}, "angular": {"x": 0, "y": 0, "z": w}}
            self._send({"op": "publish", "topic": topic, "msg": msg})
            await asyncio.sleep(max(0.0, t0 + k * 0.1 - time.monotonic()))

    def _message(self, raw: bytes, now: float) -> None:
        head = raw[:400]
        m = _STAMP.search(head)
        t = _TOPIC.search(head)
        if m is None or t is None:
            return
        stamp_ns = int(m.group(1)) * 1_000_000_000 + int(m.group(2))
        self._received(t.group(1).decode(), stamp_ns, now)

    def _received(self, topic: str, stamp_ns: int, now: float) -> None:
        if stamp_ns / 1e9 >= self.end:
            self.done.add(topic)
            if len(self.done) >= len(self.stamps):
                self._finish(None)
        if not (self.start <= stamp_ns / 1e9 < self.end):
            return
        if topic in self.stamps:
            self.stamps[topic].append(stamp_ns)
            self.arrivals[topic].append(now)
        self.latencies.append(now - stamp_ns / 1e9)

    def _finish(self, error: BaseException | None) -> None:
        self.open = False
        if self.driver is not None:
            self.driver.cancel()
        if not self.finished.done():
            if error is None:
                self.finished.set_result(None)
            else:
                self.finished.set_exception(error)

    def close(self) -> None:
        """Stop driving and send a close frame (the server then sees a clean close)."""
        self.open = False
        if self.driver is not None:
            self.driver.cancel()
        if self.ws.state is State.OPEN and self.transport is not None:
            self.ws.send_close()
            self._flush()

    def result(self) -> dict[str, Any]:
        return {
            "stamps": self.stamps,
            "arrivals": self.arrivals,
            "latencies": self.latencies,
            "error": None,
        }


#: The Foxglove protocol's binary ``messageData``: opcode 1, subscription id, log time (LE).
_MESSAGE_DATA = struct.Struct("<BIQ")
#: A CDR message's header stamp: after the 4-byte encapsulation, ``int32 sec, uint32 nanosec``.
_CDR_STAMP = struct.Struct("<iI")


class _FoxgloveClient(_Client):
    """One Foxglove WebSocket client (``foxglove.sdk.v1``): subscribes to the topics' channels.

    The stamp is read from the CDR payload's header (every subscribed topic has one first).
    """

    def __init__(self, url: str, spec: dict[str, Any], start: float, end: float) -> None:
        super().__init__(url, spec, start, end)
        self.ws = ClientProtocol(
            parse_uri(url), subprotocols=[Subprotocol("foxglove.sdk.v1")], max_size=None
        )
        self.subscriptions: dict[int, str] = {}

    def _opened(self) -> None:
        if self.ws.state is not State.OPEN:
            self._finish(ConnectionError(f"handshake refused: {self.ws.handshake_exc}"))
            return
        self.open = True  # the server advertises its channels: subscribed in _message

    def _message(self, raw: bytes, now: float) -> None:
        if raw[:1] == b"{":
            body = json.loads(raw)
            if body.get("op") != "advertise":
                return
            subs = []
            for channel in body["channels"]:
                if channel["topic"] in self.stamps:
                    sub_id = len(self.subscriptions) + 1
                    self.subscriptions[sub_id] = channel["topic"]
                    subs.append({"id": sub_id, "channelId": channel["id"]})
            if subs:
                self._send({"op": "subscribe", "subscriptions": subs})
            return
        if len(raw) < _MESSAGE_DATA.size + 12 or raw[0] != 1:
            return
        _, sub_id, _log_time = _MESSAGE_DATA.unpack_from(raw)
        topic = self.subscriptions.get(sub_id)
        if topic is None:
            return
        sec, nanosec = _CDR_STAMP.unpack_from(raw, _MESSAGE_DATA.size + 4)
        self._received(topic, sec * 1_000_000_000 + nanosec, now)


async def _one(url: str, spec: dict[str, Any], start: float, end: float) -> dict[str, Any]:
    loop = asyncio.get_running_loop()
    parts = urlsplit(url)
    kind = _FoxgloveClient if spec.get("protocol") == "foxglove" else _Client
    client = kind(url, spec, start, end)
    transport, _ = await loop.create_connection(
        lambda: client, parts.hostname or "127.0.0.1", parts.port or 80
    )
    result = client.result()
    try:
        await asyncio.wait_for(client.finished, max(1.0, end + 60.0 - time.time()))
    except TimeoutError:
        pass  # a topic never delivered past the window: report what arrived
    except Exception as err:  # what arrived before the error still counts
        result["error"] = f"{type(err).__name__}: {err}"
    finally:
        client.close()
        transport.close()
    result["reads"] = client.reads
    result["bytes"] = client.bytes
    return result


async def _main(spec: dict[str, Any]) -> list[dict[str, Any]]:
    results: list[dict[str, Any]] = [{} for _ in spec["clients"]]

    async def one(i: int, c: dict[str, Any]) -> None:
        if "protocol" in spec:
            c = {**c, "protocol": spec["protocol"]}
        try:
            results[i] = await _one(spec["url"], c, spec["start"], spec["end"])
        except Exception as err:  # reported, not raised: the other clients carry on
            results[i] = {"error": f"{type(err).__name__}: {err}"}

    await asyncio.gather(*(one(i, c) for i, c in enumerate(spec["clients"])))
    return results


def main() -> None:
    spec = json.loads(sys.argv[1])
    results = asyncio.run(_main(spec))
    sys.stdout.write(json.dumps(results) + "\n")


if __name__ == "__main__":
    main()
