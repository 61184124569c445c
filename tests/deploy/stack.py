"""The Docker side of the deployment tests: an engine, local images, and compose projects.

Nothing here pulls from a registry: the base image is made with debootstrap (Debian bookworm
minbase + Python) and ``docker import``; the project image is the repository's Dockerfile built
FROM it (``--build-arg BASE_IMAGE``); the web-interface image is Debian's nginx on the same base.
Everything is cached: a second run finds the engine running and the base images present, and
rebuilds the project image from Docker's layer cache.

The arm64 images (a Raspberry Pi 4B/5 with a 64-bit OS) are made the same way, with
``debootstrap --arch arm64`` and ``docker build --platform linux/arm64``, and run here under
Debian's qemu-user-static, registered with the kernel's binfmt_misc (:func:`enable_arm64`).

Several test runs may share this machine and its engine at once: image creation is serialised by
file locks (one per architecture), each run uses its own compose project and free 127.0.0.1
ports, and a run that died leaves containers that the next run removes (its project name carries
its process id). On a fresh machine the images are made in the background while the rest of the
suite runs (``tests/deploy/prepare.py``).
"""

from __future__ import annotations

import contextlib
import fcntl
import glob
import hashlib
import json
import os
import re
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any


ROOT = Path(__file__).resolve().parent.parent.parent
HERE = Path(__file__).resolve().parent
COMPOSE_FILE = ROOT / "docker-compose.yml"
COMPOSE_TEST_FILE = HERE / "compose.test.yml"
NGINX_DOCKERFILE = HERE / "nginx.Dockerfile"

#: Bump the suffix when the recipe changes, so cached images are made again.
BASE_IMAGE = "simbridge-test-base:bookworm-1"
NGINX_IMAGE = "simbridge-test-nginx:bookworm-1"
BASE_PACKAGES = ["python3", "python3-venv", "ca-certificates"]
#: The arm64 twins of the two images (bump the suffix with the recipe, as above).
ARM64_BASE_IMAGE = "simbridge-test-base:bookworm-arm64-1"
ARM64_NGINX_IMAGE = "simbridge-test-nginx:bookworm-arm64-1"
#: Debian's qemu-user-static: the emulator and its binfmt_misc entry (flag F: the kernel
#: opens the emulator when the entry is registered, so it also runs binaries inside containers).
QEMU_AARCH64 = Path("/usr/bin/qemu-aarch64-static")
BINFMT_CONF = Path("/usr/lib/binfmt.d/qemu-aarch64.conf")
BINFMT_DIR = Path("/proc/sys/fs/binfmt_misc")
DEBIAN_MIRROR = os.environ.get("SIMBRIDGE_TEST_DEBIAN_MIRROR", "http://deb.debian.org/debian")
#: Label of the project images the tests build (dangling ones are pruned).
TEST_LABEL = "org.simbridge.test=1"
LOCK_PATH = Path(tempfile.gettempdir()) / "simbridge-test-docker.lock"
DOCKERD_LOG = Path(tempfile.gettempdir()) / "simbridge-test-dockerd.log"
PROJECT_PREFIX = "sbtest"

#: The two compose front ends the course's commands must work with.
COMPOSE_COMMANDS = {"docker-compose": ["docker-compose"], "docker compose": ["docker", "compose"]}

#: The dockerd this process started. It outlives the tests on purpose; keeping its Popen here
#: stops the garbage collector from finalising it mid-run, which warns "subprocess is still
#: running" (an error under the suite's ``filterwarnings = error``).
_STARTED_ENGINES: list[subprocess.Popen[bytes]] = []


def log(text: str) -> None:
    """Print a progress line (shown with ``pytest -s``; kept short)."""
    print(f"[docker] {text}", file=sys.stderr, flush=True)


def run(
    cmd: Sequence[str],
    *,
    timeout: float = 120,
    check: bool = True,
    env: dict[str, str] | None = None,
    input_data: bytes | None = None,
) -> subprocess.CompletedProcess[str]:
    """Run a command; on failure raise with its output (the reason a test failed)."""
    proc = subprocess.run(
        list(cmd),
        capture_output=True,
        timeout=timeout,
        env=env,
        input=input_data,
        check=False,
    )
    out = proc.stdout.decode(errors="replace")
    err = proc.stderr.decode(errors="replace")
    if check and proc.returncode != 0:
        msg = f"{' '.join(cmd)} exited {proc.returncode}:\n{out[-3000:]}\n{err[-3000:]}"
        raise RuntimeError(msg)
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)


@contextlib.contextmanager
def machine_lock(arch: str | None = None) -> Iterator[None]:
    """Hold a machine-wide lock of the Docker test setup.

    Without ``arch``, the engine's and binfmt_misc's; with it, that architecture's images' (an
    arm64 build, minutes under emulation, does not hold up the amd64 tests meanwhile).
    """
    path = LOCK_PATH if arch is None else LOCK_PATH.with_suffix(f".{arch}.lock")
    with path.open("a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def engine_running() -> bool:
    """Whether a Docker engine answers."""
    try:
        return run(["docker", "info"], timeout=30, check=False).returncode == 0
    except subprocess.TimeoutExpired:
        return False


def start_engine(timeout: float = 60) -> str | None:
    """Start dockerd if none runs and this process can; return why not, or None when running.

    dockerd is started detached (it outlives the tests, so the next run starts at once); its log
    is ``$TMPDIR/simbridge-test-dockerd.log``.
    """
    if shutil.which("docker") is None:
        return "the docker client is not installed (`make deps` installs docker.io as root)"
    if engine_running():
        return None
    with machine_lock():
        if engine_running():
            return None
        dockerd = shutil.which("dockerd")
        if dockerd is None:
            return "no Docker engine runs and dockerd is not installed (apt-get install docker.io)"
        if os.geteuid() != 0:
            return "no Docker engine runs and only root can start dockerd here"
        log(f"starting dockerd (log: {DOCKERD_LOG})")
        with DOCKERD_LOG.open("ab") as out:
            proc = subprocess.Popen(
                [dockerd],
                stdin=subprocess.DEVNULL,
                stdout=out,
                stderr=out,
                start_new_session=True,
            )
        _STARTED_ENGINES.append(proc)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if engine_running():
                return None
            if proc.poll() is not None:
                break
            time.sleep(0.5)
        tail = DOCKERD_LOG.read_text(errors="replace").strip().splitlines()[-5:]
        if proc.poll() is None:
            proc.terminate()
        return "dockerd did not start: " + " | ".join(tail)


def image_exists(tag: str) -> bool:
    """Whether the engine has an image with this tag."""
    return run(["docker", "image", "inspect", tag], check=False).returncode == 0


def enable_arm64() -> str | None:
    """Let this kernel run arm64 binaries (qemu-user); return why not, or None when it can.

    Registers Debian's qemu-aarch64 entry with binfmt_misc (mounting binfmt_misc first where a
    container sandbox has not), as ``update-binfmts``/systemd-binfmt would. An entry registered
    without the F flag is replaced: without it the emulator is looked up inside each container.
    """
    if not QEMU_AARCH64.exists() or not BINFMT_CONF.exists():
        return "qemu-user-static is not installed (`make deps` installs it as root)"
    register = BINFMT_DIR / "register"
    entry = BINFMT_DIR / "qemu-aarch64"
    with machine_lock():
        if not register.exists():
            if os.geteuid() != 0:
                return f"binfmt_misc is not mounted on {BINFMT_DIR} and only root can mount it"
            mounted = run(
                ["mount", "-t", "binfmt_misc", "binfmt_misc", str(BINFMT_DIR)], check=False
            )
            if mounted.returncode != 0:
                return f"binfmt_misc cannot be mounted here: {mounted.stderr.strip()}"
        if entry.exists():
            lines = entry.read_text().splitlines()
            flags = next((ln.split(":", 1)[1] for ln in lines if ln.startswith("flags:")), "")
            if lines[:1] == ["enabled"] and "F" in flags:
                return None
            if os.geteuid() != 0:
                return f"{entry} is disabled or lacks the F flag and only root can replace it"
            try:
                entry.write_text("-1")  # unregister, then register Debian's entry below
            except OSError as err:
                return f"cannot replace {entry}: {err}"
        if os.geteuid() != 0:
            return "qemu-aarch64 is not registered with binfmt_misc and only root can register it"
        line = next(ln for ln in BINFMT_CONF.read_text().splitlines() if ln.startswith(":"))
        try:
            register.write_text(line)
        except OSError as err:
            return f"binfmt_misc refused the qemu-aarch64 entry: {err}"
    return None


def ensure_base_image(arch: str = "amd64") -> None:
    """Make the local base image (debootstrap, then ``docker import``) unless it exists.

    Debian bookworm minbase with Python 3.11 and its venv module: what the Dockerfile needs of a
    base. The machine's extra CA certificates go in, so that pip and apt work where outgoing
    TLS is inspected. ``arch="arm64"`` makes the arm64 one (:func:`enable_arm64` first).
    """
    tag = ARM64_BASE_IMAGE if arch == "arm64" else BASE_IMAGE
    if image_exists(tag):
        return
    with machine_lock(arch):
        if image_exists(tag):
            return
        if shutil.which("debootstrap") is None:
            msg = "debootstrap is not installed (`make deps` installs it as root)"
            raise RuntimeError(msg)
        started = time.monotonic()
        with tempfile.TemporaryDirectory(prefix="simbridge-rootfs-", dir="/var/tmp") as tmp:
            rootfs = Path(tmp) / "rootfs"
            cmd = ["debootstrap", "--variant=minbase", f"--include={','.join(BASE_PACKAGES)}"]
            if arch == "arm64":
                cmd.append("--arch=arm64")
            run(
                [*cmd, "bookworm", str(rootfs), DEBIAN_MIRROR],
                timeout=2400 if arch == "arm64" else 900,
            )
            log(f"debootstrap: {time.monotonic() - started:.0f} s")
            for deb in (rootfs / "var/cache/apt/archives").glob("*.deb"):
                deb.unlink()
            shutil.rmtree(rootfs / "var/lib/apt/lists", ignore_errors=True)
            (rootfs / "var/lib/apt/lists/partial").mkdir(parents=True)
            certs = sorted(glob.glob("/usr/local/share/ca-certificates/*.crt"))
            for cert in certs:
                shutil.copy(cert, rootfs / "usr/local/share/ca-certificates")
            if certs:
                run(["chroot", str(rootfs), "update-ca-certificates"])
            if arch == "arm64":
                _import_arm64(rootfs, Path(tmp), tag)
            else:
                _import(rootfs, tag)
        log(f"base image {tag}: {time.monotonic() - started:.0f} s")


def _import(rootfs: Path, tag: str) -> None:
    """``docker import`` a root file system as the image ``tag`` (this host's architecture)."""
    tar = subprocess.Popen(["tar", "-C", str(rootfs), "-c", "."], stdout=subprocess.PIPE)
    assert tar.stdout is not None
    imported = subprocess.run(
        ["docker", "import", "--change", 'CMD ["/bin/bash"]', "-", tag],
        stdin=tar.stdout,
        capture_output=True,
        timeout=300,
        check=False,
    )
    tar.stdout.close()
    if tar.wait() != 0 or imported.returncode != 0:
        msg = f"docker import failed: {imported.stderr.decode(errors='replace')}"
        raise RuntimeError(msg)


def _import_arm64(rootfs: Path, tmp: Path, tag: str) -> None:
    """Make an arm64 root file system the image ``tag``, recorded as linux/arm64.

    Not ``docker import --platform``: an engine without experimental features ignores the
    platform and records the host's, and a ``--platform linux/arm64`` build FROM it would then
    look for an arm64 image in a registry. A build FROM scratch records the platform it is given.
    """
    context = tmp / "context"
    context.mkdir()
    run(["tar", "-C", str(rootfs), "-cf", str(context / "rootfs.tar"), "."], timeout=300)
    (context / "Dockerfile").write_text('FROM scratch\nADD rootfs.tar /\nCMD ["/bin/bash"]\n')
    run(["docker", "build", "--platform", "linux/arm64", "-t", tag, str(context)], timeout=600)


def project_image_tag(arch: str = "amd64") -> str:
    """The project image of this checkout (several checkouts may share the engine)."""
    name = "simbridge-test-arm64:" if arch == "arm64" else "simbridge-test:"
    return name + hashlib.sha1(str(ROOT).encode()).hexdigest()[:12]


def background_cgroup() -> str | None:
    """Make a cgroup that gets CPU only when nothing else wants it; return its path, or None.

    For ``docker build --cgroup-parent``: the build's steps run in containers of the engine, not
    as children of the process that asks for the build, so a scheduling class or a nice value
    does not reach them; a parent cgroup of the least CPU weight does (cgroup v1: ``cpu.shares``
    2, v2: ``cpu.weight`` 1). Only with the engine's cgroupfs driver (a systemd-driven engine
    wants a slice) and where this process may make cgroups; otherwise builds run as usual.
    """
    info = run(
        ["docker", "info", "--format", "{{.CgroupDriver}} {{.CgroupVersion}}"], check=False
    ).stdout.split()
    name = "simbridge-test-background"
    try:
        if info == ["cgroupfs", "1"] and Path("/sys/fs/cgroup/cpu/cpu.shares").exists():
            group = Path("/sys/fs/cgroup/cpu") / name
            group.mkdir(exist_ok=True)
            (group / "cpu.shares").write_text("2")
        elif info == ["cgroupfs", "2"]:
            group = Path("/sys/fs/cgroup") / name
            group.mkdir(exist_ok=True)
            (group / "cpu.weight").write_text("1")  # absent unless the root delegates cpu
        else:
            return None
    except OSError:
        return None
    return f"/{name}"


def build_images(arch: str = "amd64", *, cgroup_parent: str | None = None) -> str:
    """Build the project image (always; layers cached) and the nginx image (once), in parallel.

    ``arch="arm64"``: both for linux/arm64, from the arm64 base (Docker's classic builder, no
    buildx: each RUN step runs under qemu), the project image with the ``dds`` extra (the Pi
    image; its Cyclone DDS binding compiled in the Dockerfile's first stage, once, cached).
    ``cgroup_parent``: the build steps' parent cgroup (:func:`background_cgroup`). Returns the
    project image's tag.
    """
    tag = project_image_tag(arch)
    base, nginx = (
        (ARM64_BASE_IMAGE, ARM64_NGINX_IMAGE)
        if arch == "arm64"
        else (
            BASE_IMAGE,
            NGINX_IMAGE,
        )
    )
    build = ["docker", "build", "--network", "host", "--build-arg", f"BASE_IMAGE={base}"]
    if arch == "arm64":
        build += ["--platform", "linux/arm64"]
    if cgroup_parent is not None:
        build += ["--cgroup-parent", cgroup_parent]
    project = ["--build-arg", "SIMBRIDGE_EXTRAS=dds"] if arch == "arm64" else []
    jobs: list[tuple[str, subprocess.Popen[bytes], tempfile._TemporaryFileWrapper[bytes]]] = []
    started = time.monotonic()

    def spawn(name: str, cmd: list[str], stdin: bytes | None = None) -> None:
        out = tempfile.NamedTemporaryFile(prefix="simbridge-build-")  # noqa: SIM115
        proc = subprocess.Popen(
            cmd, stdin=subprocess.PIPE, stdout=out, stderr=subprocess.STDOUT, cwd=ROOT
        )
        assert proc.stdin is not None
        if stdin is not None:
            proc.stdin.write(stdin)
        proc.stdin.close()
        jobs.append((name, proc, out))

    with machine_lock(arch):
        if not image_exists(nginx):
            # a Dockerfile on stdin: no build context at all
            spawn("nginx image", [*build, "-t", nginx, "-"], NGINX_DOCKERFILE.read_bytes())
        spawn("project image", [*build, *project, "--label", TEST_LABEL, "-t", tag, str(ROOT)])
        failures = []
        for name, proc, out in jobs:
            try:
                code = proc.wait(timeout=1200 if arch == "arm64" else 600)
            except subprocess.TimeoutExpired:
                proc.kill()
                code = -1
            out.seek(0)
            text = out.read().decode(errors="replace")
            out.close()
            if code != 0:
                failures.append(f"{name} build failed ({code}):\n{text[-4000:]}")
    if failures:
        raise RuntimeError("\n".join(failures))
    log(f"images built in {time.monotonic() - started:.1f} s")
    # the previous build of this checkout, now untagged
    run(["docker", "image", "prune", "-f", "--filter", f"label={TEST_LABEL}"], check=False)
    return tag


def free_port() -> int:
    """A TCP port free on 127.0.0.1 right now."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def reap_stale_projects() -> None:
    """Remove containers and networks of test projects whose test process is gone."""
    fmt = '{{.ID}}\t{{.Label "com.docker.compose.project"}}'
    label = "label=com.docker.compose.project"
    containers = run(["docker", "ps", "-a", "--filter", label, "--format", fmt]).stdout
    networks = run(["docker", "network", "ls", "--filter", label, "--format", fmt]).stdout
    stale_containers, stale_networks = [], []
    for lines, stale in ((containers, stale_containers), (networks, stale_networks)):
        for line in lines.splitlines():
            ident, _, project = line.partition("\t")
            found = re.fullmatch(rf"{PROJECT_PREFIX}(\d+)[a-z0-9]*", project)
            if found and not _alive(int(found.group(1))):
                stale.append(ident)
    if stale_containers:
        run(["docker", "rm", "-f", *stale_containers], check=False)
    if stale_networks:
        run(["docker", "network", "rm", *stale_networks], check=False)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


class Stack:
    """One compose project of docker-compose.yml + tests/deploy/compose.test.yml."""

    def __init__(
        self,
        compose: Sequence[str],
        image: str,
        suffix: str,
        extra: Sequence[Path] = (),
        nginx: str = NGINX_IMAGE,
    ) -> None:
        #: The compose command: ``docker-compose`` or ``docker compose``.
        self.compose = list(compose)
        #: Compose files after the test override (e.g. the benchmark's).
        self.files = [COMPOSE_FILE, COMPOSE_TEST_FILE, *extra]
        #: Compose project name (carries this process id, see :func:`reap_stale_projects`).
        self.project = f"{PROJECT_PREFIX}{os.getpid()}{suffix}"
        #: Host ports on 127.0.0.1: the bridge's 9090 and nginx's 8080.
        self.ws_port = free_port()
        self.web_port = free_port()
        self.env = dict(os.environ)
        self.env.update(
            SIMBRIDGE_TEST_IMAGE=image,
            NGINX_IMAGE=nginx,
            WS_PUBLISH=f"127.0.0.1:{self.ws_port}",
            WEB_PUBLISH=f"127.0.0.1:{self.web_port}",
        )

    def command(self, *args: str) -> list[str]:
        """The full compose command line for ``args``."""
        files = [arg for path in self.files for arg in ("-f", str(path))]
        return [*self.compose, "-p", self.project, *files, *args]

    def __call__(
        self, *args: str, timeout: float = 180, check: bool = True
    ) -> subprocess.CompletedProcess[str]:
        """Run a compose sub-command (``up -d``, ``ps``, ``logs``, ``down`` ...)."""
        return run(self.command(*args), timeout=timeout, check=check, env=self.env)

    def containers(self) -> dict[str, str]:
        """Service name -> container id, for this project's containers."""
        fmt = '{{.ID}}\t{{.Label "com.docker.compose.service"}}'
        label = f"label=com.docker.compose.project={self.project}"
        out = run(["docker", "ps", "-a", "--no-trunc", "--format", fmt, "--filter", label]).stdout
        return {svc: ident for ident, _, svc in (ln.partition("\t") for ln in out.splitlines())}

    def inspect(self, service: str) -> dict[str, Any]:
        """``docker inspect`` of a service's container."""
        ident = self.containers()[service]
        return dict(json.loads(run(["docker", "inspect", ident]).stdout)[0])

    def health(self) -> dict[str, str]:
        """Service name -> health status (``starting``, ``healthy``, ``unhealthy``)."""
        out = {}
        for service, ident in self.containers().items():
            state = run(
                ["docker", "inspect", "-f", "{{.State.Status}} {{.State.Health.Status}}", ident]
            ).stdout.split()
            out[service] = state[1] if state[0] == "running" else state[0]
        return out

    def wait_healthy(self, services: Sequence[str], timeout: float = 120) -> dict[str, str]:
        """Wait until every service is healthy; raise with their logs if not in time."""
        deadline = time.monotonic() + timeout
        health: dict[str, str] = {}
        while time.monotonic() < deadline:
            health = self.health()
            if all(health.get(s) == "healthy" for s in services):
                return health
            time.sleep(0.25)
        logs = self("logs", "--no-color", "--tail", "30", check=False).stdout
        msg = f"not healthy after {timeout} s: {health}\n{logs}"
        raise TimeoutError(msg)
