"""Shared fixtures: a real simbridge on 127.0.0.1 (free ports) and the real-client runners."""

from __future__ import annotations

import asyncio
import json
import shutil
import signal
import subprocess
import sys
from collections.abc import AsyncIterator, Awaitable, Callable
from typing import Any

import pytest
from websockets.asyncio.client import ClientConnection, connect

from simbridge.app.runner import App
from simbridge.app.settings import ServerSettings
from tests.helpers import JS_DIR, ROOT, ROSLIBPY_RUN, TIMEOUT_FACTOR, ws_url


def pytest_configure(config: pytest.Config) -> None:
    """Start every child as from a terminal, however the run itself was started.

    A shell starts a background job (``make test &`` in a script, CI runners that do so) with
    SIGINT and SIGQUIT ignored, and every child would inherit that: a test's Ctrl-C (SIGINT)
    to a server or a tool would then test nothing it means to.
    """
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if signal.getsignal(signal.SIGQUIT) is signal.SIG_IGN:
        signal.signal(signal.SIGQUIT, signal.SIG_DFL)


#: The Zenoh tests run first, the deployment tests last (the arm64 ones at the very end): the
#: deployment tests' images are made in the background in between (tests/deploy/prepare.py).
#: First, because the Zenoh tests' flood and discovery checks failed in two of three fresh runs
#: with the images made beside them (one at the normal, one at the idle priority), in none of
#: two without.
_ZENOH = ROOT / "tests" / "ros2" / "zenoh"
_DEPLOY = ROOT / "tests" / "deploy"
_PREPARE = pytest.StashKey[subprocess.Popen[bytes] | None]()
_PREPARE_WANTED = pytest.StashKey[bool]()


def _rank(item: pytest.Item) -> int:
    path = item.path
    if path.is_relative_to(_ZENOH):
        return 0
    if not path.is_relative_to(_DEPLOY):
        return 1
    return 3 if path.name == "test_arm64.py" else 2


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Order the tests as :func:`_rank` says (stable: modules and parameters stay together)."""
    items.sort(key=_rank)
    config.stash[_PREPARE_WANTED] = not config.option.collectonly and any(
        _rank(item) >= 2 for item in items
    )


def pytest_runtest_setup(item: pytest.Item) -> None:
    """Start making the deployment tests' images once the Zenoh tests are done."""
    config = item.config
    if _rank(item) >= 1 and config.stash.get(_PREPARE_WANTED, False):
        config.stash[_PREPARE_WANTED] = False
        from tests.deploy import prepare

        config.stash[_PREPARE] = prepare.start()


def pytest_unconfigure(config: pytest.Config) -> None:
    """Stop the background image maker if the run ended before it did."""
    proc = config.stash.get(_PREPARE, None)
    if proc is not None:
        from tests.deploy import prepare

        prepare.stop(proc)


AppFactory = Callable[..., Awaitable[App]]


@pytest.fixture
async def make_app() -> AsyncIterator[AppFactory]:
    """Start simbridge apps in this test's event loop; stop them afterwards."""
    apps: list[App] = []

    async def factory(
        *, world: Any = None, params: Any = None, seed: int = 0, **settings: Any
    ) -> App:
        options: dict[str, Any] = {"host": "127.0.0.1", "port": 0, "http_port": 0}
        options.update(settings)
        app = App(ServerSettings(**options), world=world, params=params, seed=seed)
        await app.start()
        apps.append(app)
        return app

    yield factory
    for app in apps:
        await app.stop()


@pytest.fixture
async def app(make_app: AppFactory) -> App:
    """A simbridge with the default world and parameters."""
    return await make_app()


@pytest.fixture
async def ws(app: App) -> AsyncIterator[ClientConnection]:
    """A plain WebSocket client connected to ``app``."""
    async with connect(ws_url(app), max_size=None) as conn:
        yield conn


async def _run_client(cmd: list[str], timeout: float) -> Any:
    proc = await asyncio.create_subprocess_exec(
        *cmd,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
        cwd=ROOT,
    )
    try:
        out, err = await asyncio.wait_for(proc.communicate(), timeout + 15)
    except TimeoutError:
        proc.kill()
        await proc.wait()
        raise
    lines = out.decode().strip().splitlines()
    assert lines, f"client printed nothing (exit {proc.returncode}):\n{err.decode()[-3000:]}"
    result = json.loads(lines[-1])
    assert result["ok"], f"client failed: {result.get('error')}\n{err.decode()[-3000:]}"
    return result["result"]


ClientRunner = Callable[..., Awaitable[Any]]


@pytest.fixture(scope="session")
def node_ready() -> None:
    """Check that Node and the pinned roslibjs packages are installed (``make deps``)."""
    assert shutil.which("node"), "node is not installed; run `make deps`"
    assert (JS_DIR / "node_modules" / "roslib1").is_dir(), (
        "tests/js/node_modules is missing; run `make deps` (npm ci --prefix tests/js)"
    )


@pytest.fixture
def run_js(node_ready: None) -> ClientRunner:
    """Run a roslibjs scenario (tests/js/scenarios) with ``lib`` = roslib1 or roslib2."""

    async def runner(
        lib: str, url: str, scenario: str, args: dict[str, Any] | None = None, timeout: float = 20
    ) -> Any:
        t = timeout * TIMEOUT_FACTOR
        cmd = ["node", str(JS_DIR / "run.mjs"), "--lib", lib, "--url", url]
        cmd += ["--scenario", scenario, "--args", json.dumps(args or {})]
        cmd += ["--timeout-ms", str(int(t * 1000))]
        return await _run_client(cmd, t)

    return runner


@pytest.fixture
def run_roslibpy() -> ClientRunner:
    """Run a roslibpy 2.1.0 scenario (tests/clients/roslibpy_scenarios.py)."""

    async def runner(
        url: str, scenario: str, args: dict[str, Any] | None = None, timeout: float = 20
    ) -> Any:
        t = timeout * TIMEOUT_FACTOR
        cmd = [sys.executable, str(ROSLIBPY_RUN), "--url", url, "--scenario", scenario]
        cmd += ["--args", json.dumps(args or {}), "--timeout-ms", str(int(t * 1000))]
        return await _run_client(cmd, t)

    return runner
