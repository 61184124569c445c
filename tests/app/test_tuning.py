from __future__ import annotations

import json
import subprocess
import sys

from simbridge.app.tuning import GC_THRESHOLDS


def test_settle_freezes_start_up_and_sets_the_running_thresholds() -> None:
    """What the command does once the server runs, an embedder gets the same (its own process)."""
    code = (
        "import gc, json; from simbridge.app.tuning import settle; before = gc.get_threshold(); "
        "kept = [[] for _ in range(9)]; settle(); "
        "print(json.dumps([before, gc.get_threshold(), gc.get_freeze_count()]))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=60
    ).stdout
    before, after, frozen = json.loads(out)
    assert tuple(before) != GC_THRESHOLDS  # importing simbridge changes nothing by itself
    assert tuple(after) == GC_THRESHOLDS and frozen >= 9
