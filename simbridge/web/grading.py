"""The instructor's grading console on ``/admin``: tasks, every student's attempts, CSV.

Each route needs the admin token, as every ``/api/admin/*`` route
(:func:`~simbridge.web.admin.check_admin_token`):

================================  ======  ======================================================
path                              method  what it does
================================  ======  ======================================================
``/api/admin/grading``            GET     the tasks (``published`` or not), every attempt (no
                                          trace), and the best official attempt of each student
                                          on each task
``/api/admin/grading/attempt``    GET     ``?id=a7``: one attempt, its response drawn
                                          (``plot_svg``)
``/api/admin/grading/report``     GET     ``?id=a7``: the attempt's report as an HTML page
``/api/admin/grading.csv``        GET     every attempt, one row each (best attempts marked)
``/api/admin/grading/publish``    POST    ``{"task": "heading_step", "published": true}``
``/api/admin/grading/cancel``     POST    ``{"robot": "r1"}``: end that robot's run now
================================  ======  ======================================================
"""

from __future__ import annotations

import csv
import io
from collections.abc import Callable
from typing import Any

import orjson

from simbridge.app.settings import ServerSettings
from simbridge.errors import ServiceError
from simbridge.grading.grader import Grader
from simbridge.grading.report import report_html
from simbridge.grading.task import METRICS
from simbridge.web.admin import AdminRefused, check_admin_token, token_from_headers
from simbridge.web.http import HttpRequest, HttpResponse, Route


__all__ = ["attempts_csv", "grading_routes"]

#: The CSV's columns before the metrics.
CSV_COLUMNS = (
    "attempt",
    "student",
    "robot",
    "task_id",
    "official",
    "best",
    "time",
    "status",
    "passed",
    "failed_lines",
)


def _cell(value: object) -> object:
    """A CSV cell a spreadsheet shows as text: a string that starts a formula gets a ``'``.

    A student names its own copy of a task (``/grading/start``'s ``task``): an id such as
    ``=HYPERLINK(...)`` was a formula in the instructor's spreadsheet (OWASP "CSV injection").
    """
    if isinstance(value, str) and value[:1] in ("=", "+", "-", "@", "\t", "\r"):
        return "'" + value
    return value


def attempts_csv(grader: Grader) -> str:
    """Return every attempt as CSV: one row each, the metrics as columns."""
    best = {r["attempt"] for r in grader.best()}
    out = io.StringIO()
    writer = csv.writer(out)
    writer.writerow([*CSV_COLUMNS, *METRICS])
    for record in grader.results.attempts.values():
        failed = [line["metric"] for line in record.get("rubric") or [] if not line["passed"]]
        metrics = record.get("metrics") or {}
        writer.writerow(
            _cell(value)
            for value in [
                record.get("attempt"),
                record.get("student"),
                record.get("robot"),
                record.get("task_id"),
                record.get("official"),
                record.get("attempt") in best,
                record.get("time"),
                record.get("status"),
                record.get("passed"),
                " ".join(failed),
                *("" if metrics.get(m) is None else metrics[m] for m in METRICS),
            ]
        )
    return out.getvalue()


def _state(grader: Grader) -> dict[str, Any]:
    return {
        "tasks": [grader.task_summary(t) for _, t in sorted(grader.tasks.items())],
        "attempts": [grader.summary(r) for r in grader.results.attempts.values()],
        "best": grader.best(),
        "running": [run.state() for run in grader.runs.values()],
        "results_file": None if grader.results.path is None else str(grader.results.path),
    }


def _attempt(grader: Grader, request: HttpRequest) -> dict[str, Any]:
    attempt = (request.query.get("id") or [""])[0]
    record = grader.results.attempts.get(attempt)
    if record is None:
        msg = f"no attempt {attempt!r}"
        raise ServiceError(msg)
    return grader.with_plot(record)


def _body(request: HttpRequest) -> dict[str, Any]:
    try:
        value = orjson.loads(request.body or b"{}")
    except orjson.JSONDecodeError as err:
        raise ServiceError(f"request body is not JSON: {err}") from None
    if not isinstance(value, dict):
        raise ServiceError("request body must be a JSON object")
    return value


def _publish(grader: Grader, body: dict[str, Any]) -> dict[str, Any]:
    task, published = body.get("task"), body.get("published", True)
    if not isinstance(task, str) or not isinstance(published, bool):
        msg = 'expected {"task": "ID", "published": true | false}'
        raise ServiceError(msg)
    grader.publish(task, published)
    return {"published": grader.published()}


def _cancel(grader: Grader, body: dict[str, Any]) -> dict[str, Any]:
    robot = body.get("robot")
    if not isinstance(robot, str):
        raise ServiceError('expected {"robot": "r1"}')
    return grader.summary(grader.cancel(robot, "cancelled by the instructor"))


def grading_routes(grader: Grader, settings: ServerSettings) -> dict[str, Route]:
    """Return the grading routes of ``/admin`` (the module docstring), by path.

    The builder adds them to the page's :class:`~simbridge.web.http.WebApp`.
    """
    gets: dict[str, Callable[[HttpRequest], HttpResponse]] = {
        "/api/admin/grading": lambda r: HttpResponse.json(_state(grader)),
        "/api/admin/grading/attempt": lambda r: HttpResponse.json(_attempt(grader, r)),
        "/api/admin/grading/report": lambda r: _html(report_html(_attempt(grader, r))),
        "/api/admin/grading.csv": lambda r: _csv(attempts_csv(grader)),
    }
    posts: dict[str, Callable[[dict[str, Any]], dict[str, Any]]] = {
        "/api/admin/grading/publish": lambda b: _publish(grader, b),
        "/api/admin/grading/cancel": lambda b: _cancel(grader, b),
    }

    def route(request: HttpRequest) -> HttpResponse:
        path = request.path.rstrip("/")
        want = "GET" if path in gets else "POST"
        if request.method != want:
            response = HttpResponse.json({"error": f"use {want} for {path}"}, 405)
            response.headers["Allow"] = want
            return response
        try:
            check_admin_token(settings.admin_token, token_from_headers(request.headers))
            if path in gets:
                return gets[path](request)
            return HttpResponse.json(posts[path](_body(request)))
        except AdminRefused as err:
            return HttpResponse.json({"error": str(err)}, err.status)
        except ServiceError as err:
            return HttpResponse.json({"error": str(err)}, 400)

    return dict.fromkeys((*gets, *posts), route)


def _html(text: str) -> HttpResponse:
    headers = {"Content-Type": "text/html; charset=utf-8", "Cache-Control": "no-store"}
    return HttpResponse(200, text.encode(), headers)


def _csv(text: str) -> HttpResponse:
    headers = {
        "Content-Type": "text/csv; charset=utf-8",
        "Content-Disposition": 'attachment; filename="grading.csv"',
        "Cache-Control": "no-store",
    }
    return HttpResponse(200, text.encode(), headers)
