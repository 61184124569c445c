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
        "import simbridge.config as c; "
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
