"""A run's report as people read it: the response plotted with the rubric drawn on it.

:func:`response_svg` draws the response (or, for waypoints, the distance to the next one)
against time, with the setpoint, the 2 % band, the overshoot limit and the time limits of the
rubric; :func:`report_html` puts it in a self-contained page (no script, no external file)
with the metrics and the verdict of each rubric line. The page, ``/admin`` and ``simbridge
grade`` (``report.html``) show the same drawing.
"""

from __future__ import annotations

import html
import math
from typing import Any


__all__ = ["report_html", "response_svg"]

_W, _H = 640, 300
_L, _R, _T, _B = 56, 12, 14, 36


def _fmt(v: float) -> str:
    return f"{v:.4g}"


def response_svg(report: dict[str, Any]) -> str:
    """Return an SVG drawing of ``report``'s response and thresholds."""
    resp = report.get("response") or {}
    t: list[float] = list(resp.get("t") or [])
    y: list[float] = list(resp.get("y") or [])
    thresholds: dict[str, dict[str, Any]] = report.get("thresholds") or {}
    degrees = resp.get("unit") == "rad"
    k = 180.0 / math.pi if degrees else 1.0
    unit = "deg" if degrees else "m"
    lines: list[tuple[str, float, str]] = []  # (label, value, colour) horizontal
    vlines: list[tuple[str, float, str]] = []
    if y:
        y0, ys, band = resp["y0"] * k, resp["ys"] * k, resp["band"] * k
        y = [v * k for v in y]
        what = "response"
        lines.append(("setpoint", ys, "#2a7"))
        lines += [("2 % band", ys + band, "#9c9"), ("", ys - band, "#9c9")]
        over = thresholds.get("overshoot_pct", {}).get("max")
        if over is not None and abs(ys - y0) > 1e-12:
            sign = 1.0 if ys >= y0 else -1.0
            lines.append((f"overshoot {over:g} %", ys + sign * abs(ys - y0) * over / 100, "#d33"))
    else:  # waypoints: the distance to the next one
        y = [v for v in (resp.get("error") or [])]
        what = "distance to the next waypoint"
        if resp.get("tolerance") is not None:
            lines.append(("tolerance", float(resp["tolerance"]), "#2a7"))
    for name, label in (("settling_time_s", "settling"), ("time_to_goal_s", "to goal")):
        limit = thresholds.get(name, {}).get("max")
        if limit is not None:
            vlines.append((f"{label} {limit:g} s", float(limit), "#d33"))
    metrics = report.get("metrics") or {}
    settled = metrics.get("settling_time_s")
    if settled is not None and y and resp.get("ys") is not None:
        vlines.append((f"settled {settled:g} s", float(settled), "#888"))
    t_max = max([*t, *(v for _, v, _ in vlines), 1e-3])
    values = [*y, *(v for _, v, _ in lines)] or [0.0, 1.0]
    lo, hi = min(values), max(values)
    if hi - lo < 1e-9:
        lo, hi = lo - 1, hi + 1
    pad = (hi - lo) * 0.06
    lo, hi = lo - pad, hi + pad

    def px(tv: float) -> float:
        return _L + (_W - _L - _R) * tv / t_max

    def py(v: float) -> float:
        return _T + (_H - _T - _B) * (hi - v) / (hi - lo)

    out = [
        f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {_W} {_H}" width="{_W}" '
        f'height="{_H}" font-family="sans-serif" font-size="11" class="grade-plot">',
        f'<rect x="{_L}" y="{_T}" width="{_W - _L - _R}" height="{_H - _T - _B}" '
        'fill="#fff" stroke="#ccc"/>',
    ]
    for i in range(5):
        v = lo + (hi - lo) * i / 4
        out.append(f'<text x="{_L - 4}" y="{py(v) + 4:.1f}" text-anchor="end">{_fmt(v)}</text>')
        tv = t_max * i / 4
        out.append(
            f'<text x="{px(tv):.1f}" y="{_H - _B + 14}" text-anchor="middle">{_fmt(tv)}</text>'
        )
    out.append(
        f'<text x="{(_L + _W) / 2}" y="{_H - 4}" text-anchor="middle">time (s) from the first '
        f"command</text>"
    )
    out.append(
        f'<text x="12" y="{(_T + _H - _B) / 2}" transform="rotate(-90 12 {(_T + _H - _B) / 2})"'
        f' text-anchor="middle">{html.escape(what)} ({unit})</text>'
    )
    for _, v, colour in lines:
        out.append(
            f'<line x1="{_L}" x2="{_W - _R}" y1="{py(v):.1f}" y2="{py(v):.1f}" '
            f'stroke="{colour}" stroke-dasharray="5 3"/>'
        )
    # each label just above its line, from the top down, at least a line of text apart (the
    # setpoint, its band and the overshoot line are often a few pixels apart)
    below = float(_T + 10)
    for label, v, colour in sorted((x for x in lines if x[0]), key=lambda x: py(x[1])):
        ty = max(py(v) - 3, below)
        below = ty + 12
        out.append(
            f'<text x="{_W - _R - 4}" y="{ty:.1f}" text-anchor="end" '
            f'fill="{colour}">{html.escape(label)}</text>'
        )
    for label, v, colour in vlines:
        out.append(
            f'<line x1="{px(v):.1f}" x2="{px(v):.1f}" y1="{_T}" y2="{_H - _B}" '
            f'stroke="{colour}" stroke-dasharray="4 3"/>'
        )
        right = px(v) > _W - _R - 110  # near the right edge: the label goes left of the line
        x = px(v) - 3 if right else px(v) + 3
        anchor = "end" if right else "start"
        # at the foot of the plot, where a settled response leaves room (the top holds the
        # setpoint's labels)
        ty = _H - _B - 4 - 12 * vlines.index((label, v, colour))
        out.append(
            f'<text x="{x:.1f}" y="{ty}" text-anchor="{anchor}" fill="{colour}">'
            f"{html.escape(label)}</text>"
        )
    if t and y:
        points = " ".join(f"{px(a):.1f},{py(b):.1f}" for a, b in zip(t, y, strict=False))
        out.append(f'<polyline points="{points}" fill="none" stroke="#1f5fbf" stroke-width="2"/>')
    out.append("</svg>")
    return "".join(out)


def report_html(report: dict[str, Any]) -> str:
    """Return ``report`` as a self-contained HTML page."""
    esc = html.escape
    task = report.get("task") or {}
    verdict = "PASSED" if report.get("passed") else "FAILED"
    status = report.get("status", "")
    rows = "".join(
        f'<tr class="{"ok" if line["passed"] else "bad"}"><td>{esc(line["metric"])}</td>'
        f"<td>{esc(_value(line['value']))}</td>"
        f"<td>{esc(_bounds(line))}</td><td>{'pass' if line['passed'] else 'FAIL'}</td></tr>"
        for line in report.get("rubric") or []
    )
    metrics = "".join(
        f"<tr><td>{esc(k)}</td><td>{esc(_value(v))}</td></tr>"
        for k, v in (report.get("metrics") or {}).items()
    )
    reason = f"<p>{esc(str(report['reason']))}</p>" if report.get("reason") else ""
    return f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>{esc(str(task.get("id", "")))}: {verdict}</title>
<style>body{{font-family:sans-serif;margin:2em;max-width:720px}}table{{border-collapse:collapse}}
td,th{{border:1px solid #ccc;padding:2px 8px;text-align:left}}.ok td:last-child{{color:#2a7}}
.bad td:last-child{{color:#d33;font-weight:bold}}</style></head><body>
<h1>{esc(str(task.get("name") or task.get("id", "task")))}: {verdict}</h1>
<p>robot <b>{esc(str(report.get("robot") or "(default)"))}</b> · attempt
{esc(str(report.get("attempt", "")))} · status {esc(str(status))} · student
{esc(str(report.get("student", "")))}</p>{reason}
{response_svg(report)}
<h2>Rubric</h2><table><tr><th>metric</th><th>value</th><th>needs</th><th></th></tr>{rows}</table>
<h2>Metrics</h2><table>{metrics}</table>
</body></html>
"""


def _value(v: Any) -> str:
    return "-" if v is None else f"{v:g}"


def _bounds(line: dict[str, Any]) -> str:
    parts = []
    if line.get("max") is not None:
        parts.append(f"<= {line['max']:g}")
    if line.get("min") is not None:
        parts.append(f">= {line['min']:g}")
    return " and ".join(parts)
