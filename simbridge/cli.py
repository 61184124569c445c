"""The ``simbridge`` command.

``simbridge [options]`` runs the server; ``simbridge COMMAND ...`` runs a sub-command
(``check-config``, ``healthcheck``; see ``simbridge --help``). Every option can also be set by
an environment variable ``SIMBRIDGE_<OPTION>`` (e.g. ``SIMBRIDGE_PORT=9091``), validated with the
option's own bounds (:func:`~simbridge.app.settings.environment`): a bad value is refused naming
the variable, with exit code 2 as a bad option is. The options and variables are generated
from the settings' declarations (:mod:`simbridge.app.settings`). The command line wins.
``healthcheck`` reads ``SIMBRIDGE_PORT`` without the settings (it runs every few seconds in a
container): a bad port is an unhealthy probe.
"""

from __future__ import annotations

import argparse
import errno
import logging
import os
import signal
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from simbridge import __version__
from simbridge.app.tuning import import_asyncio, import_hashlib, settle
from simbridge.errors import ConfigError, SimbridgeError


if TYPE_CHECKING:
    from simbridge.app.settings import Declared, ServerSettings

# simbridge.app is imported where it is used: `simbridge healthcheck`, a container's
# HEALTHCHECK every few seconds, then costs a bare interpreter (it matters on a Pi).


__all__ = ["COMMANDS", "main"]


def setup_logging(level: str = "info") -> None:
    """Configure the root logger: one line per notable event, never one per message."""
    logging.basicConfig(
        level=getattr(logging, level.upper(), logging.INFO),
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    logging.getLogger("websockets").setLevel(logging.WARNING)


def _env(name: str, default: str | None) -> str | None:
    return os.environ.get(f"SIMBRIDGE_{name}", default)


def _typed(declared: Declared) -> Callable[[str], Any]:
    """An argparse ``type`` checking a value as the settings do (the field's type and bounds)."""
    from simbridge.app.settings import check

    def parse(text: str) -> Any:
        if text == declared.info.default:
            return text  # argparse passes a text default through ``type`` too: it is valid
        try:
            return check(declared, text)
        except ValueError as err:
            raise argparse.ArgumentTypeError(str(err)) from None

    return parse


def _say_unknown_variables() -> None:
    """Warn of each ``SIMBRIDGE_*`` variable no option reads (only when there are variables)."""
    if not any(k.startswith("SIMBRIDGE_") for k in os.environ):
        return
    from simbridge.app.settings import unknown_variables

    for line in unknown_variables(os.environ):
        print(f"simbridge: warning: {line}", file=sys.stderr)


def _environment() -> dict[str, Any]:
    """Return the validated ``SIMBRIDGE_*`` variables by option name.

    Raises:
        ConfigError: one is invalid (the text names it).
    """
    from simbridge.app.settings import environment

    return environment(os.environ)


class _Items(argparse.Action):
    """A list-valued option: one or more values, repeatable; they replace the variable's."""

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: str | Sequence[Any] | None,
        option_string: str | None = None,
    ) -> None:
        given = getattr(namespace, self.dest)
        kept = () if given is self.default else tuple(given)
        setattr(namespace, self.dest, (*kept, *(values or ())))


def _add_options(
    parser: argparse.ArgumentParser, env: dict[str, Any], names: set[str] | None = None
) -> None:
    """Add the options the settings declare (:class:`~simbridge.app.settings.Option`).

    Each has the field's description, default and variable as its help, the field's type and
    bounds as its check (of each item, for a list), and the variable's value (``env``) as its
    default; ``names``: only those options.
    """
    from simbridge.app.settings import RunOptions, ServerSettings, options

    groups: dict[str, argparse._ArgumentGroup] = {}
    for declared in options(ServerSettings, RunOptions):
        if names is not None and declared.name not in names:
            continue
        group = declared.option.group
        target: argparse._ActionsContainer = parser
        if group is not None:
            if group not in groups:
                groups[group] = parser.add_argument_group(group)
            target = groups[group]
        if declared.flag_only:
            target.add_argument(
                declared.flag,
                action="store_true",
                default=bool(env.get(declared.name, False)),
                help=declared.help(),
            )
            continue
        listed: dict[str, Any] = {} if declared.item is None else {"nargs": "+", "action": _Items}
        target.add_argument(
            declared.flag,
            **listed,
            type=_typed(declared),
            metavar=declared.metavar,
            default=env.get(declared.name, declared.info.default),
            help=declared.help(),
        )


def _check_foxglove(args: argparse.Namespace) -> None:
    """Check that the Foxglove extra is there when --foxglove-port asks for it.

    Raises:
        ConfigError: it is not (the message gives the install command).
    """
    if args.foxglove_port is None:
        return
    from simbridge.foxglove.front import import_foxglove

    import_foxglove()  # exits at once, with the install command, when the extra is missing


def _zenoh_options(args: argparse.Namespace) -> Any:
    """Return the ZenohOptions of ``--zenoh``, or None without it.

    Raises:
        ConfigError: the extra is not installed, or a setting is invalid.
    """
    if not args.zenoh:
        if args.zenoh_connect or args.zenoh_listen:
            msg = "--zenoh-connect and --zenoh-listen (or their variables) need --zenoh"
            raise ConfigError(msg)
        if args.ros_distro and not args.dds:
            msg = "--ros-distro (or SIMBRIDGE_ROS_DISTRO) needs --zenoh or --dds"
            raise ConfigError(msg)
        return None
    from simbridge.ros2.zenoh.config import ZenohOptions
    from simbridge.ros2.zenoh.link import import_zenoh

    import_zenoh()  # exits at once, with the install command, when the extra is missing
    return ZenohOptions.from_env(
        distro=args.ros_distro, connect=args.zenoh_connect, listen=args.zenoh_listen
    )


def _dds_options(args: argparse.Namespace) -> Any:
    """Return the DdsOptions of ``--dds``, or None without it.

    Raises:
        ConfigError: the extra is not installed, or a setting is invalid.
    """
    if not args.dds:
        return None
    from simbridge.ros2.dds.link import import_cyclonedds
    from simbridge.ros2.dds.options import DdsOptions

    import_cyclonedds()  # exits at once, with the install command, when the extra is missing
    return DdsOptions.from_env(distro=args.ros_distro)


def _server_values(args: argparse.Namespace) -> dict[str, Any]:
    """Return the ServerSettings fields of the options (their files read and checked).

    Raises:
        ConfigError: a file is missing or malformed, or the TLS options are incomplete.
    """
    from simbridge.app.config import load_client_tokens
    from simbridge.app.settings import ServerSettings, options

    out: dict[str, Any] = {d.field: getattr(args, d.name) for d in options(ServerSettings)}
    out["http_port"] = None if args.no_http else args.http_port
    out["ping_timeout"] = args.ping_interval  # one option: a peer answers within as long
    out["admin_token"] = args.admin_token or None
    out["ros2_role"] = args.ros2_role or None
    out["foxglove_scope"] = args.foxglove_scope or None
    if args.client_tokens:
        out["client_tokens"] = load_client_tokens(args.client_tokens)
    if args.auth_secret_file:
        try:
            secret = Path(args.auth_secret_file).read_text(encoding="utf-8").strip()
        except OSError as err:
            msg = f"auth secret file '{args.auth_secret_file}': cannot be read ({err.strerror})"
            raise ConfigError(msg) from None
        if len(secret) < 16:
            msg = f"auth secret file '{args.auth_secret_file}': the secret needs 16+ characters"
            raise ConfigError(msg)
        out["auth_secret"] = secret
    if args.allowed_origins:
        out["allowed_origins"] = tuple(
            o.strip().rstrip("/") for o in args.allowed_origins.split(",") if o.strip()
        )
    if args.keyfile and not args.certfile:
        msg = "--keyfile needs --certfile (the certificate chain)"
        raise ConfigError(msg)
    if args.certfile:
        import ssl

        from simbridge.rosbridge.server import tls_context  # imported late: `--help` stays fast

        try:
            tls_context(args.certfile, args.keyfile)
        except (OSError, ssl.SSLError) as err:
            msg = f"TLS: cannot load --certfile/--keyfile: {err}"
            raise ConfigError(msg) from None
    return out


def _run_parser(env: dict[str, Any]) -> argparse.ArgumentParser:
    commands = "\n".join(f"  {name:<14} {text}" for name, (text, _) in COMMANDS.items())
    parser = argparse.ArgumentParser(
        prog="simbridge",
        description=(
            "A rosbridge v2 server with a built-in 2D differential-drive robot (LiDAR, /odom, "
            "/tf, /cmd_vel). Point roslibjs, roslibpy or Foxglove at ws://HOST:PORT/ and open "
            "http://HOST:HTTP-PORT/ to drive the robot from a browser. Every option can be set "
            "by the variable named after it (a repeatable one's values separated by commas)."
        ),
        epilog=f"sub-commands (simbridge COMMAND --help):\n{commands}",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"simbridge {__version__}")
    _add_options(parser, env)
    return parser


#: The most open files :func:`raise_file_limit` asks for.
FILE_LIMIT = 65_536


def raise_file_limit() -> int:
    """Raise this process's soft limit on open files to its hard limit (at most FILE_LIMIT).

    A connection to the WebSocket port holds a file descriptor while websockets waits (up to
    10 s) for its request: 6,000 idle TCP connections from one address took all 1,024 of the
    usual soft limit, and the instructor's connect timed out. Returns the limit now in force
    (0 where the platform has none to raise).
    """
    try:
        import resource
    except ImportError:  # not a Unix
        return 0
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    want = FILE_LIMIT if hard == resource.RLIM_INFINITY else min(hard, FILE_LIMIT)
    if soft != resource.RLIM_INFINITY and soft < want:
        try:
            resource.setrlimit(resource.RLIMIT_NOFILE, (want, hard))
        except (ValueError, OSError):
            return soft
        return want
    return soft


async def _serve(
    settings: ServerSettings,
    world: str | None,
    params: str | None,
    record: tuple[str, list[str] | None] | None = None,
    zenoh: Any = None,
    no_sim: bool = False,
    dds: Any = None,
) -> int:
    import asyncio

    from simbridge.app.runner import App  # imported late: `simbridge --help` stays fast

    try:
        app = App(
            settings,
            world=world,
            params=params,
            zenoh=zenoh,
            no_sim=no_sim,
            dds=dds,
            record=record,
            run_bags=True,
        )
    except SimbridgeError as err:  # the --record bag exists, a results file cannot be read...
        print(f"simbridge: {err}", file=sys.stderr)
        return 2
    try:
        await app.start()
    except OSError as err:
        await app.stop()
        if err.errno == errno.EADDRINUSE:
            print(
                f"simbridge: a port is already in use ({err}); stop the other server or choose "
                "another with --port / --http-port",
                file=sys.stderr,
            )
        else:
            print(f"simbridge: cannot listen: {err}", file=sys.stderr)
        return 2
    settle()  # the heap start-up freed given back, what it built frozen, the GC's thresholds
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    everywhere = settings.host in ("0.0.0.0", "::", "")
    shown = _bracketed("127.0.0.1" if everywhere else settings.host)
    ws, http = ("wss", "https") if settings.certfile else ("ws", "http")  # both ports are TLS
    page = f"  page {http}://{shown}:{app.http_port}/" if app.http_port is not None else ""
    fox = f"  foxglove ws://{shown}:{app.foxglove.port}" if app.foxglove is not None else ""
    print(f"simbridge: rosbridge {ws}://{shown}:{app.ws_port}/{page}{fox}", flush=True)
    lan = _network_address(_in_container()) if everywhere else None
    if lan is not None:  # what an instructor hands out (the first line is for this machine)
        page = f"  page {http}://{lan}:{app.http_port}/" if app.http_port is not None else ""
        print(f"simbridge: from the network: {ws}://{lan}:{app.ws_port}/{page}", flush=True)
    await stop.wait()
    print("simbridge: stopping", flush=True)
    await app.stop()
    if app.recorder is not None:
        print(f"simbridge: recorded {app.recorder.count} messages to {record and record[0]}/")
    return 0


def _in_container() -> bool:
    return Path("/.dockerenv").exists() or Path("/run/.containerenv").exists()


def _bracketed(host: str) -> str:
    """Return ``host`` as a URL writes it (an IPv6 address in brackets)."""
    return f"[{host}]" if ":" in host and not host.startswith("[") else host


def _network_address(in_container: bool) -> str | None:
    """Return the IPv4 address other machines most likely reach this one at, if any.

    The address of the interface with the default route (a UDP socket "connected" to a private
    address: nothing is sent). None without a route (an offline Pi: its address is then the
    one the instructor set) or in a container, whose own address is not the one published.
    """
    if in_container:
        return None
    import socket

    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            probe.connect(("10.254.254.254", 9))
            address = str(probe.getsockname()[0])
    except OSError:
        return None
    return None if address.startswith("127.") or address == "0.0.0.0" else address


def _asks_for_tls(argv: Sequence[str]) -> bool:
    """Whether this run is given a TLS certificate (``--certfile``, or its variable).

    Read before the options are: pydantic-settings imports asyncio, and asyncio is imported
    without ssl when no certificate is given (:func:`~simbridge.app.tuning.import_asyncio`).
    An option argparse reads as ``--certfile`` (a prefix of it, ``--certfile=PEM``) counts.
    """
    if os.environ.get("SIMBRIDGE_CERTFILE", "").strip():
        return True
    return any(
        len(flag) >= 4 and "--certfile".startswith(flag)
        for flag in (arg.partition("=")[0] for arg in argv)
    )


def _cmd_run(argv: Sequence[str]) -> int:
    import_hashlib()  # before anything imports hashlib (websockets, through secrets too)
    import_asyncio(tls=_asks_for_tls(argv))  # before anything imports asyncio
    from simbridge.app.config import load_params, load_world
    from simbridge.app.settings import server_settings

    _say_unknown_variables()  # first: a typo may be why another variable reads as it does
    try:
        env = _environment()
    except ConfigError as err:
        print(f"simbridge: {err}", file=sys.stderr)
        return 2
    args = _run_parser(env).parse_args(argv)
    setup_logging(args.log_level)
    try:
        _check_foxglove(args)
        settings = server_settings(**_server_values(args))
        if args.tasks:
            from simbridge.grading import load_tasks

            if not Path(args.tasks).is_dir():
                msg = f"--tasks: '{args.tasks}' is not a directory of task files"
                raise ConfigError(msg)
            load_tasks(args.tasks)
        # validate before binding anything, so a bad file fails fast and clearly
        load_world(args.world)
        load_params(args.params)
        record = (args.record, args.record_topics) if args.record else None
        zenoh = _zenoh_options(args)
        dds = _dds_options(args)
        raise_file_limit()
        import asyncio

        return asyncio.run(
            _serve(settings, args.world, args.params, record, zenoh, no_sim=args.no_sim, dds=dds)
        )
    except ConfigError as err:
        print(f"simbridge: {err}", file=sys.stderr)
        return 2


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"


def _cmd_check_config(argv: Sequence[str]) -> int:
    from simbridge.app.config import load_params, load_world

    parser = argparse.ArgumentParser(
        prog="simbridge check-config",
        description="Validate a world and a parameter file, as the server does at startup.",
    )
    _say_unknown_variables()
    try:
        env = _environment()
    except ConfigError as err:
        print(f"simbridge: {err}", file=sys.stderr)
        return 2
    _add_options(parser, env, {"world", "params", "tasks"})
    args = parser.parse_args(argv)
    try:
        world = load_world(args.world)
        params = load_params(args.params)
        tasks = None
        if args.tasks:
            from simbridge.grading import load_tasks

            if not Path(args.tasks).is_dir():
                msg = f"--tasks: '{args.tasks}' is not a directory of task files"
                raise ConfigError(msg)
            tasks = load_tasks(args.tasks)
    except ConfigError as err:
        print(f"simbridge: {err}", file=sys.stderr)
        return 2
    print(
        f"ok: world '{world.name}' ({_count(len(world.segments()), 'wall segment')}), robot "
        f"max {params.robot.max_linear_velocity} m/s, LiDAR {params.lidar.rays} rays"
        + ("" if tasks is None else f", {_count(len(tasks), 'task')}")
    )
    return 0


def _cmd_healthcheck(argv: Sequence[str]) -> int:
    parser = argparse.ArgumentParser(
        prog="simbridge healthcheck",
        description="Exit 0 if a simbridge server answers /healthz, else 1 (Docker HEALTHCHECK).",
    )
    parser.add_argument(
        "--url",
        default=_env("HEALTHCHECK_URL", None),
        help="URL to probe (default: http://127.0.0.1:$SIMBRIDGE_PORT/healthz, port 9090)",
    )
    parser.add_argument("--timeout", type=float, default=3.0, help="seconds (default: 3)")
    args = parser.parse_args(argv)
    url = args.url or f"http://127.0.0.1:{_env('PORT', '9090')}/healthz"
    # here, not at the top: urllib.request brings http.client and email (2.6 MB a server never uses)
    import urllib.error
    import urllib.request

    try:
        with urllib.request.urlopen(url, timeout=args.timeout) as response:
            body = response.read()
            ok = response.status == 200 and b'"status":"ok"' in body
    except (urllib.error.URLError, OSError, ValueError) as err:
        print(f"unhealthy: {url}: {err}", file=sys.stderr)
        return 1
    print("healthy" if ok else f"unhealthy: {url} answered {body[:200]!r}")
    return 0 if ok else 1


def _cmd_topic(argv: Sequence[str]) -> int:
    from simbridge.tools.rostool import topic_main

    return topic_main(argv)


def _cmd_service(argv: Sequence[str]) -> int:
    from simbridge.tools.rostool import service_main

    return service_main(argv)


def _cmd_param(argv: Sequence[str]) -> int:
    from simbridge.tools.rostool import param_main

    return param_main(argv)


def _cmd_zenohd(argv: Sequence[str]) -> int:
    from simbridge.ros2.zenoh.router import zenohd_main

    return zenohd_main(argv)


def _cmd_record(argv: Sequence[str]) -> int:
    from simbridge.tools.record import record_main

    return record_main(argv)


def _cmd_replay(argv: Sequence[str]) -> int:
    from simbridge.tools.record import replay_main

    return replay_main(argv)


def _cmd_grade(argv: Sequence[str]) -> int:
    from simbridge.tools.grade import grade_main

    return grade_main(argv)


def _cmd_compare(argv: Sequence[str]) -> int:
    from simbridge.tools.compare import compare_main

    return compare_main(argv)


def _cmd_fit(argv: Sequence[str]) -> int:
    from simbridge.tools.fit import fit_main

    return fit_main(argv)


#: Sub-commands: name -> (one-line help, function(argv) -> exit code).
COMMANDS: dict[str, tuple[str, Callable[[Sequence[str]], int]]] = {
    "check-config": ("validate a world and a parameter file, then exit", _cmd_check_config),
    "healthcheck": ("probe a running server's /healthz; exit 0 or 1", _cmd_healthcheck),
    "topic": ("list|echo|hz|pub topics of any rosbridge URL (as `ros2 topic`)", _cmd_topic),
    "service": ("list|call services of any rosbridge URL (as `ros2 service`)", _cmd_service),
    "param": ("list|get|set parameters through rosapi (as `ros2 param`)", _cmd_param),
    "record": ("record topics of any rosbridge URL into a rosbag2 MCAP bag", _cmd_record),
    "replay": ("replay a bag's /cmd_vel into a server or a headless simulation", _cmd_replay),
    "compare": ("compare the odometry of a simulated and a real run (RMSE, drift)", _cmd_compare),
    "fit": ("fit the realism profile to a real robot's /cmd_vel and /odom bag", _cmd_fit),
    "grade": ("run a task file on a server or headless; report.json, report.html", _cmd_grade),
    "zenohd": (
        "run a Zenoh router for ROS 2 over Zenoh (as rmw_zenohd; [zenoh] extra)",
        _cmd_zenohd,
    ),
}


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; return the exit code."""
    args = list(sys.argv[1:] if argv is None else argv)
    if args and args[0] in COMMANDS:
        return COMMANDS[args[0]][1](args[1:])
    if args and args[0] == "run":
        args = args[1:]
    return _cmd_run(args)
