"""The results journal survives a torn last line and records cut attempts as interrupted."""

from __future__ import annotations

from pathlib import Path

import orjson

from simbridge.grading.results import ResultsLog


def test_a_torn_last_line_and_an_unfinished_attempt_after_a_crash(tmp_path: Path) -> None:
    path = tmp_path / "results.jsonl"
    log = ResultsLog(path)
    log.open()
    for attempt in ("a1", "a2"):
        log.start(attempt, {"task_id": "t", "robot": "r1"})
        log.finish(attempt, {"status": "passed", "passed": True})
    log.start(log.new_id(), {"task_id": "t", "robot": "r1"})  # a3: the crash comes now
    log.publish("t", True)
    log.close()
    with path.open("ab") as f:
        f.write(b'{"kind": "result", "attempt": "a3", "sta')  # torn mid-write
    again = ResultsLog(path)
    assert again.open() == ["a3"]
    assert again.bad_lines == 1
    assert [r["status"] for r in again.attempts.values()] == ["passed", "passed", "interrupted"]
    assert again.published == ["t"]
    assert again.new_id() == "a4"
    again.start("a4", {"task_id": "t"})
    again.close()
    lines = path.read_bytes().splitlines()
    parsed = []
    for raw in lines:
        try:
            parsed.append(orjson.loads(raw))
        except orjson.JSONDecodeError:
            assert raw.startswith(b'{"kind": "result", "attempt": "a3", "sta')
    assert parsed[-1]["attempt"] == "a4"  # the next line starts clean after the torn one
    assert sum(1 for p in parsed if p.get("status") == "interrupted") == 1


def test_without_a_file_results_stay_in_memory() -> None:
    log = ResultsLog(None)
    assert log.open() == []
    log.start("a1", {})
    assert log.attempts["a1"]["status"] == "running"
