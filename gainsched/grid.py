"""The grid sweep: nominal, linearisation, periodic LQR at every (speed, tilt) circle.

One job per speed (joblib, in config order, so results are deterministic);
inside a job every tilt is solved at once as a batch. The step count per
period is ``N = 2 round(T / (2 dt))`` (even, so that the symmetry maps land on
steps) and the discretisation uses ``dt_k = T / N``, within 0.15 % of the
control period on the paper grid. Gains at the azimuth grid are interpolated
linearly between the two steps that bracket each grid azimuth.

A circle with any infeasible sample (slack, thrust limits, trim failure) has
no gains: NaN in K, and the reason bits say why.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
from joblib import Parallel, delayed

from .linearize import discretize, jacobians, lqr_system
from .lqr import monodromy, periodic_lqr, spectral_radius
from .model import Model
from .nominal import circle_nominal, period
from .trim import TrimError

__all__ = ["CircleSolution", "solve_circle", "build_grid", "GridResult", "steps_per_period"]


def steps_per_period(speed: float, r: float, dt: float) -> int:
    """Even number of control steps closest to one period."""
    return max(2, 2 * int(round(period(speed, r) / (2 * dt))))


@dataclass(frozen=True)
class CircleSolution:
    """Everything the table needs for one speed, all tilts (leading axis: tilt).

    Attributes
    ----------
    K : (n_a, n_xi, 4, n) gains at the grid azimuths (NaN if infeasible)
    S : (n_a, n_xi, n, n) cost-to-go at the grid azimuths
    u_d : (n_a, n_xi, 4) N; phi_d : (n_a, n_xi) rad; tension : (n_a, n_xi) N
    reasons : (n_a, n_xi) uint8
    rho : (n_a,) closed-loop monodromy spectral radius (NaN if infeasible)
    sweeps : (n_a,) int; steps : int; dt : float, s
    """

    K: np.ndarray
    S: np.ndarray
    u_d: np.ndarray
    phi_d: np.ndarray
    tension: np.ndarray
    reasons: np.ndarray
    rho: np.ndarray
    sweeps: np.ndarray
    steps: int
    dt: float


def _sample(X, n_xi):
    """Values at grid azimuths 2 pi j / n_xi from the N step values along axis -3/-... (axis 1)."""
    N = X.shape[1]
    pos = np.arange(n_xi) * (N / n_xi)
    k = np.floor(pos).astype(int)
    w = (pos - k).reshape((1, n_xi) + (1,) * (X.ndim - 2))
    return (1 - w) * X[:, k] + w * X[:, (k + 1) % N]


def solve_circle(config, speed: float, tilts, *, keep_steps=False):
    """Periodic LQR for one speed at all ``tilts`` (rad, batched).

    Returns a :class:`CircleSolution` (and, with ``keep_steps``, the per-step
    ``(Ad, Bd, K)`` for checks).
    """
    model = Model(config)
    tilts = np.asarray(tilts, dtype=float)
    n_xi = config.grid.azimuth_samples
    N = steps_per_period(speed, model.r, config.control.dt)
    dt = period(speed, model.r) / N
    n_a = tilts.size

    zs, us, bad = [], [], np.zeros(n_a, dtype=np.uint8)
    grid_nom = []
    for i, a in enumerate(tilts):
        try:
            nom = circle_nominal(model, speed, a, N)
            gnom = circle_nominal(model, speed, a, n_xi)
            bad[i] = np.bitwise_or.reduce(nom.reasons)
        except TrimError:
            nom = gnom = None
            bad[i] = 8
        zs.append(None if nom is None else nom.z)
        us.append(None if nom is None else nom.u)
        grid_nom.append(gnom)
    ok = np.flatnonzero(bad == 0)
    n = model.n_z + 1
    K = np.full((n_a, n_xi, 4, n), np.nan)
    S = np.full((n_a, n_xi, n, n), np.nan)
    rho = np.full(n_a, np.nan)
    sweeps = np.zeros(n_a, dtype=np.int32)
    u_d = np.full((n_a, n_xi, 4), np.nan)
    phi_d = np.full((n_a, n_xi), np.nan)
    tension = np.full((n_a, n_xi), np.nan)
    reasons = np.full((n_a, n_xi), 8, dtype=np.uint8)
    for i, g in enumerate(grid_nom):
        if g is not None:
            u_d[i], phi_d[i], tension[i] = g.u, g.phi, g.tension
            reasons[i] = g.reasons | np.where((g.reasons == 0) & (bad[i] != 0), 16, 0).astype(
                np.uint8
            )
    steps = None
    if ok.size:
        z = np.stack([zs[i] for i in ok])
        u = np.stack([us[i] for i in ok])
        A, B = jacobians(model, z, u, tilts[ok][:, None])
        Ax, Bx = lqr_system(A, B)
        Ad, Bd = discretize(Ax, Bx, dt)
        Qx = np.zeros((n, n))
        Qx[:11, :11] = config.control.Q
        sol = periodic_lqr(Ad, Bd, Qx, config.control.R, terminal=config.control.terminal,
                           keep_S=True)  # fmt: skip
        K[ok] = _sample(sol.K, n_xi)
        S[ok] = _sample(sol.S[:, :-1], n_xi)
        rho[ok] = spectral_radius(monodromy(Ad, Bd, sol.K))
        sweeps[ok] = sol.sweeps
        if keep_steps:
            steps = (Ad, Bd, sol.K)
    out = CircleSolution(K, S, u_d, phi_d, tension, reasons, rho, sweeps, N, dt)
    return (out, steps) if keep_steps else out


@dataclass(frozen=True)
class GridResult:
    """The whole grid, axes (tilt, speed, xi). Arrays as in CircleSolution with a speed axis
    after the tilt axis; ``steps`` and ``dt`` per speed."""

    K: np.ndarray
    S: np.ndarray
    u_d: np.ndarray
    phi_d: np.ndarray
    tension: np.ndarray
    reasons: np.ndarray
    rho: np.ndarray
    sweeps: np.ndarray
    steps: np.ndarray
    dt: np.ndarray


def build_grid(config, *, n_jobs=1, progress=None, backend=None) -> GridResult:
    """Sweep all speeds (one joblib job each) and assemble the grid.

    Parameters
    ----------
    config : Config
    n_jobs : int
        joblib workers (-1: all cores).
    progress : callable(int) or None
        Called with 1 after each finished speed (e.g. ``tqdm.update``).
    backend : str, optional
        joblib backend name (``"loky"``, ``"threading"``, ``"dask"``...).
    """
    speeds = config.grid.speeds
    tilts = config.grid.tilts
    jobs = (delayed(solve_circle)(config, float(v), tilts) for v in speeds)
    par = Parallel(n_jobs=n_jobs, backend=backend, return_as="generator")
    sols = []
    for s in par(jobs):
        sols.append(s)
        if progress is not None:
            progress(1)

    per_tilt = {f.name: np.stack([getattr(s, f.name) for s in sols], axis=1)
                for f in fields(CircleSolution) if f.name not in ("steps", "dt")}  # fmt: skip
    return GridResult(**per_tilt, steps=np.array([s.steps for s in sols]),
                      dt=np.array([s.dt for s in sols]))  # fmt: skip
