"""The fit problem: the flight logs, the base config, the noise weights.

:class:`_Problem` evaluates the model variant of a candidate
(:class:`~gainsched.analysis.diagnose._candidates.CandidateModel`) on every flight: the
residual of :mod:`gainsched.analysis.compare` (measured minus the prediction of the
equations of motion, paper eqs. 3, 6, 8, 10, as compare's module docstring says), every
axis divided by its noise floor (so 1 per axis and sample is pure noise), the segments
grouped by flight (the folds of the leave-one-flight-out scores). The base model's
residual is computed once; the pose is re-measured only for another attachment point
(the attachment offset, the centre of mass's offset).
It also scores the binned structure (:mod:`gainsched.analysis.structure`) that a fit
leaves or removes, and runs independent fits side by side (:meth:`_Problem.map`).
"""

from __future__ import annotations

import copy
from concurrent.futures import ThreadPoolExecutor
from types import SimpleNamespace

import numpy as np

from ...config import Config
from ...model.reduced import Model
from ...schedule.jobs import local_processes
from ..compare import (
    UNITS,
    Comparison,
    attachment_from_cog_config,
    measure,
    residual_axes,
)
from ..structure import Finding, binned_means, findings
from ._candidates import CandidateModel

#: the fewest logged samples (all flights) for which :meth:`_Problem.map` runs fits in
#: threads. Measured 2026-12-03 (2 cores, the bench's 7 flights with rotor drag, diagnose
#: one thread / two): 1.9 s / 2.9 s at 3,857 samples (the example flights), 2.0 s /
#: 2.3 s at 12,000, 3.3 s / 3.0 s at 30,000, 11.5 s / 7.3 s at 120,000 (10 minutes)
THREADS_MIN_SAMPLES = 50_000


class _Problem:
    """The logs, the base config, the weights; evaluates variants on every flight."""

    def __init__(self, config: Config, measured, segs, noise: dict, residuals,
                 n_jobs: int = -1):
        self.config = config
        self.n_jobs = n_jobs
        self.residuals = residuals  # the base comparison's, for their binning variables
        self.segs = segs
        self._meas = {_geometry(config): measured}
        self.axes = tuple(a for a in noise if np.isfinite(noise[a]) and noise[a] > 0)
        self.weights = {a: 1.0 / noise[a] for a in self.axes}
        groups: dict[str, list[int]] = {}
        for i, m in enumerate(measured):
            groups.setdefault(m.source, []).append(i)
        self.flights = list(groups.values())
        self.flight_names = [measured[g[0]].name.split("#")[0] for g in self.flights]
        self.window = max(m.window for m in measured)
        self.n_evals = 0
        speeds = np.concatenate([r.variables["airspeed"] for r in residuals])
        self.airspeed_range = (float(speeds.min()), float(speeds.max()))
        tensions = np.concatenate([r.variables["tension"] for r in residuals])
        self.tension_range = (float(tensions.min()), float(tensions.max()))
        self.structure_keys: list[tuple[str, str]] = []
        self._base: list[dict] | None = None
        self._p_before: tuple | None = None

    def map(self, jobs, progress=None) -> list:
        """``[job(problem) for label, job in jobs]``, the jobs (independent fits) run side
        by side in threads (``n_jobs``, -1: every core), each on its own view of this
        problem (:meth:`_view`), the results in order; ``progress(label)`` as each result
        comes, in order.

        Threads, not processes: a fit's time goes to numpy and scipy on arrays of the
        logs' length, which leave the GIL while they work, and the logs (120 MB for 10
        minutes of 7 flights) need not travel. Below :data:`THREADS_MIN_SAMPLES` the
        arrays are short and the threads wait on each other for the GIL more than they
        work: one thread. Every fit computes what it computes alone: the results, and
        the count of evaluations, do not depend on ``n_jobs``."""
        jobs = list(jobs)
        n = local_processes(self.n_jobs, len(jobs))
        if sum(m.t.size for m in self._meas[_geometry(self.config)]) < THREADS_MIN_SAMPLES:
            n = 1
        if n <= 1:
            out = []
            for label, job in jobs:
                out.append(job(self))
                if progress is not None:
                    progress(label)
            return out
        self._base_residuals()  # shared by the views, computed once
        self.base_structure_power()
        views = [self._view() for _ in jobs]
        out = []
        pool = ThreadPoolExecutor(n, thread_name_prefix="gainsched-fit")
        try:
            futures = [pool.submit(job, v) for (_, job), v in zip(jobs, views, strict=True)]
            for (label, _), f in zip(jobs, futures, strict=True):
                out.append(f.result())
                if progress is not None:
                    progress(label)
        finally:  # an error or Ctrl-C: the fits not started are dropped
            pool.shutdown(wait=True, cancel_futures=True)
        self.n_evals += sum(v.n_evals for v in views)
        return out

    def _view(self) -> _Problem:
        """This problem for a fit in another thread: the same logs, weights and base
        residual (read only), its own cache of the flights measured at another
        attachment point (:meth:`measured`) and its own count of evaluations."""
        view = copy.copy(self)
        view._meas = dict(self._meas)
        view.n_evals = 0
        return view

    def track_structure(self, comparison: Comparison) -> None:
        """Score fits also on the binned structure that ``comparison`` found (its
        findings' axes and binning variables): :meth:`structure_power`."""
        keys = [(f.axis, f.variable) for f in comparison.structure if f.axis in self.axes]
        self.structure_keys = list(dict.fromkeys(keys))
        self._p_before = None

    def structure_power(self, vecs) -> float | None:
        """Noise-corrected power of the block-averaged bins of weighted residuals ``vecs``
        (list over flights of {axis: (n,)}) on the tracked findings: the sum over them
        of ``sum_b n_b max(mean_b^2 - se_b^2, 0)`` (:func:`binned_means`); None when none
        are tracked."""
        if not self.structure_keys:
            return None
        segs = self._segments(vecs)
        total = 0.0
        for axis, var in self.structure_keys:
            bm = binned_means(segs, [axis], var)[axis]
            ok = np.isfinite(bm.mean)
            total += float(np.sum(bm.n_blocks[ok] * np.maximum(bm.mean[ok] ** 2
                                                               - bm.se[ok] ** 2, 0.0)))
        return total

    def _segments(self, vecs, scale=None) -> list:
        """Residual segments (what :func:`binned_means` takes) of the weighted residuals
        ``vecs`` (list over flights of {axis: (n,)}), each axis times ``scale[axis]``."""
        segs = []
        for g, f in zip(self.flights, vecs, strict=True):
            off = 0
            for i in g:
                r = self.residuals[i]
                n = r.t.size
                segs.append(SimpleNamespace(t=r.t, variables=r.variables, residual={
                    a: f[a][off:off + n] * (1.0 if scale is None else scale[a]) for a in f}))
                off += n
        return segs

    def structure_left(self, vecs) -> list[Finding]:
        """Significant binned structure of the weighted residuals ``vecs`` (list over
        flights of {axis: (n,)}) in bins of every variable of
        :data:`~gainsched.analysis.structure.STRUCTURE_BINS`
        (:func:`~gainsched.analysis.structure.findings`, in the axes' units): what a fit
        leaves that a right model would not."""
        noise = {a: 1.0 / w for a, w in self.weights.items()}
        return findings(self._segments(vecs, noise), noise, units=UNITS)[0]

    def base_structure_power(self) -> float | None:
        """:meth:`structure_power` of the base model's residual (computed once; its
        prediction is :meth:`_base_residuals`', not counted as a new evaluation)."""
        if self._p_before is None:
            base = self._base_residuals()
            vecs = [self._weighted(base, g) for g in self.flights]
            self._p_before = (self.structure_power(vecs),)
        return self._p_before[0]

    def measured(self, config: Config):
        """The flights measured with ``config``'s attachment point (the base's and one
        more kept: a fit moves one at a time)."""
        key, base_key = _geometry(config), _geometry(self.config)
        if key not in self._meas:
            for k in [x for x in self._meas if x != base_key]:
                del self._meas[k]
            base = self._meas[base_key]
            if key[0] == base_key[0]:  # the COG moved, the attachment offset the same
                p_e = np.array(key[1:])
                self._meas[key] = [m.with_attachment(p_e) for m in base]
            else:
                self._meas[key] = [measure(s, config, name=m.name)
                                   for s, m in zip(self.segs, base, strict=True)]
        return self._meas[key]

    def _base_residuals(self) -> list[dict]:
        """Unweighted residual axes of the base config per segment (computed once)."""
        if self._base is None:
            model = Model(self.config)
            self._base = [residual_axes(model, m, self.config.analysis.latency_s)
                          for m in self.measured(self.config)]
        return self._base

    def vectors(self, var: CandidateModel, only: int | None = None) -> list[dict]:
        """Weighted residual per flight and axis: list over flights of {axis: (n,)}
        (only flight ``only`` when given: a one-element list)."""
        meas = self.measured(var.config)
        model = Model(var.config)
        groups = self.flights if only is None else [self.flights[only]]
        self.n_evals += 1 if only is None else 1 / len(self.flights)
        base = None
        if (var.axes is not None and var.latency == self.config.analysis.latency_s
                and _geometry(var.config) == _geometry(self.config)):
            base = self._base_residuals()
        out = []
        for g in groups:
            if base is None:
                per_seg = {i: residual_axes(model, meas[i], var.latency) for i in g}
            else:
                per_seg = {i: {**base[i], **residual_axes(model, meas[i], var.latency,
                                                          var.axes)} for i in g}
            out.append(self._weighted(per_seg, g))
        return out

    def base_vectors(self) -> list[dict]:
        """:meth:`vectors` of the base config, from :meth:`_base_residuals` (the base
        model's prediction is computed once per diagnose, for both)."""
        self.n_evals += 1
        base = self._base_residuals()
        return [self._weighted(base, g) for g in self.flights]

    def _weighted(self, per_seg, g) -> dict:
        """One flight's residual per axis: its segments ``g`` concatenated and weighted."""
        return {a: np.concatenate([per_seg[i][a] for i in g]) * self.weights[a]
                for a in self.axes}


def _geometry(config: Config) -> tuple:
    """What the measured kinematics depend on of a config: its attachment offset (the
    reduced coordinates') and its attachment point from the COG (the COG's kinematics)."""
    return (float(config.tether.attachment_offset),
            *(float(v) for v in attachment_from_cog_config(config)))
