"""Run one roslibpy 2.1.0 scenario against a rosbridge URL (subprocess harness).

    python tests/clients/roslibpy_run.py --url ws://127.0.0.1:PORT --scenario NAME
        [--args JSON] [--timeout-ms N] [--connect-timeout-ms N]

Same contract as tests/js/run.mjs:

* stdout carries exactly one line, printed last:
  ``{"ok":true,"result":...}`` (exit 0) or ``{"ok":false,"error":"..."}`` (exit 1).
  Anything else (roslibpy/Twisted logging, prints) goes to stderr.
* Scenarios live in ``roslibpy_scenarios.SCENARIOS``.
* ``args.authenticate`` (the fields of ``Ros.authenticate``) authenticates on connection,
  before any scenario.
* Failing to connect, an exception, the connection closing mid-scenario or the
  global timeout (default 20000 ms, connect included) give ok:false. The
  Twisted reactor is always stopped (``ros.terminate()``) before the line is
  printed.

roslibpy notes: ``Ros(host, port=None)`` uses ``host`` verbatim as the URL
when ``port`` is None, so the full ``ws://...`` URL is passed as ``host``.
Its factory is a Twisted ReconnectingClientFactory: a refused connection is
retried silently, so failing to connect shows up as "Failed to connect to ROS"
after the connect timeout, and a dropped connection is reconnected (we treat
the drop itself as a failure). The reactor cannot be restarted, hence one
scenario per process.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import sys
import threading
import time
from pathlib import Path
from typing import Any


# Keep the real stdout for the result line; everything else writes to stderr.
_RESULT_OUT = sys.stdout
sys.stdout = sys.stderr

_finish_lock = threading.Lock()
_finishing = False
_ros: Any = None


def _terminate_ros(timeout_s: float = 5.0) -> None:
    """Close the connection and stop the reactor, without hanging forever.

    Runs ``ros.terminate()`` (which joins the reactor thread) in a helper
    thread, so it is safe even when called from the reactor thread.
    """
    if _ros is None:
        return
    t = threading.Thread(target=_ros.terminate, name="roslibpy-terminate", daemon=True)
    t.start()
    t.join(timeout_s)
    if t.is_alive():
        print("[roslibpy_run] ros.terminate() did not finish in time", file=sys.stderr)


def finish(ok: bool, payload: Any) -> None:
    """Print the single result line and exit the process (first caller wins)."""
    global _finishing
    with _finish_lock:
        if _finishing:
            first = False
        else:
            _finishing = True
            first = True
    if not first:
        # Another thread is already finishing and will os._exit() the process.
        threading.Event().wait()
    if ok:
        try:
            line = json.dumps(
                {"ok": True, "result": payload}, allow_nan=False, separators=(",", ":")
            )
        except (TypeError, ValueError) as exc:
            ok = False
            line = json.dumps(
                {"ok": False, "error": f"result is not JSON-serialisable: {exc}"},
                separators=(",", ":"),
            )
    else:
        line = json.dumps({"ok": False, "error": str(payload)}, separators=(",", ":"))
    try:
        _terminate_ros()
    except Exception as exc:
        print(f"[roslibpy_run] terminate failed: {exc!r}", file=sys.stderr)
    _RESULT_OUT.write(line + "\n")
    _RESULT_OUT.flush()
    sys.stderr.flush()
    # os._exit: do not wait for roslibpy/Twisted threads that may still linger.
    os._exit(0 if ok else 1)


def _finish_in_thread(ok: bool, payload: Any) -> None:
    """finish() from a fresh thread (for callbacks running on the reactor thread)."""
    threading.Thread(target=finish, args=(ok, payload), name="finish").start()


def _error_text(exc: BaseException) -> str:
    text = str(exc)
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--url", required=True)
    parser.add_argument("--scenario", required=True)
    parser.add_argument("--args", default="{}", help="JSON object passed to the scenario")
    parser.add_argument("--timeout-ms", type=float, default=20000)
    parser.add_argument("--connect-timeout-ms", type=float, default=10000)
    opts = parser.parse_args()

    try:
        args = json.loads(opts.args)
    except json.JSONDecodeError as exc:
        finish(False, f"--args is not valid JSON: {exc}")
    if not isinstance(args, dict):
        finish(False, "--args must be a JSON object")
    if not opts.url.startswith(("ws://", "wss://")):
        finish(False, f"--url must be ws:// or wss://, got {opts.url}")

    started = time.monotonic()
    watchdog = threading.Timer(
        opts.timeout_ms / 1000, finish, args=(False, f"timeout after {opts.timeout_ms:g} ms")
    )
    watchdog.daemon = True
    watchdog.start()

    logging.basicConfig(
        level=logging.WARNING, stream=sys.stderr, format="%(levelname)s %(name)s: %(message)s"
    )
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import roslibpy
    from roslibpy_scenarios import SCENARIOS

    scenario = SCENARIOS.get(opts.scenario)
    if scenario is None:
        finish(False, f"unknown scenario {opts.scenario!r}; known: {', '.join(sorted(SCENARIOS))}")

    global _ros
    _ros = roslibpy.Ros(opts.url)  # port=None -> the URL is used as given
    if "authenticate" in args:
        # roslibpy sends the rosbridge `auth` op on connection (its documented use), so the
        # fields must be given before connecting: the scenario then runs authenticated
        _ros.authenticate(**args["authenticate"])
    remaining_s = opts.timeout_ms / 1000 - (time.monotonic() - started)
    connect_timeout_s = max(0.1, min(opts.connect_timeout_ms / 1000, remaining_s))
    try:
        _ros.run(timeout=connect_timeout_s)
    except Exception as exc:
        finish(False, f"connection failed: {_error_text(exc)}")
    version = roslibpy.__version__
    print(f"[roslibpy_run] roslibpy {version} connected to {opts.url}", file=sys.stderr)

    # A dropped connection would be retried silently by roslibpy; fail instead.
    # ('close' is emitted on the reactor thread, where finish() must not run.)
    _ros.on("close", lambda _proto: _finish_in_thread(False, "connection closed during scenario"))

    result = scenario(roslibpy, _ros, args)
    finish(True, result)


if __name__ == "__main__":
    try:
        main()
    except SystemExit as exc:
        # argparse errors (usage printed on stderr) still produce a result line.
        if exc.code not in (0, None):
            finish(False, f"bad command line (exit {exc.code})")
        raise
    except BaseException as exc:
        print("[roslibpy_run] scenario failed:", file=sys.stderr)
        import traceback

        traceback.print_exc()
        finish(False, _error_text(exc))
