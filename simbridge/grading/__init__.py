"""Labs that grade themselves: task files, runs scored on the true pose, the class's results.

=============  ================================================================================
``task``       task files (:class:`Task`): start pose, goal, time limit, robot parameters, rubric
``metrics``    the metrics of a run (overshoot, rise and settling time, errors, path, clearance,
               collisions) and the rubric's verdict; pure functions
``results``    the append-only journal of attempts and published tasks (:class:`ResultsLog`)
``report``     a run's report as SVG and HTML (the response with the thresholds drawn)
``grader``     the node on the graph that runs tasks (:class:`Grader`, ``/simbridge/grade/*``)
=============  ================================================================================

:func:`install_grader` builds the grader of a server from its settings (``results_file``,
``tasks_dir``); ``simbridge grade`` (:mod:`simbridge.tools.grade`) is the command line.
"""

from __future__ import annotations

from pathlib import Path

from simbridge.app.config import resource_dir
from simbridge.app.settings import ServerSettings
from simbridge.errors import ConfigError
from simbridge.grading.grader import GRADE_TYPE, Grader, Run
from simbridge.grading.results import Offload, ResultsLog
from simbridge.grading.task import METRICS, Task, load_task, load_tasks, parse_task
from simbridge.graph.graph import Graph
from simbridge.sim import World


__all__ = [
    "GRADE_TYPE",
    "METRICS",
    "Grader",
    "Offload",
    "ResultsLog",
    "Run",
    "Task",
    "default_tasks_dir",
    "install_grader",
    "load_task",
    "load_tasks",
    "parse_task",
]


def default_tasks_dir() -> Path:
    """Return the bundled ``config/tasks`` directory."""
    return resource_dir("config") / "tasks"


def install_grader(
    graph: Graph, world: World, settings: ServerSettings, *, offload: Offload | None = None
) -> Grader:
    """Build the grader of a server: its tasks, its results journal (read back), its services.

    ``offload`` is where the journal's ``fsync`` runs (the server's event-loop executor).

    The task files are read when first needed (``simbridge`` checks a ``--tasks`` directory at
    startup).

    Raises:
        ConfigError: the tasks directory is missing, or the results file cannot be read or created
            (the text names the setting).
    """
    tasks_dir = Path(settings.tasks_dir) if settings.tasks_dir else default_tasks_dir()
    if settings.tasks_dir and not tasks_dir.is_dir():
        msg = f"tasks_dir: '{tasks_dir}' is not a directory of task files"
        raise ConfigError(msg)

    def tasks() -> dict[str, Task]:
        return load_tasks(tasks_dir) if tasks_dir.is_dir() else {}

    path = Path(settings.results_file) if settings.results_file else None
    results = ResultsLog(path, offload=offload)
    try:
        results.open()
    except OSError as err:
        msg = f"results_file: '{path}' cannot be read or created ({err.strerror})"
        raise ConfigError(msg) from None
    bags = path.with_name(f"{path.stem}-bags") if path is not None else None
    return Grader(
        graph, world, results, tasks, bags=bags, max_attempts=settings.grading_max_attempts
    )
