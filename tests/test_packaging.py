from __future__ import annotations

import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from tests.helpers import ROOT


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("wheel")
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--quiet", "-w", str(out), str(ROOT)],
        check=True,
        timeout=300,
    )
    (found,) = out.glob("simbridge-*.whl")
    return found


def test_wheel_carries_the_page_and_the_config(wheel: Path) -> None:
    """static/ and config/ are package data: a plain install has its page, world and params."""
    names = set(zipfile.ZipFile(wheel).namelist())
    assert "simbridge/static/index.html" in names
    assert "simbridge/config/pi4b_params.yaml" in names
    assert "simbridge/config/worlds/default.yaml" in names


def test_installed_package_runs_from_any_directory(wheel: Path, tmp_path: Path) -> None:
    """Installed (non-editable) elsewhere, simbridge finds its bundled files from /."""
    site = tmp_path / "site"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "install",
            "--no-deps",
            "--quiet",
            "--target",
            str(site),
            str(wheel),
        ],
        check=True,
        timeout=300,
    )
    env = {**os.environ, "PYTHONPATH": str(site)}
    code = (
        "import simbridge.app.config as c; "
        "print(c.resource_dir('static')); print(c.default_params_path()); "
        "print(c.load_world(None).name)"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd="/", env=env, timeout=60
    )
    assert result.returncode == 0, result.stderr
    static, params, world = result.stdout.split()
    assert static.startswith(str(site)) and params.startswith(str(site))
    assert world == "default"
    check = subprocess.run(
        [sys.executable, "-m", "simbridge", "check-config"],
        capture_output=True,
        text=True,
        cwd="/",
        env=env,
        timeout=60,
    )
    assert check.returncode == 0, check.stderr


def _fake_venv(tmp_path: Path) -> tuple[Path, Path]:
    """A venv whose python, pip and simbridge only log how they were called (and where)."""
    venv, log = tmp_path / "venv", tmp_path / "calls.log"
    (venv / "bin").mkdir(parents=True)
    for tool in ("python", "pip", "simbridge"):
        script = venv / "bin" / tool
        script.write_text(
            f'#!/bin/sh\necho "{tool} $* (in $PWD, world=$SIMBRIDGE_WORLD)" >> "{log}"\n'
        )
        script.chmod(0o755)
    return venv, log


def _make(venv: Path, *args: str, **env: str) -> list[str]:
    log = venv.parent / "calls.log"
    log.unlink(missing_ok=True)
    done = subprocess.run(
        ["make", "--no-print-directory", f"VENV={venv}", "SETUP_TEST_DEPS=true", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
        env={**os.environ, **env},
    )
    assert done.returncode == 0, done.stderr
    return log.read_text().splitlines() if log.exists() else []


def test_make_run_passes_options_runs_in_the_checkout_and_reinstalls_after_make_deps(
    tmp_path: Path,
) -> None:
    """ARGS and SIMBRIDGE_* reach simbridge, run in the checkout; deps' install is undone.

    `make deps` replaces the plain install by an editable one: the next `make run` installs
    plainly again (its stamp no longer hides the change).
    """
    venv, _ = _fake_venv(tmp_path)
    world = "config/worlds/classroom.yaml"
    calls = _make(venv, "run", f"ARGS=--world {world} --demo-nodes")
    assert calls == [
        f"pip install --quiet . (in {ROOT}, world=)",
        f"simbridge --host 0.0.0.0 --world {world} --demo-nodes (in {ROOT}, world=)",
    ]
    calls = _make(venv, "run", SIMBRIDGE_WORLD=world)
    assert calls == [f"simbridge --host 0.0.0.0 (in {ROOT}, world={world})"]  # installed already
    assert _make(venv, "deps")[0] == f"pip install --quiet -e .[test] (in {ROOT}, world=)"
    assert _make(venv, "run")[0] == f"pip install --quiet . (in {ROOT}, world=)"
    assert (
        _make(venv, "run", "EXTRAS=zenoh")[0] == f"pip install --quiet .[zenoh] (in {ROOT}, world=)"
    )


def test_npm_ci_in_the_node_folders_leaves_the_checkout_clean() -> None:
    """Each package.json has its lock file in git; what `npm ci` installs is ignored."""
    if not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    for folder in ("tests/js", "examples"):
        lock = f"{folder}/package-lock.json"
        tracked = subprocess.run(["git", "ls-files", "--error-unmatch", lock], cwd=ROOT)
        assert tracked.returncode == 0, f"{lock} is not in git"
        ignored = subprocess.run(
            ["git", "check-ignore", "-q", f"{folder}/node_modules/x"], cwd=ROOT
        )
        assert ignored.returncode == 0, f"{folder}/node_modules/ is not ignored"
