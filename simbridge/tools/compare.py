"""``simbridge compare SIM REAL``: how far a simulated run drifts from the real one.

Both bags hold the same velocity sequence (``examples/velocity_sequence.py``, or ``simbridge
replay --headless`` of the real bag) and the robot's ``/odom``. Each run is aligned in time at
its first non-zero ``/cmd_vel`` (receive time), and in space at its pose at that instant: poses
are expressed in that start pose's frame, so runs that started at different places or headings
compare. Both are resampled (linear interpolation, heading unwrapped) on a common 20 Hz grid
over the time both cover, and the report gives, for position (metres) and heading (radians):

* RMSE over the compared time, the maximum, and the *final drift* (the error at the end);

plus each run's distance travelled. ``--plot FILE.html`` (or ``.svg``) draws both trajectories
and the errors over time as a self-contained page (inline SVG, no dependencies).
"""

from __future__ import annotations

import argparse
import html
import json
import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from simbridge.errors import SimbridgeError
from simbridge.robot.cmdvel import twist_of
from simbridge.tools.bag import read_messages


__all__ = [
    "CompareError",
    "Comparison",
    "Run",
    "compare",
    "compare_main",
    "load_run",
    "plot",
    "replay_against",
]

Floats = npt.NDArray[np.float64]
#: A command counts as the start when |linear| or |angular| exceeds this.
MOVING = 1e-6


class CompareError(SimbridgeError):
    """Two runs cannot be compared (no /odom, no command...)."""


@dataclass
class Run:
    """One run's trajectory from its start command on: time (s), x, y (m), unwrapped yaw."""

    name: str
    #: Seconds from the start of the bag to the first non-zero command.
    start_offset: float
    t: Floats
    x: Floats
    y: Floats
    yaw: Floats

    def distance(self) -> float:
        """Return the path length, metres."""
        return _length(self.x, self.y)


def _length(x: Floats, y: Floats) -> float:
    return float(np.sum(np.hypot(np.diff(x), np.diff(y))))


def _yaw(q: dict[str, float]) -> float:
    return math.atan2(2 * (q["w"] * q["z"] + q["x"] * q["y"]), 1 - 2 * (q["y"] ** 2 + q["z"] ** 2))


def load_run(path: str | Path, odom: str = "/odom", cmd_vel: str = "/cmd_vel") -> Run:
    """Read a bag's odometry from its first non-zero command on, in the start pose's frame.

    Raises:
        CompareError: no odometry or no non-zero command, or odometry ends before the start.
        BagError: the bag cannot be read.
    """
    stamps: list[int] = []
    poses: list[tuple[float, float, float]] = []
    start_ns: int | None = None
    first_ns: int | None = None
    for topic, _type, stamp, msg in read_messages(path, {odom, cmd_vel}):
        first_ns = stamp if first_ns is None else first_ns
        if topic == cmd_vel:
            twist = twist_of(msg)  # Twist or TwistStamped
            moving = abs(twist["linear"]["x"]) > MOVING or abs(twist["angular"]["z"]) > MOVING
            if start_ns is None and moving:
                start_ns = stamp
        else:
            p = msg["pose"]["pose"]
            stamps.append(stamp)
            poses.append((p["position"]["x"], p["position"]["y"], _yaw(p["orientation"])))
    if start_ns is None or first_ns is None:
        text = f"bag '{path}' has no non-zero {cmd_vel} to align on"
        raise CompareError(text)
    if len(poses) < 2 or stamps[-1] <= start_ns:
        text = f"bag '{path}' has no {odom} after its first non-zero {cmd_vel}"
        raise CompareError(text)
    t = (np.array(stamps, dtype=np.int64) - start_ns) / 1e9
    arr = np.array(poses, dtype=np.float64)
    yaw = np.unwrap(arr[:, 2])
    x0 = float(np.interp(0.0, t, arr[:, 0]))
    y0 = float(np.interp(0.0, t, arr[:, 1]))
    th0 = float(np.interp(0.0, t, yaw))
    keep = t > 0
    t = np.concatenate([[0.0], t[keep]])
    dx = np.concatenate([[x0], arr[keep, 0]]) - x0
    dy = np.concatenate([[y0], arr[keep, 1]]) - y0
    c, s = math.cos(-th0), math.sin(-th0)
    return Run(
        name=str(path),
        start_offset=(start_ns - first_ns) / 1e9,
        t=t,
        x=c * dx - s * dy,
        y=s * dx + c * dy,
        yaw=np.concatenate([[th0], yaw[keep]]) - th0,
    )


@dataclass
class Comparison:
    """Errors of ``sim`` against ``real`` on a common time grid."""

    sim: Run
    real: Run
    t: Floats
    position_error: Floats
    heading_error: Floats
    #: Both runs' positions on the grid: sim x, sim y, real x, real y.
    grid: tuple[Floats, Floats, Floats, Floats]

    def metrics(self) -> dict[str, Any]:
        """Return the figures of the report (SI units)."""
        pe, he = self.position_error, np.abs(self.heading_error)
        return {
            "duration_s": round(float(self.t[-1]), 3),
            "samples": len(self.t),
            "position_rmse_m": float(np.sqrt(np.mean(pe**2))),
            "position_max_m": float(np.max(pe)),
            "position_final_drift_m": float(pe[-1]),
            "heading_rmse_rad": float(np.sqrt(np.mean(he**2))),
            "heading_max_rad": float(np.max(he)),
            "heading_final_drift_rad": float(he[-1]),
            "sim_distance_m": _length(self.grid[0], self.grid[1]),
            "real_distance_m": _length(self.grid[2], self.grid[3]),
            "sim_start_offset_s": round(self.sim.start_offset, 3),
            "real_start_offset_s": round(self.real.start_offset, 3),
        }


def compare(sim: Run, real: Run, rate: float = 20.0) -> Comparison:
    """Resample both runs on a common grid over the time both cover; return the errors.

    Raises:
        CompareError: the runs share less than one grid step.
    """
    end = min(float(sim.t[-1]), float(real.t[-1]))
    if end < 1.0 / rate:
        msg = "the runs overlap for less than one sample after alignment"
        raise CompareError(msg)
    t = np.arange(0.0, end + 1e-9, 1.0 / rate)

    def at(run: Run) -> tuple[Floats, Floats, Floats]:
        return np.interp(t, run.t, run.x), np.interp(t, run.t, run.y), np.interp(t, run.t, run.yaw)

    sx, sy, syaw = at(sim)
    rx, ry, ryaw = at(real)
    d = syaw - ryaw
    return Comparison(
        sim,
        real,
        t,
        np.hypot(sx - rx, sy - ry),
        np.arctan2(np.sin(d), np.cos(d)),
        (sx, sy, rx, ry),
    )


def report(c: Comparison) -> str:
    """Return the human-readable report."""
    m = c.metrics()
    deg = math.degrees
    return "\n".join(
        [
            f"simbridge compare: {c.sim.name} (sim) vs {c.real.name} (real)",
            f"aligned at the first non-zero /cmd_vel: {m['sim_start_offset_s']:.2f} s and "
            f"{m['real_start_offset_s']:.2f} s into the bags; {m['duration_s']:.2f} s compared",
            f"position error: RMSE {m['position_rmse_m']:.4f} m, max {m['position_max_m']:.4f} m, "
            f"final drift {m['position_final_drift_m']:.4f} m",
            f"heading error:  RMSE {m['heading_rmse_rad']:.4f} rad "
            f"({deg(m['heading_rmse_rad']):.2f} deg), max {m['heading_max_rad']:.4f} rad, "
            f"final drift {m['heading_final_drift_rad']:.4f} rad "
            f"({deg(m['heading_final_drift_rad']):.2f} deg)",
            f"distance travelled in that time: sim {m['sim_distance_m']:.3f} m, "
            f"real {m['real_distance_m']:.3f} m",
        ]
    )


# -- the plot -----------------------------------------------------------------------------------

_SIM, _REAL, _POS, _HEAD = "#1f77b4", "#ff7f0e", "#2ca02c", "#d62728"


def _polyline(xs: Floats, ys: Floats, color: str, box: tuple[float, ...], width: float) -> str:
    x0, x1, y0, y1, left, top, w, h = box
    sx = w / (x1 - x0) if x1 > x0 else 1.0
    sy = h / (y1 - y0) if y1 > y0 else 1.0
    pts = " ".join(
        f"{left + (x - x0) * sx:.1f},{top + h - (y - y0) * sy:.1f}"
        for x, y in zip(xs, ys, strict=True)
    )
    return f'<polyline fill="none" stroke="{color}" stroke-width="{width}" points="{pts}"/>'


def _svg(c: Comparison) -> str:
    return _svg_many([("sim", c)])


#: Colours of the simulated runs drawn beside the real one (ideal, fitted...).
_SIMS = (_SIM, "#9467bd", "#17becf", "#8c564b")


def _svg_many(runs: list[tuple[str, Comparison]]) -> str:
    """Trajectories of the real run and each simulated one; each one's position error."""
    size, pad = 360.0, 40.0
    real = runs[0][1].real
    colours = [_SIMS[i % len(_SIMS)] for i in range(len(runs))]
    # trajectories, equal aspect
    xs = np.concatenate([real.x, *(c.sim.x for _, c in runs)])
    ys = np.concatenate([real.y, *(c.sim.y for _, c in runs)])
    span = max(float(np.ptp(xs)), float(np.ptp(ys)), 0.1) * 1.1
    cx, cy = float(xs.min() + xs.max()) / 2, float(ys.min() + ys.max()) / 2
    box = (cx - span / 2, cx + span / 2, cy - span / 2, cy + span / 2, pad, pad, size, size)
    parts = [
        f'<rect x="{pad}" y="{pad}" width="{size}" height="{size}" fill="none" stroke="#999"/>',
        f'<text x="{pad}" y="{pad - 10}">trajectories (start frame, {span:.2f} m across)</text>',
        _polyline(real.x, real.y, _REAL, box, 2),
    ]
    labels = [("real", _REAL)]
    for (label, c), colour in zip(runs, colours, strict=True):
        parts.append(_polyline(c.sim.x, c.sim.y, colour, box, 2))
        labels.append((label, colour))
    x = pad
    for label, colour in labels:
        parts.append(
            f'<text x="{x:.0f}" y="{pad + size + 20}" fill="{colour}">{html.escape(label)}</text>'
        )
        x += 12 + 8 * len(label)
    # errors over time
    left = 2 * pad + size + 30
    top_pe = max(max(float(c.position_error.max()) for _, c in runs), 1e-3)
    top_he = max(max(float(np.abs(c.heading_error).max()) for _, c in runs), 1e-3)
    t_end = max(float(c.t[-1]) for _, c in runs)
    half = size / 2 - 10
    single = len(runs) == 1
    for i, (top, label, unit) in enumerate(
        [(top_pe, "position error", "m"), (top_he, "heading error", "rad")]
    ):
        y = pad + i * (half + 20)
        colour = (_POS, _HEAD)[i] if single else "#333"
        parts += [
            f'<rect x="{left}" y="{y}" width="{size}" height="{half}" fill="none" stroke="#999"/>',
            f'<text x="{left}" y="{y - 5 if i == 0 else y - 4}" fill="{colour}">'
            f"{label} (max {top:.4f} {unit}) over {t_end:.1f} s</text>",
        ]
        for (_, c), run_colour in zip(runs, colours, strict=True):
            values = c.position_error if i == 0 else np.abs(c.heading_error)
            stroke = colour if single else run_colour
            frame = (0.0, t_end, 0.0, top, left, y, size, half)
            parts.append(_polyline(c.t, values, stroke, frame, 1.5))
    width, height = left + size + pad, 2 * pad + size + 30
    body = "".join(parts)
    return (
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width:.0f}" height="{height:.0f}" '
        f'font-family="sans-serif" font-size="12">{body}</svg>'
    )


def plot(c: Comparison | list[tuple[str, Comparison]], path: Path) -> None:
    """Write the plot: ``.svg`` as is, anything else as a self-contained HTML page.

    ``c`` is one comparison, or several simulated runs against the same real one (labelled).
    """
    runs = [("sim", c)] if isinstance(c, Comparison) else c
    svg = _svg_many(runs)
    if path.suffix.lower() == ".svg":
        path.write_text(svg, encoding="utf-8")
        return
    rows = "".join(
        f"<tr><td>{html.escape(prefix + k)}</td><td>{v:.4f}</td></tr>"
        if isinstance(v, float)
        else f"<tr><td>{html.escape(prefix + k)}</td><td>{v}</td></tr>"
        for label, run in runs
        for prefix in [f"{label} " if len(runs) > 1 else ""]
        for k, v in run.metrics().items()
    )
    names = " and ".join(html.escape(run.sim.name) for _, run in runs)
    title = f"{names} vs {html.escape(runs[0][1].real.name)}"
    path.write_text(
        f'<!doctype html><html><head><meta charset="utf-8"><title>simbridge compare</title>'
        f"<style>body{{font-family:sans-serif}}td{{padding:0 1em}}</style></head><body>"
        f"<h1>simbridge compare</h1><p>{title}</p>{svg}<table>{rows}</table></body></html>",
        encoding="utf-8",
    )


def replay_against(
    real_bag: str,
    fitted: str | Path,
    *,
    params: str | None = None,
    world: str | None = None,
    odom: str = "/odom",
    cmd_vel: str = "/cmd_vel",
) -> list[tuple[str, Comparison]]:
    """Replay the real run's commands on the ideal model and the fitted one; compare each.

    The ideal model is ``params`` (default: the bundled ones) with ``realism.enabled`` off;
    the fitted one is the parameters file ``fitted`` (``simbridge fit`` writes it). Both run
    in ``world`` (default: an empty one: the real room's walls are not known).

    Raises:
        CompareError: a run cannot be compared.
        ConfigError: a file is invalid.
    """
    import tempfile

    from simbridge.app.config import WorldSpec, load_params, load_world
    from simbridge.tools.record import replay_headless

    real = load_run(real_bag, odom, cmd_vel)
    spec = load_world(world) if world else WorldSpec()
    base = load_params(params)
    ideal = base.replace(realism=base.realism.replace(enabled=False))
    out: list[tuple[str, Comparison]] = []
    with tempfile.TemporaryDirectory(prefix="simbridge-compare-") as tmp:
        for label, model in (("ideal", ideal), ("fitted", load_params(fitted))):
            bag = Path(tmp) / label
            replay_headless(real_bag, bag, topic=cmd_vel, world=spec, params=model)
            run = load_run(bag, odom, cmd_vel)
            run.name = f"{label} replay"
            out.append((label, compare(run, real)))
    return out


def compare_main(argv: Sequence[str]) -> int:
    """Run ``simbridge compare``; return the exit code."""
    parser = argparse.ArgumentParser(
        prog="simbridge compare",
        description="Compare the odometry of two runs of the same velocity sequence "
        "(simulation and real robot): RMSE and final drift of position and heading. With "
        "--fitted PARAMS and one bag (the real run): replay its commands on the ideal model "
        "and on the fitted one, and compare each with it.",
    )
    parser.add_argument("bags", nargs="+", help="SIM REAL (bags: directories or .mcap), or REAL")
    parser.add_argument("--fitted", help="the fitted parameters (simbridge fit): replay REAL")
    parser.add_argument("--params", help="with --fitted: the ideal model's parameters")
    parser.add_argument("--world", help="with --fitted: the world to replay in (default: empty)")
    parser.add_argument("--odom", default="/odom", help="odometry topic (default /odom)")
    parser.add_argument("--cmd-vel", default="/cmd_vel", help="command topic (default /cmd_vel)")
    parser.add_argument("--plot", help="write a plot: FILE.html (self-contained) or FILE.svg")
    parser.add_argument("--json", action="store_true", help="print the figures as JSON")
    args = parser.parse_args(argv)
    if len(args.bags) != (1 if args.fitted else 2):
        parser.error("give SIM REAL, or REAL with --fitted PARAMS")
    try:
        if args.fitted:
            runs = replay_against(
                args.bags[0],
                args.fitted,
                params=args.params,
                world=args.world,
                odom=args.odom,
                cmd_vel=args.cmd_vel,
            )
        else:
            sim = load_run(args.bags[0], args.odom, args.cmd_vel)
            real = load_run(args.bags[1], args.odom, args.cmd_vel)
            runs = [("sim", compare(sim, real))]
    except SimbridgeError as err:
        print(f"simbridge: {err}", file=sys.stderr)
        return 1
    if args.json:
        figures = {label: c.metrics() for label, c in runs}
        print(json.dumps(figures if args.fitted else runs[0][1].metrics()))
    else:
        print("\n\n".join(report(c) for _, c in runs))
        if args.fitted:
            rmse = ", ".join(f"{label} {c.metrics()['position_rmse_m']:.4f} m" for label, c in runs)
            print(f"\nposition RMSE against the real run: {rmse}")
    if args.plot:
        plot(runs, Path(args.plot))
        if not args.json:
            print(f"plot: {args.plot}")
    return 0
