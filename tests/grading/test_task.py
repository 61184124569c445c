"""Task files: validated like world files, one line naming the key; the bundled tasks load."""

from __future__ import annotations

from pathlib import Path

import pytest

from simbridge.errors import ConfigError
from simbridge.grading import default_tasks_dir, load_tasks, parse_task
from simbridge.tools.grade import grade_main


GOOD = """
name: demo
goal: {heading: 1.57}
time_limit: 5
rubric: {overshoot_pct: {max: 10}}
"""


def test_bundled_tasks_load_with_their_file_names_as_ids() -> None:
    tasks = load_tasks(default_tasks_dir())
    assert {"heading_step", "goto_position", "wall_follow"} <= set(tasks)
    assert tasks["heading_step"].goal.kind == "heading"
    assert tasks["goto_position"].goal.position == (1.0, 0.0)


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        (GOOD.replace("overshoot_pct", "overshot"), "rubric: overshot: unknown metric"),
        (GOOD.replace("time_limit: 5", "time_limit: -1"), "time_limit: must be greater than 0"),
        (GOOD.replace("{heading: 1.57}", "{heading: 1.57, position: [1, 0]}"), "goal: give"),
        (GOOD.replace("{max: 10}", "{}"), "rubric.overshoot_pct: give max or min"),
        (GOOD + "robot_params: {mass: 3}\n", "robot_params: mass: a parameter name"),
        (GOOD.replace("{heading: 1.57}", "{waypoints: [[1, 0]]}"), "rubric.overshoot_pct: not"),
        ("goal: [1", "is not valid YAML"),
    ],
)
def test_a_malformed_task_is_refused_in_one_line_naming_the_key(text: str, expected: str) -> None:
    with pytest.raises(ConfigError) as caught:
        parse_task(text, source="task file 'lab.yaml'", task_id="lab")
    message = str(caught.value)
    assert message.startswith("task file 'lab.yaml': ")
    assert expected in message
    assert "\n" not in message


def test_grade_exits_2_with_one_line_on_a_bad_task_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "lab.yaml"
    path.write_text(GOOD.replace("time_limit: 5", "time_limit: soon"))
    assert grade_main([str(path), "--url", "ws://127.0.0.1:9"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0
    assert f"task file '{path}': time_limit:" in err


def test_a_copy_that_asks_something_else_has_another_digest() -> None:
    a = parse_task(GOOD, task_id="lab")
    b = parse_task(GOOD.replace("max: 10", "max: 50"), task_id="lab")
    c = parse_task(GOOD.replace("name: demo", "name: demo\ndescription: words"), task_id="lab")
    assert a.digest() != b.digest()
    assert a.digest() == c.digest()


def test_a_task_sent_by_a_student_may_not_use_yaml_aliases() -> None:
    # 360 bytes whose aliases stand for 9**8 strings: the refusal spelled them out (1 GB, 5 s)
    levels = ['&a0 ["x", "x", "x", "x", "x", "x", "x", "x", "x"]']
    levels += [f"&a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, 8)]
    text = GOOD.replace("name: demo", "name: [" + ", ".join(levels) + "]")
    with pytest.raises(ConfigError) as caught:
        parse_task(text, source="task_yaml", task_id="lab")
    message = str(caught.value)
    assert "is not valid YAML" in message
    assert "aliases" in message
    assert len(message) < 500
