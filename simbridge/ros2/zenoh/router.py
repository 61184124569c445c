"""``simbridge zenohd``: a Zenoh router, as ``ros2 run rmw_zenoh_cpp rmw_zenohd`` starts one.

rmw_zenoh nodes (and ``simbridge --zenoh``) find each other through a router at
``tcp/localhost:7447``; this one runs from eclipse-zenoh, so an all-Python classroom needs no
ROS install anywhere. It listens on ``tcp/[::]:7447`` unless told otherwise;
``ZENOH_ROUTER_CONFIG_URI`` and ``ZENOH_CONFIG_OVERRIDE`` apply as for rmw_zenohd.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
from collections.abc import Sequence

from simbridge.errors import ConfigError


__all__ = ["zenohd_main"]


def zenohd_main(argv: Sequence[str]) -> int:
    """Run the router until SIGINT or SIGTERM; return the exit code."""
    parser = argparse.ArgumentParser(
        prog="simbridge zenohd",
        description="Run a Zenoh router for ROS 2 over Zenoh (what rmw_zenohd is for rmw_zenoh).",
    )
    parser.add_argument(
        "--listen",
        metavar="ENDPOINT",
        action="append",
        default=[],
        help="endpoint to listen on (repeatable; default: tcp/[::]:7447)",
    )
    parser.add_argument(
        "--connect",
        metavar="ENDPOINT",
        action="append",
        default=[],
        help="another router to connect to, e.g. on the class server (repeatable)",
    )
    args = parser.parse_args(argv)
    from simbridge.ros2.zenoh.config import router_config
    from simbridge.ros2.zenoh.link import import_zenoh

    try:
        zenoh = import_zenoh("the router")
        config = router_config(zenoh, args.listen, args.connect, os.environ)
    except ConfigError as err:
        print(f"simbridge zenohd: {err}", file=sys.stderr)
        return 2
    try:
        session = zenoh.open(config)
    except Exception as err:  # Zenoh cannot listen (port in use, bad endpoint)
        print(f"simbridge zenohd: cannot start the router: {err}", file=sys.stderr)
        return 2
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    shown = ", ".join(args.listen) or "tcp/[::]:7447"
    print(f"simbridge zenohd: router {session.info.zid()} listening on {shown}", flush=True)
    stop.wait()
    session.close()
    print("simbridge zenohd: stopped", flush=True)
    return 0
