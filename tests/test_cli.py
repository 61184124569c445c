from __future__ import annotations

import asyncio
import hashlib
import hmac
import json
import os
import re
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from simbridge.cli import _network_address
from tests.helpers import ROOT, TIMEOUT_FACTOR


PY = sys.executable


def run(
    *args: str, cwd: Path = ROOT, env: dict[str, str] | None = None
) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [PY, "-m", "simbridge", *args],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=cwd,
        env={**os.environ, **(env or {})},
    )


def test_help_explains_every_option() -> None:
    """--help documents host, ports, world, params and the sub-commands."""
    out = run("--help").stdout
    for option in (
        "--host",
        "--port",
        "--http-port",
        "--world",
        "--params",
        "check-config",
        "healthcheck",
    ):
        assert option in out
    assert "9090" in out and "8080" in out


def test_check_config_accepts_the_bundled_files() -> None:
    """check-config validates the defaults and exits 0."""
    result = run("check-config")
    assert result.returncode == 0
    assert result.stdout.startswith("ok: world 'default'")


def test_check_config_counts_in_english(tmp_path: Path) -> None:
    one = tmp_path / "one.yaml"
    one.write_text("walls:\n  - [0, 0, 1, 0]\n")
    assert "(1 wall segment)," in run("check-config", "--world", str(one)).stdout


def test_check_config_validates_task_files_naming_the_key(tmp_path: Path) -> None:
    assert ", 3 tasks" in run("check-config", "--tasks", str(ROOT / "config" / "tasks")).stdout
    (tmp_path / "lab.yaml").write_text("goal: {heading: 1}\ntime_limit: 5\nrubric: {x: {max: 1}}\n")
    bad = run("check-config", "--tasks", str(tmp_path))
    assert bad.returncode == 2
    assert bad.stderr.startswith(
        f"simbridge: task file '{tmp_path / 'lab.yaml'}': rubric: x: unknown"
    )
    assert bad.stderr.count("\n") == 1


def test_the_readmes_sample_errors_are_what_simbridge_prints(tmp_path: Path) -> None:
    """The world-file and environment errors the README quotes, reproduced word for word."""
    readme = " ".join((ROOT / "README.md").read_text().split())  # quotes may span lines
    world_error = re.search(r"`(simbridge: world file 'lab\.yaml': [^`]+)`", readme)
    env_error = re.search(
        r"`(simbridge: environment variable SIMBRIDGE_STALL_TIMEOUT: [^`]+)`", readme
    )
    assert world_error and env_error
    walls = "".join(f"  - [{n}, 0, {n}, 1]\n" for n in range(3)) + "  - [0, 0, 1]\n"
    (tmp_path / "lab.yaml").write_text(f"walls:\n{walls}")
    result = run("check-config", "--world", "lab.yaml", cwd=tmp_path)
    assert (result.returncode, result.stderr) == (2, world_error[1] + "\n")
    result = run("check-config", env={"SIMBRIDGE_STALL_TIMEOUT": "-5"})
    assert (result.returncode, result.stderr) == (2, env_error[1] + "\n")


def test_bad_world_file_fails_fast_with_the_file_and_the_key(tmp_path: Path) -> None:
    """The server refuses to start on a bad world, naming file and key, exit code 2."""
    bad = tmp_path / "bad.yaml"
    bad.write_text("walls:\n  - [0, 0, 1]\n")
    result = run("--world", str(bad), "--port", "0", "--http-port", "0")
    assert result.returncode == 2
    assert "bad.yaml" in result.stderr and "walls[0]" in result.stderr


def test_bad_params_file_fails_fast_with_one_line_naming_file_field_and_reason(
    tmp_path: Path,
) -> None:
    """A wheel radius of -1 stops the server before it binds: one line, no traceback."""
    bad = tmp_path / "pi.yaml"
    bad.write_text("robot:\n  wheel_radius: -1\n")
    result = run("--params", str(bad), "--port", "0", "--http-port", "0")
    assert result.returncode == 2
    assert result.stderr == (
        f"simbridge: params file '{bad}': robot.wheel_radius: must be greater than 0 (got -1)\n"
    )


async def start_server(
    *extra: str, env: dict[str, str] | None = None
) -> tuple[asyncio.subprocess.Process, int, int]:
    proc = await asyncio.create_subprocess_exec(
        PY,
        "-m",
        "simbridge",
        "--host",
        "127.0.0.1",
        "--port",
        "0",
        "--http-port",
        "0",
        *extra,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
        cwd="/tmp",
        env=env,
    )
    assert proc.stdout is not None
    line = (await asyncio.wait_for(proc.stdout.readline(), 20 * TIMEOUT_FACTOR)).decode()
    match = re.search(r"ws://127\.0\.0\.1:(\d+)/\s+page http://127\.0\.0\.1:(\d+)/", line)
    assert match, line
    return proc, int(match.group(1)), int(match.group(2))


def test_the_address_for_other_machines_is_one_of_this_machine_not_a_container_one() -> None:
    """Printed beside the 127.0.0.1 line when listening everywhere: what an instructor gives."""
    address = _network_address(in_container=False)
    if address is None:
        pytest.skip("no default route here: nothing to print")
    assert not address.startswith("127.")
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as mine:
        mine.bind((address, 0))  # an address of this machine's interfaces
    assert _network_address(in_container=True) is None  # its own address is not the published one


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
async def test_signal_stops_the_server_cleanly_with_exit_0(sig: signal.Signals) -> None:
    """SIGTERM (docker stop) and SIGINT (Ctrl-C) exit 0 without a traceback."""
    proc, _, _ = await start_server()
    proc.send_signal(sig)
    _, err = await asyncio.wait_for(proc.communicate(), 20 * TIMEOUT_FACTOR)
    assert proc.returncode == 0
    assert b"Traceback" not in err


async def test_healthcheck_subcommand_probes_a_running_server() -> None:
    """Simbridge healthcheck exits 0 against a live server and 1 against a dead port."""
    proc, ws_port, _ = await start_server()
    try:
        ok = await asyncio.to_thread(
            run, "healthcheck", "--url", f"http://127.0.0.1:{ws_port}/healthz"
        )
        assert ok.returncode == 0 and "healthy" in ok.stdout
    finally:
        proc.terminate()
        await proc.wait()
    dead = await asyncio.to_thread(
        run, "healthcheck", "--url", f"http://127.0.0.1:{ws_port}/healthz"
    )
    assert dead.returncode == 1


async def test_busy_port_is_a_clear_error() -> None:
    """A port already in use exits 2 and says so."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        result = await asyncio.to_thread(
            run, "--host", "127.0.0.1", "--port", str(port), "--http-port", "0"
        )
    assert result.returncode == 2
    assert "already in use" in result.stderr


async def test_environment_overrides_the_defaults() -> None:
    """SIMBRIDGE_PORT and SIMBRIDGE_HTTP_PORT are used when no option is given."""
    with socket.socket() as a, socket.socket() as b:
        a.bind(("127.0.0.1", 0))
        b.bind(("127.0.0.1", 0))
        ws_port, http_port = a.getsockname()[1], b.getsockname()[1]
    env = {**os.environ, "SIMBRIDGE_PORT": str(ws_port), "SIMBRIDGE_HTTP_PORT": str(http_port)}
    proc = await asyncio.create_subprocess_exec(
        PY,
        "-m",
        "simbridge",
        "--host",
        "127.0.0.1",
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
        cwd="/tmp",
        env=env,
    )
    try:
        assert proc.stdout is not None
        line = (await asyncio.wait_for(proc.stdout.readline(), 20 * TIMEOUT_FACTOR)).decode()
        assert f"ws://127.0.0.1:{ws_port}/" in line and f"http://127.0.0.1:{http_port}/" in line
    finally:
        proc.terminate()
        await proc.wait()


def test_healthcheck_stays_light_without_pydantic_or_numpy() -> None:
    """`simbridge healthcheck` (a container's HEALTHCHECK) imports no config or simulation code."""
    code = (
        "import sys; from simbridge.cli import main; "
        "rc = main(['healthcheck', '--url', 'http://127.0.0.1:1/healthz', '--timeout', '1']); "
        "print(sorted(m for m in ('pydantic', 'yaml', 'numpy', 'websockets') if m in sys.modules))"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=30, check=False
    )
    assert proc.stdout.strip() == "[]", proc.stdout + proc.stderr
    assert "unhealthy" in proc.stderr


def test_the_command_hashes_with_cpythons_own_functions_alike() -> None:
    """`simbridge` hashes without OpenSSL (issue 16): no libcrypto, the same digests.

    Those of websockets' handshake (SHA-1), rosauth (SHA-512) and the page's ETags.
    """
    code = (
        "import json, sys; from simbridge.app.tuning import import_hashlib; import_hashlib(); "
        "import base64, hashlib, hmac; k = b'dGhlIHNhbXBsZSBub25jZQ==' "
        "b'258EAFA5-E914-47DA-95CA-C5AB0DC85B11'; "
        "print(json.dumps([sorted(m for m in ('_hashlib', '_ssl') if m in sys.modules), "
        "'libcrypto' in open('/proc/self/maps').read(), "
        "base64.b64encode(hashlib.sha1(k).digest()).decode(), "
        "[hashlib.new(n, k).hexdigest() for n in ('md5', 'sha256', 'sha512', 'sha3_256')], "
        "hmac.new(b'secret', k, 'sha512').hexdigest(), "
        "sorted(hashlib.algorithms_guaranteed - set(dir(hashlib)))]))"
    )
    proc = subprocess.run(
        [PY, "-c", code], capture_output=True, text=True, timeout=30, check=True, cwd=ROOT
    )
    imported, libcrypto, accept, digests, mac, missing = json.loads(proc.stdout)
    assert imported == [] and not libcrypto
    key = b"dGhlIHNhbXBsZSBub25jZQ==258EAFA5-E914-47DA-95CA-C5AB0DC85B11"
    assert accept == "s3pPLMBiTxaQ9kYGzzhZRbK+xOo="  # RFC 6455 section 1.3
    assert digests == [
        hashlib.new(n, key).hexdigest() for n in ("md5", "sha256", "sha512", "sha3_256")
    ]
    assert mac == hmac.new(b"secret", key, "sha512").hexdigest()
    assert missing == []


async def test_use_sim_time_flag_stamps_headers_with_sim_time() -> None:
    """`simbridge --use-sim-time`: /odom header stamps count from 0, not from the epoch."""
    proc = await asyncio.create_subprocess_exec(
        *(PY, "-m", "simbridge", "--host", "127.0.0.1", "--port", "0", "--no-http"),
        "--use-sim-time",
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
        cwd=ROOT,
    )
    try:
        assert proc.stdout is not None
        line = (await asyncio.wait_for(proc.stdout.readline(), 20 * TIMEOUT_FACTOR)).decode()
        url = line.split()[2].rstrip("/")
        echo = await asyncio.to_thread(
            run, "topic", "echo", "/odom", "--once", "--field", "header.stamp.sec", "--url", url
        )
        assert echo.returncode == 0, echo.stderr
        assert 0 <= int(echo.stdout.splitlines()[0]) < 600
    finally:
        proc.terminate()
        await proc.wait()


@pytest.mark.parametrize(
    ("variable", "value", "why"),
    [
        ("SIMBRIDGE_STALL_TIMEOUT", "-5", "greater than 0 (got '-5')"),
        ("SIMBRIDGE_MAX_CLIENTS", "abc", "valid integer"),
        ("SIMBRIDGE_PORT", "70000", "less than or equal to 65535"),
        ("SIMBRIDGE_PING_INTERVAL", "nan", "finite number"),
        ("SIMBRIDGE_USE_SIM_TIME", "maybe", "valid boolean"),
        ("SIMBRIDGE_LOG_LEVEL", "loud", "'debug', 'info', 'warning' or 'error'"),
    ],
)
@pytest.mark.parametrize("command", [[], ["check-config"]])
def test_bad_environment_variable_is_refused_naming_it(
    variable: str,
    value: str,
    why: str,
    command: list[str],
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """A bad SIMBRIDGE_* value stops the command with exit 2 and names the variable (no trace)."""
    from simbridge.cli import main

    monkeypatch.setenv(variable, value)
    assert main(command) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"simbridge: environment variable {variable}: "), err
    assert why in err
    assert "Traceback" not in err


@pytest.mark.parametrize(
    ("option", "value", "why"),
    [
        ("--stall-timeout", "-5", "greater than 0 (got '-5')"),
        ("--max-clients", "abc", "valid integer"),
        ("--port", "70000", "less than or equal to 65535"),
        ("--ros-distro", "rolling", "'humble', 'jazzy' or 'kilted' (got 'rolling')"),
    ],
)
def test_bad_option_is_refused_like_the_environment(
    option: str, value: str, why: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """The same bounds on the command line: argparse's exit 2 and the same words."""
    from simbridge.cli import main

    with pytest.raises(SystemExit) as exc:
        main([option, value])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert f"argument {option}: must be" in err
    assert why in err


def test_repeatable_options_replace_their_variables_and_no_http_closes_the_http_port(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """A list option's values replace its variable's; SIMBRIDGE_NO_HTTP is --no-http."""
    from simbridge.app.settings import environment
    from simbridge.cli import _run_parser, _server_values

    env = environment(
        {
            "SIMBRIDGE_ZENOH_CONNECT": "tcp/10.0.0.1:7447,tcp/10.0.0.2:7447",
            "SIMBRIDGE_RECORD_TOPICS": "/odom",
            "SIMBRIDGE_NO_HTTP": "1",
        }
    )
    args = _run_parser(env).parse_args([])
    assert args.zenoh_connect == ("tcp/10.0.0.1:7447", "tcp/10.0.0.2:7447")
    assert args.record_topics == ("/odom",) and args.zenoh_listen == ()
    assert _server_values(args)["http_port"] is None
    given = ["--zenoh-connect", "tcp/a:7447", "--zenoh-connect", "tcp/b:7447"]
    args = _run_parser(env).parse_args([*given, "--record-topics", "/tf", "/cmd_vel"])
    assert args.zenoh_connect == ("tcp/a:7447", "tcp/b:7447")
    assert args.record_topics == ("/tf", "/cmd_vel")
    assert _server_values(_run_parser({}).parse_args([]))["http_port"] == 8080
    with pytest.raises(SystemExit) as exc:
        _run_parser({}).parse_args(["--zenoh-listen", ""])
    assert exc.value.code == 2
    assert "argument --zenoh-listen: must not be empty (got '')" in capsys.readouterr().err


def test_empty_environment_variable_means_the_default() -> None:
    """SIMBRIDGE_PORT= (set but empty, as compose's ${VAR:-} gives) is the option's default."""
    from simbridge.app.settings import environment

    assert environment({"SIMBRIDGE_PORT": "", "SIMBRIDGE_MAX_CLIENTS": "  "}) == {}
    assert environment({"SIMBRIDGE_MAX_CLIENTS": "7", "HOME": "/root"}) == {"max_clients": 7}


def test_the_server_raises_its_soft_limit_on_open_files_to_the_hard_one() -> None:
    """1,024 descriptors were 6,000 idle TCP connections' to take (issue 29's red team)."""
    import resource

    from simbridge.cli import FILE_LIMIT, raise_file_limit

    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    want = FILE_LIMIT if hard == resource.RLIM_INFINITY else min(hard, FILE_LIMIT)
    try:
        resource.setrlimit(resource.RLIMIT_NOFILE, (min(256, want), hard))
        assert raise_file_limit() == want
        assert resource.getrlimit(resource.RLIMIT_NOFILE) == (want, hard)
    finally:
        resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))


@pytest.mark.parametrize("command", [[], ["check-config"]])
@pytest.mark.parametrize(
    ("variable", "value"),
    [("SIMBRIDGE_WORLD", "/nonexistent/world.yaml"), ("SIMBRIDGE_STALL_TIMEOUT", "-5")],
)
def test_a_variable_no_option_reads_is_said_with_the_closest_one(
    command: list[str],
    variable: str,
    value: str,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """A typo in a SIMBRIDGE_* name is a warning naming the variable meant, not silence.

    Said first, also when another variable (a bad value, a file that is not there) stops the
    command; not for the tools' own variables, nor for a blank one.
    """
    from simbridge.cli import main

    monkeypatch.setenv("SIMBRIDGE_MAX_CLIENT", "3")
    monkeypatch.setenv("SIMBRIDGE_URL", "ws://127.0.0.1:9090")  # the tools' variable
    monkeypatch.setenv("SIMBRIDGE_EXTRAS", "dds")  # the image's build argument
    monkeypatch.setenv("SIMBRIDGE_NOTHING", " ")  # blank: unset
    monkeypatch.setenv(variable, value)
    assert main(command) == 2
    first, *rest = capsys.readouterr().err.splitlines()
    assert first == (
        "simbridge: warning: SIMBRIDGE_MAX_CLIENT is not a setting "
        "(did you mean SIMBRIDGE_MAX_CLIENTS?): ignored"
    )
    assert rest and rest[0].startswith("simbridge: ") and "warning" not in rest[0]
    assert not any(n in "\n".join(rest) for n in ("_URL", "_EXTRAS", "_NOTHING"))
