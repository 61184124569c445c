"""HTTP of the page and /healthz: the httptools server vs the hand-written one it replaced.

First, the parser alone (sans-I/O, one GET /healthz parsed and its response framed, in
microseconds): h11 (the issue's suggestion) beside httptools (llhttp), the choice this measures.
Then both servers, the old hand-written one and the httptools one, answer with the same
:class:`~simbridge.web.WebApp` (the real page), alternating rounds so that load from other
programs lands on both. The client runs in a separate process (``bench.http --client``,
blocking sockets) so that it does not share the server's event loop. Rows: requests per second
and p99 latency of keep-alive GETs of ``/healthz`` (a small JSON) and ``/`` (the page, ~10 KB),
with 1 and 8 connections; ratio = httptools / hand-written requests per second (higher is
better).
"""

from __future__ import annotations

import asyncio
import json
import socket
import statistics
import subprocess
import sys
import threading
import time
from typing import Any

from bench.encoding import _time
from bench.http_handwritten import serve_http as handwritten
from simbridge.app.config import resource_dir
from simbridge.web import HttpResponse, WebApp, serve_http
from simbridge.web.http import _encode, _Parsed


SECONDS = 1.0
ROUNDS = 2
CASES = [("/healthz", 1), ("/healthz", 8), ("/", 1), ("/", 8)]


def _client(port: int, path: str, connections: int, seconds: float) -> dict[str, Any]:
    """Keep-alive GETs on ``connections`` sockets for ``seconds``; latencies in seconds."""
    request = f"GET {path} HTTP/1.1\r\nHost: bench\r\n\r\n".encode()
    latencies: list[list[float]] = [[] for _ in range(connections)]
    end = time.perf_counter() + seconds

    def run(k: int) -> None:
        with socket.create_connection(("127.0.0.1", port)) as s:
            buf = b""
            while time.perf_counter() < end:
                t0 = time.perf_counter()
                s.sendall(request)
                while b"\r\n\r\n" not in buf:
                    buf += s.recv(65536)
                head, _, buf = buf.partition(b"\r\n\r\n")
                length = int(head.lower().split(b"content-length:")[1].split(b"\r\n")[0])
                while len(buf) < length:
                    buf += s.recv(65536)
                buf = buf[length:]
                latencies[k].append(time.perf_counter() - t0)

    threads = [threading.Thread(target=run, args=(k,)) for k in range(connections)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    flat = sorted(x for row in latencies for x in row)
    return {
        "rps": len(flat) / seconds,
        "p50": flat[len(flat) // 2],
        "p99": flat[min(len(flat) - 1, int(0.99 * len(flat)))],
    }


async def _phase(kind: str, path: str, connections: int) -> dict[str, Any]:
    web = WebApp(resource_dir("static"), lambda: {"status": "ok", "clients": 0})
    start = serve_http if kind == "new" else handwritten
    server = await start(web, "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    proc = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "bench.http",
        "--client",
        str(port),
        path,
        str(connections),
        str(SECONDS),
        stdout=subprocess.PIPE,
    )
    out, _ = await proc.communicate()
    server.close()
    await server.wait_closed()
    return dict(json.loads(out))


_REQUEST = b"GET /healthz HTTP/1.1\r\nHost: bench\r\nUser-Agent: bench\r\nAccept: */*\r\n\r\n"


def _parse_h11() -> float | None:
    """Seconds per request: h11 parses it and frames the /healthz answer."""
    try:
        import h11
    except ImportError:
        return None
    body = b'{"status":"ok","clients":0}'
    conn = h11.Connection(h11.SERVER)

    def once() -> None:
        conn.receive_data(_REQUEST)
        request = conn.next_event()
        conn.next_event()
        {k.decode("latin-1"): v.decode("latin-1") for k, v in request.headers}
        head = [(b"Content-Type", b"application/json"), (b"Content-Length", b"27")]
        conn.send(h11.Response(status_code=200, headers=head, reason=b"OK"))
        conn.send(h11.Data(data=body))
        conn.send(h11.EndOfMessage())
        conn.start_next_cycle()

    return _time(once)


def _parse_httptools() -> float:
    """Seconds per request: simbridge's parser (httptools) and framing of the same answer."""
    parsed = _Parsed()
    response = HttpResponse.json({"status": "ok", "clients": 0})

    def once() -> None:
        parsed.parser.feed_data(_REQUEST)
        _request, keep = parsed.ready.popleft()
        _encode(response, False, keep)

    return _time(once)


async def _run() -> int:
    t_h11, t_ht = _parse_h11(), _parse_httptools()
    print("http: parse one GET and frame its answer (sans-I/O, median microseconds)")
    if t_h11 is None:
        print(f"  httptools {t_ht * 1e6:.1f}   (h11 not installed: pip install -e '.[bench]')")
    else:
        print(f"  h11 {t_h11 * 1e6:.1f}   httptools {t_ht * 1e6:.1f}   ratio {t_h11 / t_ht:.1f}x")
    print(f"http: keep-alive GETs, {SECONDS:g} s per row, median of {ROUNDS} rounds")
    print(
        f"{'path':<9} {'conns':>5} {'hand req/s':>10} {'new req/s':>10} {'ratio':>6} "
        f"{'hand p99 ms':>11} {'new p99 ms':>10}"
    )
    for path, conns in CASES:
        runs: dict[str, list[dict[str, Any]]] = {"hand": [], "new": []}
        for _ in range(ROUNDS):
            for kind in ("hand", "new"):
                runs[kind].append(await _phase(kind, path, conns))
        hand = statistics.median(r["rps"] for r in runs["hand"])
        new = statistics.median(r["rps"] for r in runs["new"])
        hand_p99 = statistics.median(r["p99"] for r in runs["hand"]) * 1e3
        new_p99 = statistics.median(r["p99"] for r in runs["new"]) * 1e3
        print(
            f"{path:<9} {conns:>5} {hand:>10.0f} {new:>10.0f} {new / hand:>5.2f}x "
            f"{hand_p99:>11.2f} {new_p99:>10.2f}",
            flush=True,
        )
    return 0


def main(argv: list[str] | None = None) -> int:
    args = argv or []
    if args[:1] == ["--client"]:
        port, path, conns, seconds = args[1:5]
        print(json.dumps(_client(int(port), path, int(conns), float(seconds))))
        return 0
    return asyncio.run(_run())


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
