"""Make the deployment tests' images in the background while the rest of the suite runs.

On a fresh machine the images of ``tests/deploy`` take about ten minutes to make (the amd64 base
by debootstrap, about a minute; the arm64 base under qemu-user emulation, several; the arm64
project image, whose Cyclone DDS binding compiles under emulation, several more). Made one
after another inside the deployment tests, that time adds to the suite's. So the suite's
``conftest`` starts this module as a separate process when the run includes deployment tests
(:func:`start`, once the Zenoh tests, run first, are done), and orders those tests last: by the
time they run, their images exist or are nearly made.

Nothing depends on this process: each deployment test's fixtures make what is missing
themselves, under the same machine-wide locks (:func:`tests.deploy.stack.machine_lock`), so they
wait for an image this process is making instead of making it twice, and a failure here only
means the fixture makes the image (and reports the failure) itself. The process and its
children (debootstrap, qemu) run in the idle scheduling class and the build steps in a cgroup
of the least CPU weight (:func:`tests.deploy.stack.background_cgroup`): they take mostly the
CPU the tests leave (not all tests are indifferent even so: the Zenoh tests run before this
starts, ``tests/conftest.py``). It logs to
``$TMPDIR/simbridge-test-prepare.log`` and is stopped when the run ends (:func:`stop`).
``SIMBRIDGE_TEST_PREPARE=0`` turns it off.
"""

from __future__ import annotations

import concurrent.futures
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from tests.deploy import stack as docker


LOG_PATH = Path(tempfile.gettempdir()) / "simbridge-test-prepare.log"


def start() -> subprocess.Popen[bytes] | None:
    """Start ``python -m tests.deploy.prepare`` in the background, unless turned off."""
    if os.environ.get("SIMBRIDGE_TEST_PREPARE", "1") == "0":
        return None
    with LOG_PATH.open("ab") as out:
        return subprocess.Popen(
            [sys.executable, "-m", "tests.deploy.prepare"],
            cwd=docker.ROOT,
            stdin=subprocess.DEVNULL,
            stdout=out,
            stderr=out,
            start_new_session=True,  # its own group: stop() ends the docker clients with it
        )


def stop(proc: subprocess.Popen[bytes] | None) -> None:
    """End the background process and its children if it still runs (the run ended first)."""
    if proc is None or proc.poll() is not None:
        return
    for sig in (signal.SIGTERM, signal.SIGKILL):
        try:
            os.killpg(proc.pid, sig)
            proc.wait(timeout=30)
            return
        except ProcessLookupError:
            return
        except subprocess.TimeoutExpired:
            continue


def main() -> int:
    """Make the amd64 and the arm64 images side by side, where the machine can.

    Side by side: the arm64 chain (about ten minutes here) is the run's longest path, and the
    amd64 one (about two, mostly downloading and unpacking) would only delay its start.
    """
    started = time.monotonic()

    def step(text: str) -> None:
        print(f"[prepare] {time.monotonic() - started:6.1f} s {text}", flush=True)

    reason = docker.start_engine()  # first: a dockerd started here keeps the normal class
    if reason is not None:
        step(f"no Docker engine: {reason}")
        return 0
    # the idle class for this thread, the threads below and every child (debootstrap, qemu)
    os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    cgroup = docker.background_cgroup()
    step(f"build steps in cgroup {cgroup or '(the engine default: none could be made)'}")

    def chain(arch: str) -> None:
        if arch == "arm64" and (reason := docker.enable_arm64()) is not None:
            step(f"arm64 skipped: {reason}")
            return
        docker.ensure_base_image(arch)
        step(f"{arch} base image")
        docker.build_images(arch, cgroup_parent=cgroup)
        step(f"{arch} images")

    with concurrent.futures.ThreadPoolExecutor(2) as pool:
        for future in [pool.submit(chain, arch) for arch in ("arm64", "amd64")]:
            try:
                future.result()
            except Exception as err:  # the fixture makes the image and reports the error
                step(f"failed (the tests' fixtures try again): {err}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
