"""The paper's own analyses (Sec. V.C) on differentiated flight logs.

With the velocity assumed tangential and the out-of-plane acceleration zero
(the paper's simplified measurement model, chosen because the tether force
dominates everything else):

    T_C_hat = -m / (cos(phi) cos(theta)) g . z_C                       (eq. 25)
    D_hat   = T_C_hat z_B . e_v + m g . e_v - m a_v                    (eq. 26, 27)
    eta_f   = T_C_hat / sum_i T_u,i                                     (eq. 28)

with ``e_v = v/|v|`` and ``a_v = d|v|/dt``; ``cos(phi) cos(theta) = z_B . z_C``.
``D_hat`` is the drag magnitude (positive against the motion). The drag model
eq. 10, ``D = mu1 |v| + mu2 |v|^2``, is fitted to ``D_hat`` by bounded linear least
squares (Fig. 6). The thrust efficiency is compared with momentum theory
(eq. 29, :class:`~gainsched.model.effects.ThrustMomentum`), whose one unknown, the
rotor disk area, is fitted to ``eta_f`` (Fig. 5).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import lsq_linear, minimize_scalar

from ..config import Config
from ..model.effects import ThrustMomentum
from .compare import Measured, centred_commands

__all__ = ["PaperFits", "paper_fits"]


@dataclass(frozen=True, eq=False)
class PaperFits:
    """Per-sample estimates (core samples of all segments) and the fits.

    airspeed (n,) m/s; T_hat (n,) N (eq. 25); T_cmd (n,) N commanded collective;
    eta (n,) (eq. 28); drag (n,) N (eq. 26); v_z (n,) m/s airspeed along z_B;
    mu1 N s/m, mu2 N s^2/m^2 with 95% half-widths (eq. 10 fit, Fig. 6); drag_rms N;
    disk_area m^2 (eq. 29 fit), momentum (n,) T/T_h of eq. 29 at the fitted area,
    momentum_rms; bins: airspeed bin table of eta and drag (mean, std, count).
    """

    airspeed: np.ndarray
    T_hat: np.ndarray
    T_cmd: np.ndarray
    eta: np.ndarray
    drag: np.ndarray
    v_z: np.ndarray
    mu1: float
    mu2: float
    mu1_ci: float
    mu2_ci: float
    drag_rms: float
    disk_area: float
    momentum: np.ndarray
    momentum_rms: float
    bins: dict

    def to_json(self) -> dict:
        return {
            "drag_fit": {"mu1": self.mu1, "mu1_ci95": self.mu1_ci, "mu2": self.mu2,
                         "mu2_ci95": self.mu2_ci, "rms_N": self.drag_rms,
                         "model": "D = mu1 |v| + mu2 |v|^2 (eq. 10) fitted to eq. 26"},
            "thrust_efficiency": {"momentum_theory_disk_area_m2": self.disk_area,
                                  "momentum_theory_rms": self.momentum_rms,
                                  "model": "eta_f (eq. 28) vs T/T_h of eq. 29"},
            "bins": self.bins,
            "samples": int(self.airspeed.size),
        }


def _estimates(m: Measured, mass: float, g: float):
    c = m.core
    R = m.R[c]
    v = m.v[c]
    a = m.a[c]
    speed = np.linalg.norm(v, axis=-1)
    e_v = v / np.maximum(speed, 1e-9)[:, None]
    a_v = np.sum(v * a, -1) / np.maximum(speed, 1e-9)
    g_C = -g * np.array([0.0, math.sin(m.alpha), math.cos(m.alpha)])
    z_B = R[:, :, 2]
    T_hat = -mass * (g_C[2]) / z_B[:, 2]  # eq. 25: cos(phi) cos(theta) = z_B . z_C
    drag = T_hat * np.sum(z_B * e_v, -1) + mass * (e_v @ g_C) - mass * a_v  # eq. 26
    T_cmd = np.sum(centred_commands(m.T_cmd)[c], -1)
    v_B = np.einsum("nji,nj->ni", R, v)
    return speed, T_hat, T_cmd, drag, v_B


def paper_fits(config: Config, measured, *, min_speed: float = 1.0) -> PaperFits:
    """Eqs. 25-29 on the measured segments (samples slower than ``min_speed`` m/s dropped)."""
    parts = [_estimates(m, config.vehicle.mass, config.g) for m in measured]
    speed = np.concatenate([p[0] for p in parts])
    keep = speed >= min_speed
    speed = speed[keep]
    T_hat = np.concatenate([p[1] for p in parts])[keep]
    T_cmd = np.concatenate([p[2] for p in parts])[keep]
    drag = np.concatenate([p[3] for p in parts])[keep]
    v_B = np.concatenate([p[4] for p in parts])[keep]
    eta = T_hat / T_cmd
    # Fig. 6: D = mu1 v + mu2 v^2, mu >= 0
    X = np.stack([speed, speed**2], -1)
    sol = lsq_linear(X, drag, bounds=(0.0, np.inf))
    mu1, mu2 = map(float, sol.x)
    r = drag - X @ sol.x
    s2 = float(np.sum(r * r)) / max(r.size - 2, 1)
    try:
        cov = np.linalg.inv(np.einsum("ni,nj->ij", X, X)) * s2
        ci = 1.96 * np.sqrt(np.diag(cov))
    except np.linalg.LinAlgError:
        ci = np.array([math.inf, math.inf])
    # Fig. 5: eta against momentum theory (eq. 29), disk area fitted
    T_per = np.repeat((T_cmd / 4)[:, None], 4, axis=1)

    def ratio(area):
        return ThrustMomentum(disk_area=area).ratio(T_per, v_B)[:, 0]

    def cost(log_a):
        d = eta - ratio(math.exp(log_a))
        return float(np.mean(d * d))

    opt = minimize_scalar(cost, bounds=(math.log(1e-5), math.log(0.1)), method="bounded")
    area = math.exp(float(opt.x))
    mom = ratio(area)
    # bins of 1 m/s
    edges = np.arange(math.floor(speed.min()), math.ceil(speed.max()) + 1.0, 1.0)
    if edges.size < 2:
        edges = np.array([speed.min(), speed.max() + 1e-9])
    idx = np.clip(np.digitize(speed, edges) - 1, 0, edges.size - 2)
    bins = {"edges": edges.tolist(), "count": np.bincount(idx, minlength=edges.size - 1).tolist()}
    for name, x in (("eta", eta), ("drag", drag), ("momentum", mom)):
        cnt = np.bincount(idx, minlength=edges.size - 1)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.bincount(idx, x, minlength=edges.size - 1) / cnt
            var = np.bincount(idx, x * x, minlength=edges.size - 1) / cnt - mean**2
        std = np.sqrt(np.maximum(var, 0))
        bins[name] = {"mean": [None if not np.isfinite(v) else float(v) for v in mean],
                      "std": [None if not np.isfinite(v) else float(v) for v in std]}
    return PaperFits(speed, T_hat, T_cmd, eta, drag, v_B[:, 2], mu1, mu2, float(ci[0]),
                     float(ci[1]), float(np.sqrt(np.mean(r * r))), area, mom,
                     float(np.sqrt(cost(opt.x))), bins)
