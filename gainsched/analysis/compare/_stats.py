"""The statistics of one residual axis pooled over the segments: RMS, bias, fit, whiteness
and the cross-correlation with the inputs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import uniform_filter1d
from scipy.signal import correlate

from ._axes import UNITS
from ._residual import Residual


@dataclass(frozen=True)
class AxisStats:
    """Statistics of one residual axis over all segments (units: :data:`UNITS`).

    rms, bias (mean), std; fit_percent = 100 (1 - |y - y_hat| / |y - mean y|);
    noise_floor: RMS residual that the measurement noise alone produces.

    Whiteness: the differentiation filter correlates samples closer than its window
    W, so the test looks at lags W, 2W, ... up to ``max_lag_s`` (roughly independent
    estimates) of the residual standardised by its local RMS (:func:`_standardised`;
    ``acf`` is that of the standardised residual): ``Q = sum rho(kW)^2 / var`` with the
    Bartlett variance
    ``var = (1 + 2 sum_{j<W} rho(j)^2) / n``, white when Q is below the 99% point of
    chi-square with as many degrees of freedom as lags. ``acf_band`` is the 95%
    band of a single lag; ``frac_outside`` the fraction of lags >= W outside it.

    Cross-correlation of the standardised residual with each input and its rate over
    +-``max_lag_s``: ``ccf`` maps
    input -> (peak |rho|, lag s at the peak, band, significant); the band is the
    Bartlett band corrected for testing every lag (Bonferroni over the ~2L/W
    independent lags). Positive lag: the residual follows the input.
    """

    axis: str
    unit: str
    n: int
    rms: float
    bias: float
    std: float
    fit_percent: float
    noise_floor: float
    white: bool
    whiteness_q: float
    whiteness_limit: float
    frac_outside: float
    acf_lags: np.ndarray
    acf: np.ndarray
    acf_band: float
    ccf: dict
    ccf_lags: np.ndarray
    ccf_curves: dict

    @property
    def rms_over_noise(self) -> float:
        return self.rms / self.noise_floor if self.noise_floor > 0 else math.nan

    def to_json(self) -> dict:
        return {
            "unit": self.unit, "n": self.n, "rms": self.rms, "bias": self.bias, "std": self.std,
            "fit_percent": self.fit_percent, "noise_floor": self.noise_floor,
            "rms_over_noise": _num(self.rms_over_noise),
            "white": self.white, "whiteness_q": self.whiteness_q,
            "whiteness_limit_99": self.whiteness_limit,
            "acf_frac_outside_band": self.frac_outside, "acf_band_95": self.acf_band,
            "acf": {"lag_s": self.acf_lags.tolist(), "value": self.acf.tolist()},
            "ccf_peaks": {k: {"abs_rho": v[0], "lag_s": v[1], "band": v[2], "significant": v[3]}
                          for k, v in self.ccf.items()},
        }


def _num(x):
    """A float for JSON (None for nan/inf)."""
    return float(x) if x is not None and np.isfinite(x) else None


def _standardised(x: np.ndarray, width: int) -> np.ndarray:
    """``x`` divided by its local RMS (a running mean of ``x^2`` over ``width`` samples).

    The correlation tests pool segments whose noise differs by 20x (the rotational axes'
    noise grows with the tether tension, ~speed^2): unscaled, the fastest flight carries
    the pooled correlation and the Bartlett variance with all n samples is far too small
    (the project's negative control failed the 99 % whiteness test on pitch, Q 18.8 >
    13.3; standardised 3.4). Scaled, every sample counts alike, as the test assumes.
    """
    rms = np.sqrt(uniform_filter1d(x * x, width, mode="nearest"))
    return np.divide(x, rms, out=np.zeros_like(x), where=rms > 0)


def _pooled_corr(xs, ys, max_lag):
    """Cross-correlation of zero-mean series pooled over segments, lags -max_lag..max_lag:
    ``sum_seg sum_t x_t y_{t-k} / sqrt(sum x^2 sum y^2)``."""
    num = np.zeros(2 * max_lag + 1)
    sx = sy = 0.0
    for x, y in zip(xs, ys, strict=True):
        n = x.size
        full = correlate(x, y, mode="full", method="fft")
        lo, hi = n - 1 - max_lag, n + max_lag
        seg = full[max(lo, 0) : hi]
        num[max(0, -lo) : max(0, -lo) + seg.size] += seg
        sx += float(np.sum(x * x))
        sy += float(np.sum(y * y))
    return num / math.sqrt(sx * sy) if sx * sy > 0 else num


def axis_stats(res: list[Residual], axis: str, noise_floor: float = math.nan,
               max_lag_s: float = 0.5) -> AxisStats:
    """Statistics of ``axis`` pooled over segments (see :class:`AxisStats`)."""
    from scipy.stats import chi2, norm

    y = np.concatenate([r.measured[axis] for r in res])
    yh = np.concatenate([r.predicted[axis] for r in res])
    e = y - yh
    n = e.size
    rms = float(np.sqrt(np.mean(e**2)))
    bias = float(np.mean(e))
    den = float(np.linalg.norm(y - y.mean()))
    fit = float(100 * (1 - np.linalg.norm(e) / den)) if den > 0 else math.nan
    dt = float(np.median(np.concatenate([np.diff(r.t) for r in res])))
    W = max(r.window for r in res)
    L = max(2 * W, int(round(max_lag_s / dt)))
    # standardised first, then centred: the raw bias is the loud segments' mean, and
    # taken from a quiet segment it is an offset there that reads as correlation
    zs = [_standardised(r.residual[axis], 4 * L + 1) for r in res]
    z_mean = float(np.mean(np.concatenate(zs)))
    xs = [z - z_mean for z in zs]
    acf = _pooled_corr(xs, xs, L)[L:]
    var1 = (1 + 2 * float(np.sum(acf[1:W] ** 2))) / n
    band = 1.96 * math.sqrt(var1)
    tail = acf[W:]
    frac = float(np.mean(np.abs(tail) > band)) if tail.size else 0.0
    lags = np.arange(W, L + 1, W)
    q = float(np.sum(acf[lags] ** 2) / var1)
    limit = float(chi2.ppf(0.99, lags.size))
    n_ind = max(1.0, (2 * L + 1) / W)
    z = float(norm.ppf(1 - 0.025 / n_ind))
    ccf, curves = {}, {}
    for nm in res[0].inputs:
        us = [r.inputs[nm] - np.mean(r.inputs[nm]) for r in res]
        rho = _pooled_corr(xs, us, L)
        acf_u = _pooled_corr(us, us, W)[W:]
        # Bartlett: var(rho_xu(k)) ~ (1/n) sum_j rho_x(j) rho_u(j); rho_x ~ 0 beyond W
        var = (1 + 2 * float(np.sum(np.abs(acf[1:W] * acf_u[1:W])))) / n
        b = z * math.sqrt(var)
        k = int(np.argmax(np.abs(rho)))
        peak = float(abs(rho[k]))
        ccf[nm] = (peak, float((k - L) * dt), b, peak > b)
        curves[nm] = rho
    return AxisStats(axis, UNITS[axis], n, rms, bias, float(np.std(e)), fit, float(noise_floor),
                     bool(q <= limit), q, limit, frac, np.arange(L + 1) * dt, acf, band, ccf,
                     np.arange(-L, L + 1) * dt, curves)
