"""Build budget: memory and CPU time a ``gainsched build`` of a config needs, estimated.

A config can ask for a build that no machine finishes (a million speeds, a 1 GHz
control rate, a million azimuth samples). :func:`check_budget` refuses it at
validation, in microseconds, with the key that drives the estimate, instead of
letting the build run out of memory or time.

The model follows :mod:`gainsched.schedule.grid` (one job per speed, the tilts of a job in
batches of ``TILT_BATCH``):

* **Steps.** A circle at speed ``v`` has ``N = 2 round(T / (2 dt))`` control steps
  per period, ``T = 2 pi r / v`` (``r = rho + L_e``, ``dt = 1 / rate_hz``); the
  slowest speed has the most.
* **Memory of a job.** The zero-order-hold ``A_d`` (n x n) and ``B_d`` (n x 4) of a
  batch of ``min(8, n_tilts)`` tilts at every step, 8 bytes each, ``n = 11 + the
  effects' states``; twice that while the trigonometric interpolation builds them
  (measured: 1.5x on the paper vehicle at 32 kHz).
* **The table.** ``n_tilts * n_speeds * azimuth_samples * (n n + 4 n + 8)`` doubles
  (K, S, u_d, phi_d, tension, ...), held twice while the per-speed results are
  stacked. The peak of one process is a job plus the table twice (the jobs may run
  in the process that assembles the table).
* **CPU time.** ``C_STEP`` per tilt and step (the periodic Riccati sweep and the
  interpolated linearisation), ``C_CIRCLE`` per circle (nominal, trim, exact
  linearisation at 64-128 azimuths) and ``C_POINT`` per table point. Calibrated on
  the paper vehicle with every circle feasible (an infeasible circle skips the
  LQR), so the estimate is an upper bound: 3.8 CPU-s for ``configs/paper.toml``,
  which builds in 1.6 s (a third of its circles are infeasible).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from ..constants import N_INPUT, TILT_BATCH
from ..errors import InputError

__all__ = ["BuildEstimate", "BuildConfig", "estimate_build", "check_budget", "GIB"]

GIB = 2.0**30
#: copies of a batch's (A_d, B_d) alive at the peak of a job (interpolation temporaries)
JOB_COPIES = 2
#: CPU seconds per (tilt, control step), per (tilt, speed) circle and per table point
#: (one core, pinned numerics; measured on the paper vehicle, all circles feasible)
C_STEP = 8e-6
C_CIRCLE = 2e-2
C_POINT = 5e-6
#: the paper's control rate: above it, the rate (not the slowest speed) is blamed for steps
REF_RATE_HZ = 1000.0
#: the paper's circle radius rho + L_e (m) and slowest speed (m/s): a radius further above
#: it than the rate and the slowness blames tether.length for the steps
REF_RADIUS = 1.6
REF_SPEED_MIN = 1.3
#: the paper grid (speeds, tilts, azimuth samples): the axis furthest above it is blamed
REF_GRID = {"grid.speeds": 18, "grid.tilts_deg": 6, "grid.azimuth_samples": 36}


class BuildConfig(Protocol):
    """What an estimate reads of a config: :class:`gainsched.config.Config` is one.

    This module owns the type it takes and names no class of the config layer (which
    calls it while it validates, from above): a structural type, the fields below.

    Attributes
    ----------
    grid : Grid
        ``speeds`` (n_v,) m/s, ``tilts`` (n_a,) rad, ``azimuth_samples``, and the ranges
        the build chooses (``speeds_auto.lo``, ``.hi``, ``.max_count``;
        ``tilts_auto.max_count``; ``azimuth_auto.hi``; None for a listed axis).
    control : Control
        ``rate_hz`` (Hz) and ``n_lqr`` (LQR states without the effects').
    effects : tuple of EffectSpec
        Each with the ``name`` of a registered effect (its states add to the LQR's).
    tether : Tether
        ``length`` (m), named when the circle's length drives the estimate.
    limits : Limits
        ``max_memory_gib`` (GiB) and ``max_build_cpu_s`` (s).
    radius : float, m
        The nominal COG circle radius ``rho + L_e``.
    """

    grid: Any
    control: Any
    effects: Any
    tether: Any
    limits: Any

    @property
    def radius(self) -> float: ...


@dataclass(frozen=True)
class BuildEstimate:
    """What a build of one config needs (estimates, upper bounds).

    Attributes
    ----------
    peak_bytes : float, bytes
        Peak memory of one build process: one job plus the table held twice.
    worker_bytes : float, bytes
        Peak memory of one job (one speed, one batch of tilts at every step).
    table_bytes : float, bytes
        The assembled table in memory (once).
    cpu_s : float, s
        CPU time of the whole build, summed over workers.
    steps_max : float
        Control steps per period at the slowest speed.
    dominant : str
        The largest term of the resource closest to its ``[limits]``, in words.
    key : str
        The config key that drives that term (e.g. ``control.rate_hz``).
    memory_term, cpu_term : (str, str)
        The largest term of the memory and of the CPU estimate: (words, key).
    """

    peak_bytes: float
    worker_bytes: float
    table_bytes: float
    cpu_s: float
    steps_max: float
    dominant: str
    key: str
    memory_term: tuple[str, str] = ("", "")
    cpu_term: tuple[str, str] = ("", "")


def _lqr_states(config: BuildConfig) -> int:
    from ..model.effects import EFFECTS

    return config.control.n_lqr + sum(EFFECTS[e.name].n_states for e in config.effects
                                      if e.name in EFFECTS)


def _grid_key(counts: dict[str, int]) -> str:
    """The grid key whose size is furthest above the paper grid."""
    return max(counts, key=lambda k: counts[k] / REF_GRID[k])


def estimate_build(config: BuildConfig) -> BuildEstimate:
    """Memory (bytes) and CPU time (s) of building ``config``'s grid; see the module docs.

    Vectorised over the speeds: microseconds even for a million speeds.
    """
    grid = config.grid
    # an axis the build chooses is estimated at its largest: max_count points
    speeds = (np.linspace(grid.speeds_auto.lo, grid.speeds_auto.hi, grid.speeds_auto.max_count)
              if grid.speeds_auto else np.asarray(grid.speeds, dtype=float))
    n_v = speeds.size
    n_t = grid.tilts_auto.max_count if grid.tilts_auto else int(np.asarray(grid.tilts).size)
    n_xi = grid.azimuth_auto.hi if grid.azimuth_auto else int(grid.azimuth_samples)
    rate = float(config.control.rate_hz)
    r = config.radius
    n = _lqr_states(config)
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        steps = np.maximum(2.0, 2.0 * np.rint(2 * np.pi * r / speeds * rate / 2))
        steps_max = float(steps.max())
        steps_sum = float(steps.sum())
    batch = min(TILT_BATCH, n_t)
    worker = JOB_COPIES * 8.0 * batch * steps_max * (n * n + N_INPUT * n)
    points = float(n_t) * n_v * n_xi
    table = points * (n * n + N_INPUT * n + 8) * 8.0
    peak = worker + 2 * table
    cpu_terms = {
        "steps": C_STEP * n_t * steps_sum,
        "circles": C_CIRCLE * n_t * n_v,
        "points": C_POINT * points,
    }
    cpu = sum(cpu_terms.values())
    v_min = float(speeds.min())
    step_key = "control.rate_hz" if rate > REF_RATE_HZ else "grid.speeds"
    if r / REF_RADIUS > max(rate / REF_RATE_HZ, REF_SPEED_MIN / v_min, 1.0):
        step_key = "tether.length"  # the circle is long, not the speed slow nor the rate high
    step_text = {
        "control.rate_hz":
            f"control.rate_hz {rate:g} Hz: {steps_max:.2g} steps per period at {v_min:g} m/s",
        "grid.speeds":
            f"grid.speeds down to {v_min:g} m/s: {steps_max:.2g} steps per period at {rate:g} Hz",
        "tether.length":
            f"tether.length {config.tether.length:g} m: a {r:g} m circle, {steps_max:.2g} steps "
            f"per period at {v_min:g} m/s and {rate:g} Hz",
    }[step_key]
    shape = f"{n_t} tilts x {n_v} speeds x {n_xi} azimuth samples"
    axes = {"grid.speeds": n_v, "grid.tilts_deg": n_t, "grid.azimuth_samples": n_xi}
    if worker >= 2 * table:
        mem = (step_text, step_key)
    else:
        mem = (f"the table of {shape}, {table / GIB:.3g} GiB, held twice while it is assembled",
               _grid_key(axes))
    term = max(cpu_terms, key=lambda k: cpu_terms[k])
    two = {k: axes[k] for k in ("grid.speeds", "grid.tilts_deg")}
    if term == "steps" and rate <= REF_RATE_HZ and n_v > REF_GRID["grid.speeds"]:
        cpu_why = (f"{n_t} tilts x {steps_sum:.3g} steps over {n_v} speeds at {rate:g} Hz",
                   _grid_key(two))
    elif term == "steps":
        cpu_why = (f"{n_t} tilts x {step_text}", step_key)
    elif term == "circles":
        cpu_why = (f"{n_t} tilts x {n_v} speeds = {n_t * n_v} circles", _grid_key(two))
    else:
        cpu_why = (f"{shape} = {points:.3g} table points", _grid_key(axes))
    lim = config.limits
    worse = mem if peak / (lim.max_memory_gib * GIB) >= cpu / lim.max_build_cpu_s else cpu_why
    return BuildEstimate(peak, worker, table, cpu, steps_max, *worse, memory_term=mem,
                         cpu_term=cpu_why)


def _fmt(x: float) -> str:
    return f"{x:.2g}" if math.isfinite(x) else "inf"


def check_budget(config: BuildConfig, source) -> BuildEstimate:
    """Refuse a config whose build needs more than ``config.limits`` allows.

    Raises :class:`InputError` naming ``source`` and the key that drives the estimate,
    with the estimate and the limit, e.g. ``control.rate_hz: needs about 37 GiB per
    worker (control.rate_hz 1e+05 Hz: ...); limit limits.max_memory_gib = 8``.
    Returns the estimate otherwise.
    """
    est = estimate_build(config)
    lim = config.limits
    if not est.peak_bytes <= lim.max_memory_gib * GIB:
        why, key = est.memory_term
        raise InputError(
            source,
            key,
            f"needs about {_fmt(est.peak_bytes / GIB)} GiB per worker ({why}); "
            f"limit limits.max_memory_gib = {lim.max_memory_gib:g}",
        )
    if not est.cpu_s <= lim.max_build_cpu_s:
        why, key = est.cpu_term
        raise InputError(
            source,
            key,
            f"needs about {_fmt(est.cpu_s)} CPU-s to build ({why}); "
            f"limit limits.max_build_cpu_s = {lim.max_build_cpu_s:g}",
        )
    return est
