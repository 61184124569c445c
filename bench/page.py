"""The student page in headless chromium: page weight, bytes per second, renderer CPU.

Two pages side by side in one run, on the same (current) server: the page as it was before
issue 13 (``static/`` at :data:`BASELINE`, extracted with ``git archive``) and the current
``static/``. Each case gets a fresh browser, so the renderer processes measured are that page's
own. For each page and world (default, classroom):

* page weight: bytes transferred to load the page (CDP ``Network.loadingFinished``
  ``encodedDataLength``: headers and bodies of every HTTP response);
* bytes per second the page receives over its WebSocket (CDP ``webSocketFrameReceived``
  payload sizes; binary frames, which CDP gives in base64, counted decoded) over
  :data:`WINDOW_S` seconds parked, then driving (W and A held: a circle);
* the renderer's CPU over the same windows: user + system seconds of the browser's renderer
  processes (``psutil``) per wall second, and the main thread's busy time (CDP
  ``Performance.getMetrics`` ``TaskDuration``).

``python -m bench page`` (about 2 minutes). Needs Debian's chromium and Playwright (``make
deps``). Run under the heavy lock on a shared machine: CPU figures are the renderer's own
counters, but a busy machine still delays its work.
"""

from __future__ import annotations

import asyncio
import base64
import re
import subprocess
import sys
import tarfile
import tempfile
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import psutil
from playwright.async_api import Page, async_playwright

from bench.procs import ROOT, stop


#: The commit whose static/ is the "before" page (main when issue 13 was started).
BASELINE = "65d96de"
WINDOW_S = 10.0
CHROMIUM = "/usr/bin/chromium"
WORLDS = ("default", "classroom")


def _serve(static: str, world: str) -> None:
    """Child process: a simbridge App serving ``static`` on free ports; prints the ports."""
    from simbridge.app.runner import App
    from simbridge.app.settings import ServerSettings

    async def run() -> None:
        settings = ServerSettings(host="127.0.0.1", port=0, http_port=0)
        app = App(settings, world=world if world != "default" else None, static_dir=Path(static))
        await app.start()
        print(f"ports {app.ws_port} {app.http_port}", flush=True)
        await asyncio.Event().wait()

    asyncio.run(run())


def _baseline_static(into: Path) -> Path:
    """Extract ``static/`` of :data:`BASELINE` into ``into``; return its path."""
    archive = subprocess.run(
        ["git", "-C", str(ROOT), "archive", BASELINE, "static"],
        check=True,
        capture_output=True,
    ).stdout
    tar = into / "baseline.tar"
    tar.write_bytes(archive)
    with tarfile.open(tar) as t:
        t.extractall(into, filter="data")
    return into / "static"


def _world_path(world: str) -> str:
    return world if world == "default" else str(ROOT / "config" / "worlds" / f"{world}.yaml")


def _renderers(marker: str) -> list[psutil.Process]:
    for proc in psutil.process_iter(["cmdline"]):
        cmd = proc.info["cmdline"] or []
        if marker in cmd:
            return [
                c
                for c in proc.children(recursive=True)
                if "--type=renderer" in " ".join(c.cmdline())
            ]
    return []


def _cpu(procs: list[psutil.Process]) -> float:
    total = 0.0
    for p in procs:
        try:
            t = p.cpu_times()
            total += t.user + t.system
        except psutil.NoSuchProcess:
            pass
    return total


@dataclass
class Figures:
    weight: int = 0
    parked_bps: float = 0.0
    driving_bps: float = 0.0
    parked_cpu: float = 0.0
    driving_cpu: float = 0.0
    parked_main: float = 0.0
    driving_main: float = 0.0


async def _window(page: Page, cdp: Any, counter: list[int], marker: str) -> tuple[float, ...]:
    procs = _renderers(marker)
    loop = asyncio.get_running_loop()
    m0 = await cdp.send("Performance.getMetrics")
    b0, c0, t0 = counter[0], _cpu(procs), loop.time()
    await asyncio.sleep(WINDOW_S)
    m1 = await cdp.send("Performance.getMetrics")
    b1, c1, t1 = counter[0], _cpu(procs), loop.time()

    def task(m: dict[str, Any]) -> float:
        return float(next(x["value"] for x in m["metrics"] if x["name"] == "TaskDuration"))

    dt = t1 - t0
    return (b1 - b0) / dt, (c1 - c0) / dt, (task(m1) - task(m0)) / dt


async def _measure(static: Path, world: str) -> Figures:
    proc = subprocess.Popen(
        [sys.executable, "-m", "bench.page", "serve", str(static), _world_path(world)],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
        cwd=ROOT,
    )
    try:
        assert proc.stdout is not None
        match = re.match(r"ports (\d+) (\d+)", proc.stdout.readline())
        if match is None:
            msg = "the bench server did not start"
            raise RuntimeError(msg)
        ws, http = match.groups()
        marker = f"--simbridge-bench={uuid.uuid4().hex}"
        fig = Figures()
        async with async_playwright() as pw:
            browser = await pw.chromium.launch(
                executable_path=CHROMIUM,
                args=["--headless", "--no-sandbox", "--disable-gpu", marker],
            )
            ctx = await browser.new_context(viewport={"width": 1280, "height": 800})
            page = await ctx.new_page()
            cdp = await ctx.new_cdp_session(page)
            await cdp.send("Network.enable")
            await cdp.send("Performance.enable")
            received = [0]
            weight = [0]

            def on_frame(ev: dict[str, Any]) -> None:
                frame = ev["response"]
                data = frame["payloadData"]
                # CDP gives binary frames (CBOR) in base64: count the bytes that travelled
                binary = frame.get("opcode") == 2
                received[0] += len(base64.b64decode(data)) if binary else len(data.encode())

            def on_loaded(ev: dict[str, Any]) -> None:
                weight[0] += int(ev["encodedDataLength"])

            cdp.on("Network.webSocketFrameReceived", on_frame)
            cdp.on("Network.loadingFinished", on_loaded)
            await page.goto(f"http://127.0.0.1:{http}/?url=ws://127.0.0.1:{ws}")
            await page.wait_for_function(
                "window.simbridge && window.simbridge.conn.connected"
                " && window.simbridge.state.pose",
                timeout=20_000,
            )
            await page.wait_for_load_state("networkidle")
            await asyncio.sleep(2.0)  # settle: discovery, parameters
            fig.weight = weight[0]
            fig.parked_bps, fig.parked_cpu, fig.parked_main = await _window(
                page, cdp, received, marker
            )
            await page.locator("#view").click()  # focus on the page, not a control
            await page.keyboard.down("w")
            await page.keyboard.down("a")
            fig.driving_bps, fig.driving_cpu, fig.driving_main = await _window(
                page, cdp, received, marker
            )
            await page.keyboard.up("w")
            await page.keyboard.up("a")
            await browser.close()
        return fig
    finally:
        stop(proc)


def _ratio(after: float, before: float) -> str:
    return f"{after / before:6.2f}x" if before else "   n/a"


async def _run() -> int:
    with tempfile.TemporaryDirectory() as tmp:
        pages = {"before": _baseline_static(Path(tmp)), "after": ROOT / "static"}
        print(
            f"page: headless chromium 1280x800, {WINDOW_S:.0f} s windows; before = static/ of "
            f"{BASELINE}, after = this checkout's static/, same server; ratio = after / before"
        )
        for world in WORLDS:
            figs = {name: await _measure(static, world) for name, static in pages.items()}
            b, a = figs["before"], figs["after"]
            print(f"  world {world}:")
            rows = [
                ("page weight (KiB on load)", b.weight / 1024, a.weight / 1024, "8.1f"),
                ("received parked (KiB/s)", b.parked_bps / 1024, a.parked_bps / 1024, "8.1f"),
                ("received driving (KiB/s)", b.driving_bps / 1024, a.driving_bps / 1024, "8.1f"),
                ("renderer CPU parked (%)", b.parked_cpu * 100, a.parked_cpu * 100, "8.1f"),
                ("renderer CPU driving (%)", b.driving_cpu * 100, a.driving_cpu * 100, "8.1f"),
                ("main thread busy parked (%)", b.parked_main * 100, a.parked_main * 100, "8.1f"),
                (
                    "main thread busy driving (%)",
                    b.driving_main * 100,
                    a.driving_main * 100,
                    "8.1f",
                ),
            ]
            for label, before, after, f in rows:
                print(
                    f"    {label:<30} before {before:{f}}  after {after:{f}}  "
                    f"{_ratio(after, before)}"
                )
    return 0


def main() -> int:
    return asyncio.run(_run())


if __name__ == "__main__":
    if sys.argv[1:2] == ["serve"]:
        _serve(sys.argv[2], sys.argv[3])
    else:
        raise SystemExit(main())
