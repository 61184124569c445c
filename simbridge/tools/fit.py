"""``simbridge fit BAG``: the realism profile of the course's robot, from its own recording.

The bag holds the real robot's ``/cmd_vel`` and ``/odom`` (``simbridge record -a`` against the
robot's rosbridge, or ``ros2 bag record``). The fit estimates the parameters of the wheel
model of :mod:`simbridge.sim.realism` that ``/odom`` can show:

* ``realism.cmd_latency`` ``L`` (s), ``realism.motor_time_constant`` ``T`` (s),
  ``realism.deadband`` ``D`` (m/s) and ``realism.wheel_speed_scale`` ``k``.

Each ``/odom`` twist gives the two wheels' rim speeds ``v +- omega b/2`` (``b`` the nominal
``robot.wheelbase``), averaged over the odometry period that ends at its receive time. The model
predicts them from the commands (clamped to the limits) exactly as the simulator moves: the
command received at ``t`` is in effect from ``t + L``; each wheel's target is its command, zero
below ``D``, times ``k``; the wheel follows it with a first-order lag ``T`` (exact exponential
between changes); its average over each period is the prediction.

The search is a grid over ``(L, D, T)``, swept for all ``D`` and ``T`` at once (numpy), with
``k`` solved in closed form (linear least squares) at each point, then a finer grid around the
best point. How well each parameter is determined comes from its *profile*: the least residual
with that parameter held at each grid value and the others free. Its interval is where the
profile stays within one noise variance (``s^2``, the residual per degree of freedom) of the
minimum; a parameter whose profile is flat over the whole searched range is *not determined*
(a recording without slow commands cannot show the deadband) and is left at its exact value.

The result is written as a parameters file (the base parameters with the fitted ``realism``
section, ``enabled: true``) that ``simbridge --params`` and ``simbridge compare --fitted``
take. Commands on a real robot reach its driver between its control steps: the latency found
is the delay from the recorded command to its effect, within one odometry period.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from simbridge.app.config import Params, load_params
from simbridge.errors import SimbridgeError
from simbridge.robot.cmdvel import twist_of
from simbridge.tools.bag import read_messages


__all__ = ["Drive", "Estimate", "FitError", "FitResult", "fit", "fit_main", "load_drive"]

Floats = npt.NDArray[np.float64]

#: The searched ranges: latency (s), deadband (m/s), time constant (s), and their grid steps.
LATENCY = (0.0, 0.5, 0.01)
DEADBAND = (0.0, 0.15, 0.005)
TIME_CONSTANT = (0.0, 1.0, 0.02)
#: The finer grid around the best point: this many coarse steps each side, this many times finer.
REFINE_SPAN, REFINE_FACTOR = 2, 5


class FitError(SimbridgeError):
    """A recording from which nothing can be fitted (no commands, no odometry)."""


@dataclass
class Drive:
    """A recording's commands and odometry on one time line (seconds from the first message)."""

    name: str
    #: Command receive times and values (linear m/s, angular rad/s).
    cmd_t: Floats
    cmd_v: Floats
    cmd_w: Floats
    #: Odometry receive times and twists.
    odom_t: Floats
    odom_v: Floats
    odom_w: Floats


def load_drive(path: str | Path, odom: str = "/odom", cmd_vel: str = "/cmd_vel") -> Drive:
    """Read a bag's commands and odometry twists.

    Raises:
        FitError: the bag has too few of either.
        BagError: the bag cannot be read.
    """
    cmds: list[tuple[int, float, float]] = []
    odoms: list[tuple[int, float, float]] = []
    for topic, _type, stamp, msg in read_messages(path, {odom, cmd_vel}):
        if topic == cmd_vel:
            tw = twist_of(msg)
            cmds.append((stamp, tw["linear"]["x"], tw["angular"]["z"]))
        elif topic == odom:
            tw = msg["twist"]["twist"]
            odoms.append((stamp, tw["linear"]["x"], tw["angular"]["z"]))
    if not cmds:
        msg_text = f"bag '{path}' has no {cmd_vel}: the fit needs the commands that were sent"
        raise FitError(msg_text)
    if len(odoms) < 10:
        msg_text = f"bag '{path}' has {len(odoms)} {odom} messages: the fit needs at least 10"
        raise FitError(msg_text)
    base = min(cmds[0][0], odoms[0][0])
    c = np.array(cmds, dtype=np.float64)
    o = np.array(odoms, dtype=np.float64)
    c[:, 0] = (np.array([s for s, _, _ in cmds], dtype=np.int64) - base) / 1e9
    o[:, 0] = (np.array([s for s, _, _ in odoms], dtype=np.int64) - base) / 1e9
    return Drive(str(path), c[:, 0], c[:, 1], c[:, 2], o[:, 0], o[:, 1], o[:, 2])


@dataclass
class Estimate:
    """One fitted parameter: its value and the interval the recording allows."""

    name: str
    unit: str
    value: float
    low: float
    high: float
    #: False: the recording cannot show it (its profile is flat over the searched range).
    determined: bool
    why: str = ""

    def describe(self) -> str:
        """One line: value, +- half the interval, or why it is not determined."""
        label = f"{self.name:<28}"
        if not self.determined:
            return f"{label} not determined: {self.why}"
        allowed = f"(the recording allows {self.low:.4f} to {self.high:.4f})"
        return f"{label} {self.value:8.4f} {self.unit:<4} {allowed}"


@dataclass
class FitResult:
    """What :func:`fit` found."""

    estimates: dict[str, Estimate]
    #: RMS of the wheel-speed residual, m/s: the fitted model, and the ideal one (L = T = D = 0,
    #: k = 1) for comparison.
    rms: float
    ideal_rms: float
    samples: int
    params: Params = field(repr=False, default_factory=Params)

    def report(self) -> str:
        """The human-readable report."""
        lines = [e.describe() for e in self.estimates.values()]
        lines.append(
            f"residual: RMS {self.rms:.4f} m/s per wheel over {self.samples} odometry samples "
            f"(the ideal model: {self.ideal_rms:.4f} m/s)"
        )
        return "\n".join(lines)

    def values(self) -> dict[str, float]:
        """The fitted realism values (the undetermined at their exact setting)."""
        exact = {"cmd_latency": 0.0, "motor_time_constant": 0.0, "deadband": 0.0}
        exact["wheel_speed_scale"] = 1.0
        return {
            name: (round(e.value, 6) if e.determined else exact[name])
            for name, e in self.estimates.items()
        }


def _grid(low: float, high: float, step: float) -> Floats:
    return np.round(np.arange(low, high + step / 2, step), 9)


def _targets(drive: Drive, params: Params, deadbands: Floats) -> Floats:
    """The commanded wheel speeds (right, left) of every command, after the deadband.

    Shape ``(2, len(deadbands), commands)``.
    """
    r = params.robot
    v = np.clip(drive.cmd_v, -r.max_linear_velocity, r.max_linear_velocity)
    w = np.clip(drive.cmd_w, -r.max_angular_velocity, r.max_angular_velocity)
    half_b = r.wheelbase / 2
    wheels = np.stack([v + w * half_b, v - w * half_b])  # (2, C)
    slow = np.abs(wheels)[:, None, :] < deadbands[None, :, None]
    return np.where(slow, 0.0, np.broadcast_to(wheels[:, None, :], slow.shape))


def _observed(drive: Drive, params: Params) -> Floats:
    half_b = params.robot.wheelbase / 2
    return np.stack([drive.odom_v + drive.odom_w * half_b, drive.odom_v - drive.odom_w * half_b])


def _bounds(drive: Drive) -> Floats:
    """Return the odometry periods' ends (each sample averages since the one before it).

    The first period starts one median period before the first sample.
    """
    t = drive.odom_t
    period = float(np.median(np.diff(t)))
    return np.concatenate([[t[0] - period], t])


def _sweep(
    latency: float, cmd_t: Floats, targets: Floats, bounds: Floats, observed: Floats, taus: Floats
) -> tuple[Floats, Floats]:
    """Return ``(Sxy, Sxx)`` per (deadband, tau) for one latency.

    The sums of the predicted (k = 1) wheel speeds times the observed ones and squared; shapes
    ``(len(deadbands), len(taus))``.
    """
    n_d = targets.shape[1]
    tau = np.maximum(taus, 1e-12)[None, None, :]
    w = np.zeros((2, n_d, len(taus)))
    acc = np.zeros_like(w)
    u = np.zeros((2, n_d, 1))
    sxy = np.zeros((n_d, len(taus)))
    sxx = np.zeros_like(sxy)
    events = cmd_t + latency
    n_c, n_b = len(events), len(bounds)
    i = k = 0
    t = min(float(events[0]), float(bounds[0]))
    inf = math.inf
    while k < n_b:
        next_e = float(events[i]) if i < n_c else inf
        next_b = float(bounds[k])
        upto = next_b if next_b <= next_e else next_e
        h = upto - t
        if h > 0.0:
            decay = np.exp(-h / tau)
            du = w - u
            if k:
                acc += u * h + du * tau * (1.0 - decay)
            w = u + du * decay
            t = upto
        if next_b <= next_e:
            if k:
                pred = acc / (bounds[k] - bounds[k - 1])
                y = observed[:, k - 1][:, None, None]
                sxy += (pred * y).sum(axis=0)
                sxx += (pred * pred).sum(axis=0)
                acc[:] = 0.0
            k += 1
        else:
            u = targets[:, :, i][..., None]
            i += 1
    return sxy, sxx


def _search(
    drive: Drive, params: Params, latencies: Floats, deadbands: Floats, taus: Floats
) -> tuple[Floats, Floats]:
    """Return the residual and the best k on the grid, each ``(L, D, T)``."""
    targets = _targets(drive, params, deadbands)
    observed = _observed(drive, params)
    bounds = _bounds(drive)
    syy = float(np.sum(observed**2))
    ssr = np.empty((len(latencies), len(deadbands), len(taus)))
    scale = np.empty_like(ssr)
    for j, latency in enumerate(latencies):
        sxy, sxx = _sweep(float(latency), drive.cmd_t, targets, bounds, observed, taus)
        with np.errstate(divide="ignore", invalid="ignore"):
            k = np.where(sxx > 0, sxy / sxx, 1.0)
        ssr[j] = syy - 2 * k * sxy + k * k * sxx
        scale[j] = k
    return np.maximum(ssr, 0.0), scale


def _interval(grid: Floats, profile: Floats, limit: float) -> tuple[float, float, bool]:
    """The grid values whose profile is within ``limit``; whether the profile is not flat."""
    inside = grid[profile <= limit]
    spread = float(profile.max() - profile.min())
    return float(inside.min()), float(inside.max()), spread > 1e-12 * max(1.0, float(profile.max()))


def fit(drive: Drive, params: Params | None = None) -> FitResult:
    """Fit latency, motor time constant, deadband and wheel-speed scale to ``drive``.

    ``params`` gives the nominal geometry and limits (default: the bundled parameters); the
    result's :attr:`FitResult.params` is them with the fitted ``realism`` section.
    """
    base = params or Params()
    spans = (LATENCY, DEADBAND, TIME_CONSTANT)
    grids = [_grid(*span) for span in spans]
    ssr, scale = _search(drive, base, *grids)
    best = np.unravel_index(int(np.argmin(ssr)), ssr.shape)
    n = 2 * len(drive.odom_t)
    # finer grids around the best point, twice
    ssr_f, scale_f, fine, best_f = ssr, scale, grids, best
    steps = [span[2] for span in spans]
    rounds: list[tuple[list[Floats], Floats]] = []
    for _ in range(2):
        around = []
        for axis, (low, high, _) in enumerate(spans):
            centre = float(fine[axis][best_f[axis]])
            lo = max(low, centre - REFINE_SPAN * steps[axis])
            hi = min(high, centre + REFINE_SPAN * steps[axis])
            steps[axis] /= REFINE_FACTOR
            around.append(_grid(lo, hi, steps[axis]))
        fine = around
        ssr_f, scale_f = _search(drive, base, *fine)
        best_f = np.unravel_index(int(np.argmin(ssr_f)), ssr_f.shape)
        rounds.append((fine, ssr_f))
    variance = float(ssr_f[best_f]) / max(1, n - 4)
    limit = float(ssr_f[best_f]) + variance + 1e-12 * float(ssr.max())
    names = [("cmd_latency", "s"), ("deadband", "m/s"), ("motor_time_constant", "s")]
    estimates: dict[str, Estimate] = {}
    for axis, (name, unit) in enumerate(names):
        others = tuple(a for a in range(3) if a != axis)
        # the interval: every refined grid point within the limit (a later, finer grid is
        # narrower than a flat bottom may be)
        inside = [g[axis][r.min(axis=others) <= limit] for g, r in rounds if r.min() <= limit]
        values = np.concatenate(inside) if inside else fine[axis][best_f[axis] : best_f[axis] + 1]
        low, high = float(values.min()), float(values.max())
        value = (low + high) / 2
        coarse = ssr.min(axis=others)
        _, _, shaped = _interval(grids[axis], coarse, float(coarse.min()) * (1 + 1e-6) + limit)
        if name == "deadband" and shaped:
            # the residual depends on the deadband only through which wheel commands it stops
            # (those slower than it): it is flat between two commanded speeds
            below, above = _levels(drive, base, float(fine[axis][best_f[axis]]))
            low, high = min(low, below), max(high, min(above, spans[axis][1]))
            value = (below + min(above, spans[axis][1])) / 2
        low, high = low - steps[axis] / 2, high + steps[axis] / 2
        why = ""
        if not shaped:
            span = spans[axis]
            why = f"the residual is the same from {span[0]:g} to {span[1]:g} {unit}"
            if name == "deadband":
                slowest = _slowest_wheel(drive, base)
                why += f" (no wheel was commanded slower than {slowest:.3f} m/s)"
        estimates[name] = Estimate(name, unit, value, max(0.0, low), high, shaped, why)
    k = float(scale_f[best_f])
    sxx_k = _sxx_at(drive, base, fine, best_f)
    k_half = math.sqrt(variance / sxx_k) if sxx_k > 0 else math.inf
    # and what the finest grid's step in latency and time constant leaves open
    near = [
        g[max(0, i - 1) : i + 2] if axis != 1 else g[i : i + 1]
        for axis, (g, i) in enumerate(zip(fine, best_f, strict=True))
    ]
    _, scales = _search(drive, base, *near)
    k_half = max(k_half, float(np.max(np.abs(scales - k))))
    estimates["wheel_speed_scale"] = Estimate(
        "wheel_speed_scale", "", k, k - k_half, k + k_half, sxx_k > 0, "no wheel ever turned"
    )
    ordered = {n: estimates[n] for n in ("cmd_latency", "motor_time_constant", "deadband")} | {
        "wheel_speed_scale": estimates["wheel_speed_scale"]
    }
    # the ideal model (L = T = D = 0 and k = 1): its residual is Syy - 2 Sxy + Sxx
    observed = _observed(drive, base)
    sxy, sxx = _sweep(
        0.0, drive.cmd_t, _targets(drive, base, np.zeros(1)), _bounds(drive), observed, np.zeros(1)
    )
    ideal_ssr = max(0.0, float(np.sum(observed**2) - 2 * sxy[0, 0] + sxx[0, 0]))
    result = FitResult(
        ordered,
        rms=math.sqrt(float(ssr_f[best_f]) / n),
        ideal_rms=math.sqrt(ideal_ssr / n),
        samples=len(drive.odom_t),
    )
    result.params = base.replace(realism=base.realism.replace(enabled=True, **result.values()))
    return result


def _levels(drive: Drive, params: Params, deadband: float) -> tuple[float, float]:
    """Return the commanded wheel speeds either side of ``deadband`` (0 and inf at the ends).

    Every deadband in ``(below, above]`` stops the same commands as ``deadband`` does.
    """
    speeds = np.abs(_targets(drive, params, np.zeros(1))).ravel()
    stopped = speeds[speeds < deadband]
    moving = speeds[speeds >= deadband]
    return (float(stopped.max()) if stopped.size else 0.0), (
        float(moving.min()) if moving.size else math.inf
    )


def _slowest_wheel(drive: Drive, params: Params) -> float:
    wheels = np.abs(_targets(drive, params, np.zeros(1)))
    moving = wheels[wheels > 1e-9]
    return float(moving.min()) if moving.size else 0.0


def _sxx_at(drive: Drive, params: Params, grids: list[Floats], at: tuple[Any, ...]) -> float:
    _, sxx = _sweep(
        float(grids[0][at[0]]),
        drive.cmd_t,
        _targets(drive, params, grids[1][at[1] : at[1] + 1]),
        _bounds(drive),
        _observed(drive, params),
        grids[2][at[2] : at[2] + 1],
    )
    return float(sxx[0, 0])


def write_params(result: FitResult, path: Path, source: str) -> None:
    """Write the fitted parameters file (YAML, with the fit's report as comments)."""
    import yaml  # only when a file is written

    header = [f"# simbridge fit {source}", "# the realism profile fitted to that recording:"]
    header += [f"#   {line}" for line in result.report().splitlines()]
    data = result.params.as_dict()
    for section in data.values():
        for key, value in list(section.items()):
            if isinstance(value, tuple):
                section[key] = list(value)
    text = yaml.safe_dump(data, sort_keys=False, default_flow_style=None)
    path.write_text("\n".join(header) + "\n" + text, encoding="utf-8")


def fit_main(argv: Sequence[str]) -> int:
    """Run ``simbridge fit``; return the exit code."""
    parser = argparse.ArgumentParser(
        prog="simbridge fit",
        description="Fit the realism profile (command latency, motor time constant, deadband, "
        "wheel-speed scale) to a recording of a real robot's /cmd_vel and /odom; write a "
        "parameters file for simbridge --params.",
    )
    parser.add_argument("bag", help="the real robot's bag (directory or .mcap)")
    parser.add_argument("-o", "--output", default="fitted_params.yaml", help="parameters file")
    parser.add_argument("--params", help="the nominal parameters (default: the bundled ones)")
    parser.add_argument("--odom", default="/odom", help="odometry topic (default /odom)")
    parser.add_argument("--cmd-vel", default="/cmd_vel", help="command topic (default /cmd_vel)")
    args = parser.parse_args(argv)
    try:
        base = load_params(args.params)
        drive = load_drive(args.bag, args.odom, args.cmd_vel)
        result = fit(drive, base)
        write_params(result, Path(args.output), args.bag)
    except SimbridgeError as err:
        print(f"simbridge: {err}", file=sys.stderr)
        return 1
    except OSError as err:
        print(f"simbridge: cannot write '{args.output}': {err.strerror}", file=sys.stderr)
        return 1
    print(f"simbridge fit: {args.bag}")
    print(result.report())
    print(f"parameters: {args.output} (simbridge --params {args.output})")
    return 0
