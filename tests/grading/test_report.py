"""The report draws the response with the rubric's thresholds, and escapes what people wrote."""

from __future__ import annotations

import math

from simbridge.grading.report import report_html, response_svg


REPORT = {
    "attempt": "a3",
    "robot": "r1",
    "status": "failed",
    "passed": False,
    "task": {"id": "lab", "name": "<b>Lab</b> & co"},
    "metrics": {"overshoot_pct": 25.0, "settling_time_s": 2.5},
    "thresholds": {"overshoot_pct": {"max": 10.0, "min": None}, "settling_time_s": {"max": 4.0}},
    "rubric": [
        {"metric": "overshoot_pct", "value": 25.0, "max": 10.0, "min": None, "passed": False},
    ],
    "response": {
        "t": [0.0, 1.0, 2.0, 3.0],
        "y": [0.0, math.pi / 2 * 1.25, math.pi / 2, math.pi / 2],
        "y0": 0.0,
        "ys": math.pi / 2,
        "band": 0.02 * math.pi / 2,
        "unit": "rad",
    },
}


def test_the_plot_draws_setpoint_band_overshoot_limit_and_settling_limit_in_degrees() -> None:
    svg = response_svg(REPORT)
    assert svg.count("<polyline") == 1
    for label in ("setpoint", "2 % band", "overshoot 10 %", "settling 4 s", "settled 2.5 s"):
        assert label in svg
    assert "(deg)" in svg


def test_the_page_escapes_the_task_name_and_marks_the_failed_line() -> None:
    page = report_html(REPORT)
    assert "&lt;b&gt;Lab&lt;/b&gt; &amp; co: FAILED" in page
    assert '<tr class="bad"><td>overshoot_pct</td><td>25</td><td>&lt;= 10</td><td>FAIL' in page
