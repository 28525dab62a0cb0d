"""Phase-locked structure of the residual: what averaging over revolutions makes plain.

An overall RMS hides a small systematic effect: a thrust dip over 30 deg of azimuth
that is 1.7x the noise floor there is 1.1x overall. Here every residual axis is
averaged in bins of the azimuth over all revolutions (and in bins of airspeed,
commanded thrust and flight time), with a standard error from the spread between *blocks*: one block
per revolution for the azimuth, one per ``BLOCK_S`` seconds of a segment for the
others. A block mean averages out the measurement noise and keeps what repeats, and
the spread of the block means is an honest error bar for it (it contains the noise,
the correlated smoothing of the differentiation and whatever does not repeat), so no
noise model is needed. The block-to-block variance is pooled over the bins of an axis
(a bin sees only as many blocks as revolutions flown through it); each bin gets a
Student t test of "mean zero" with the pooled degrees of freedom, at a family-wise
level :data:`ALPHA` over all bins, axes and variables (Bonferroni).

A bin counts when it is significant and its mean is at least :data:`MIN_AMPLITUDE`
noise floors. A finding is the strongest such bin of an axis and variable, widened to the
contiguous significant bins around it (wrapping in azimuth): the sector, its mean
residual (the amplitude) with a 95 % confidence interval, and the t value.

This is plain statistics on the residuals of :mod:`gainsched.analysis.compare`; no
library bins by revolution with block standard errors, so it is written here
(scipy gives the t distribution).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..constants import BIN_VARIABLES

__all__ = ["ALPHA", "BLOCK_S", "STRUCTURE_BINS", "BinnedMean", "Finding", "binned_means",
           "findings"]

#: family-wise significance level over every bin, axis and variable
ALPHA = 0.01
#: block length (s) for the variables other than the azimuth
BLOCK_S = 0.5
#: bins per variable: the azimuth in 15 deg sectors, the others in quantile bins (the
#: flight time too: a drift, such as a battery's sag, is structure in time)
STRUCTURE_BINS = {"azimuth": 24, "airspeed": 8, "thrust": 8, "time": 8}
#: fewest blocks a bin needs to be tested
MIN_BLOCKS = 3
#: a significant bin is reported only when its mean is at least this many noise floors
#: (the per-sample RMS the measurement noise alone leaves): statistically sure and large
#: enough to matter. Below it, e.g. a 0.08 mm mean tether stretch on one fast flight of
#: the negative control (0.5x its floor, t = 4.3)
MIN_AMPLITUDE = 1.0


@dataclass(frozen=True)
class BinnedMean:
    """Block-averaged residual of one axis in bins of one variable.

    Attributes
    ----------
    axis, variable, unit : str
        The residual axis, the binning variable, the axis unit.
    edges : ndarray, shape (n + 1,)
        Bin edges in the variable's unit (deg for the azimuth).
    mean, se : ndarray, shape (n,)
        Mean of the block means and its standard error, axis unit (NaN: too few blocks).
    n_blocks : ndarray, shape (n,), int
    t : ndarray, shape (n,)
        ``mean / se``.
    p : ndarray, shape (n,)
        Two-sided p value of ``mean = 0`` (Student t, the pooled degrees of freedom).
    """

    axis: str
    variable: str
    unit: str
    edges: np.ndarray
    mean: np.ndarray
    se: np.ndarray
    n_blocks: np.ndarray
    t: np.ndarray
    p: np.ndarray

    @property
    def centers(self) -> np.ndarray:
        return 0.5 * (self.edges[1:] + self.edges[:-1])

    def to_json(self) -> dict:
        return {"axis": self.axis, "variable": self.variable, "unit": self.unit,
                "edges": self.edges.tolist(), "mean": self.mean.tolist(),
                "se": self.se.tolist(), "n_blocks": self.n_blocks.tolist(),
                "t": self.t.tolist(), "p": self.p.tolist()}


@dataclass(frozen=True)
class Finding:
    """A significant phase-locked (or airspeed-, thrust-locked) residual.

    Attributes
    ----------
    axis, variable, unit : str
    lo, hi : float
        The sector (or range) of the variable, its unit; for the azimuth ``hi`` may exceed
        360 when the sector wraps.
    amplitude, ci95 : float
        Mean residual over the sector's bins and its 95 % half-width, axis unit.
    t : float
        The strongest bin's t value.
    noise_floor : float
        The axis noise floor (RMS), axis unit, for scale.
    """

    axis: str
    variable: str
    unit: str
    lo: float
    hi: float
    amplitude: float
    ci95: float
    t: float
    noise_floor: float

    @property
    def center(self) -> float:
        c = 0.5 * (self.lo + self.hi)
        return c % 360.0 if self.variable == "azimuth" else c

    def sentence(self) -> str:
        vu = UNIT_OF[self.variable]
        rng = (f"{self.lo % 360:.0f}-{self.hi % 360 or 360:.0f} {vu}" if self.variable == "azimuth"
               else f"{self.lo:.3g}-{self.hi:.3g} {vu}")
        return (f"{self.axis} residual {self.amplitude:+.3g} +- {self.ci95:.2g} {self.unit} "
                f"at {self.variable} {rng} (t = {self.t:.1f}; "
                f"{abs(self.amplitude) / self.noise_floor:.2f}x the noise floor)")

    def to_json(self) -> dict:
        return {"axis": self.axis, "variable": self.variable, "unit": self.unit,
                "range": [self.lo, self.hi], "center": self.center,
                "amplitude": self.amplitude, "ci95": self.ci95, "t": self.t,
                "noise_floor": self.noise_floor, "sentence": self.sentence()}


#: units of the binning variables
UNIT_OF = {v: BIN_VARIABLES[v][0] for v in STRUCTURE_BINS}


def _blocks(res, variable: str) -> list[np.ndarray]:
    """Block index per sample of each segment: the revolution for the azimuth (from the
    unwrapped azimuth), else ``BLOCK_S`` seconds; unique over segments."""
    out, base = [], 0
    for r in res:
        if variable == "azimuth":
            turns = np.unwrap(np.deg2rad(r.variables["azimuth"])) / (2 * np.pi)
            k = np.floor(np.abs(turns - turns[0])).astype(int)
        else:
            k = np.floor((r.t - r.t[0]) / BLOCK_S).astype(int)
        out.append(base + k)
        base += int(k.max()) + 1
    return out


def _edges(variable: str, x: np.ndarray, n: int) -> np.ndarray:
    if variable == "azimuth":
        return np.linspace(0.0, 360.0, n + 1)
    edges = np.unique(np.quantile(x, np.linspace(0, 1, n + 1)))
    if edges.size < 2:
        return np.array([x.min() - 0.5, x.max() + 0.5])
    edges[-1] += 1e-9 * max(1.0, abs(edges[-1]))
    return edges


def binned_means(res, axes, variable: str, n_bins: int | None = None,
                 units=None) -> dict[str, BinnedMean]:
    """Block-averaged residual per bin of ``variable`` for each of ``axes``.

    Parameters
    ----------
    res : list of Residual
        Residual segments (:func:`gainsched.analysis.compare.residuals`).
    axes : sequence of str
    variable : {"azimuth", "airspeed", "thrust", "time"}
    n_bins : int, optional
        Default :data:`STRUCTURE_BINS`.
    units : dict, optional
        Unit per axis (for the reports).
    """
    from scipy.stats import t as student

    n_bins = n_bins or STRUCTURE_BINS[variable]
    x = np.concatenate([r.variables[variable] for r in res])
    blk = np.concatenate(_blocks(res, variable))
    edges = _edges(variable, x, n_bins)
    nb = edges.size - 1
    b = np.clip(np.digitize(x, edges) - 1, 0, nb - 1)
    # one cell per (block, bin): its sample mean
    cell = blk * nb + b
    ucell, inv, cnt = np.unique(cell, return_inverse=True, return_counts=True)
    cell_bin = ucell % nb
    out = {}
    for a in axes:
        e = np.concatenate([r.residual[a] for r in res])
        cmean = np.bincount(inv, e) / cnt
        n = np.bincount(cell_bin, minlength=nb)
        s1 = np.bincount(cell_bin, cmean, minlength=nb)
        s2 = np.bincount(cell_bin, cmean * cmean, minlength=nb)
        ok = n >= MIN_BLOCKS
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = s1 / n
            # the block-to-block variance pooled over the bins (one per axis): a few
            # revolutions per bin give too few degrees of freedom on their own
            ss = np.where(ok, s2 - n * mean * mean, 0.0)
            dof = int(np.sum(np.where(ok, n - 1, 0)))
            var = float(np.sum(ss)) / max(dof, 1)
            se = np.sqrt(var / n)
            t = mean / se
        mean, se, t = (np.where(ok, v, np.nan) for v in (mean, se, t))
        p = np.where(ok, 2 * student.sf(np.abs(np.nan_to_num(t)), max(dof, 1)), np.nan)
        out[a] = BinnedMean(a, variable, (units or {}).get(a, ""), edges, mean, se, n, t, p)
    return out


def _sector(bm: BinnedMean, sig: np.ndarray, k: int) -> list[int]:
    """Contiguous significant bins of the same sign around bin ``k`` (wrapping in azimuth)."""
    nb = sig.size
    wrap = bm.variable == "azimuth"
    sign = np.sign(bm.mean[k])
    idx = [k]
    for step in (-1, 1):
        j = k
        while True:
            j += step
            if wrap:
                j %= nb
            if not 0 <= j < nb or j in idx or not sig[j] or np.sign(bm.mean[j]) != sign:
                break
            idx.append(j)
    return idx


def findings(res, noise: dict, *, units=None,
             variables=None) -> tuple[list[Finding], dict]:
    """Significant binned structure of every residual axis.

    Parameters
    ----------
    res : list of Residual
    noise : dict
        Noise floor (RMS) per axis, axis unit.
    units : dict, optional
        Unit per axis.
    variables : sequence of str, optional
        Binning variables (keys of :data:`STRUCTURE_BINS`); default: every one the
        segments have.

    Returns
    -------
    findings : list of Finding
        At most one per (axis, variable), strongest first (largest |t|).
    tables : dict
        ``{variable: {axis: BinnedMean}}``.
    """
    axes = [a for a in res[0].residual if all(a in r.residual for r in res)]
    if variables is None:
        variables = [v for v in STRUCTURE_BINS if all(v in r.variables for r in res)]
    tables = {v: binned_means(res, axes, v, units=units) for v in variables}
    m = sum(int(np.count_nonzero(np.isfinite(bm.p))) for tab in tables.values()
            for bm in tab.values())
    level = ALPHA / max(m, 1)
    out = []
    for v, tab in tables.items():
        for a, bm in tab.items():
            big = np.abs(bm.mean) >= MIN_AMPLITUDE * float(noise.get(a, 0.0))
            sig = np.isfinite(bm.p) & (bm.p < level) & big
            if not sig.any():
                continue
            k = int(np.nanargmax(np.where(sig, np.abs(bm.t), -np.inf)))
            idx = _sector(bm, sig, k)
            if v == "azimuth":  # the sector may wrap: start at its first bin
                start, nb = k, sig.size
                while (start - 1) % nb in idx and len(idx) < nb and (start - 1) % nb != k:
                    start = (start - 1) % nb
                lo = float(bm.edges[start])
                hi = lo + float(bm.edges[1] - bm.edges[0]) * len(idx)
            else:
                lo, hi = float(bm.edges[min(idx)]), float(bm.edges[max(idx) + 1])
            w = bm.n_blocks[idx].astype(float)
            amp = float(np.sum(w * bm.mean[idx]) / np.sum(w))
            se = float(math.sqrt(np.sum((w * bm.se[idx]) ** 2)) / np.sum(w))
            out.append(Finding(a, v, bm.unit, float(lo), float(hi), amp, 1.96 * se,
                               float(bm.t[k]), float(noise.get(a, math.nan))))
    out.sort(key=lambda f: -abs(f.t))
    return out, tables
