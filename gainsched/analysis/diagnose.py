"""Which physical effect is missing: fit candidates to the residual, score them on held-out flights.

For each candidate of :data:`CANDIDATES` (the effects library plus config
parameters and measurement latency) the model is refitted on the flight logs:
the parameters minimise the residual of :mod:`gainsched.analysis.compare`, every axis
weighted by its noise floor (so 1 per axis and sample is pure noise). Where
the residual is affine in a parameter (drag, rotor drag, thrust scale, thrust
polynomial, tether length, tether compliance) one linear least-squares step is
exact; mass and attachment offset take a few Gauss-Newton steps; motor time
constant, latency, momentum-theory disk area and the tether damping time are
found by a bounded 1-D search (grid, then :func:`scipy.optimize.minimize_scalar`).

Scores, all on **held-out flights** (leave-one-flight-out: refit without the
flight, predict it):

- ``rms_reduction``: ``1 - sqrt(SSE_fit / SSE_model)`` of the normalised residual;
- ``excess_explained``: the share of the residual power above the noise floor
  that the candidate removes, ``(SSE_model - SSE_fit) / (SSE_model - SSE_noise)``;
- ``delta_bic`` (in-sample, ``n_eff = samples x axes / window``: neighbouring
  samples share the differentiation window);
- plausibility (the estimate inside the parameter's plausible range, not
  pinned to its edge) and fold stability (how far the fold fits move the
  prediction, linearised at the estimate, relative to the effect itself).

A candidate is accepted when it clears every threshold of :data:`THRESHOLDS`, leaves
no significant binned structure (:mod:`gainsched.analysis.structure`: azimuth, airspeed,
thrust or flight time, every axis) in its held-out residual (a right model leaves noise;
a wrong one that correlates with the truth leaves what it cannot follow) and is
physically possible (:meth:`~gainsched.model.effects.Effect.implausible`); the first such
in the ranking (by held-out RMS reduction) is the verdict. When none is, forward
selection adds effects while they explain clearly more or remove the structure left
(:func:`_forward`).
**Identifiability gate**: two candidates whose fitted contributions to the
residual are nearly collinear (``|cos| >= 0.95``, i.e. VIF >= 10) and whose
held-out fits explain nearly as much (within 10 points of the residual power
above noise) cannot be told apart on these flights; the report says so and names the flight
that would separate them. Multi-parameter candidates report their parameter correlation.
**Beyond the library**: when no physical candidate passes while something is there
to explain (a residual above the noise floor, or significant binned structure of
:mod:`gainsched.analysis.structure` below it), the empirical candidates (effects
marked ``empirical``, e.g. the azimuth thrust series) are fitted too; a series'
order is chosen by leave-one-flight-out SSE with the one-standard-error rule
(:func:`_choose_order`). At the noise floor with significant structure, candidates
are judged by the share of that binned structure they remove on held-out flights
(``min_structure_explained``) instead of the RMS, excess and delta-BIC scores.
When nothing clears the thresholds the report says that no candidate explains
the residual and where the residual concentrates
(:func:`gainsched.analysis.compare.where_it_fails`).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np
from scipy.optimize import minimize_scalar

from ..config import Config, EffectSpec, Tether, config_from_text
from ..configedit import remove_key, set_section, set_value
from ..model.effects import EFFECTS, Effect, Param, Refit
from ..model.reduced import Model
from ..model.symmetry import table_refusal
from .compare import (
    AT_NOISE_FLOOR,
    UNITS,
    Comparison,
    compare,
    has_channel,
    measure,
    residual_axes,
)
from .structure import Finding, binned_means, findings

__all__ = [
    "FitParam",
    "Candidate",
    "CANDIDATES",
    "candidate_library",
    "THRESHOLDS",
    "CandidateResult",
    "Diagnosis",
    "diagnose",
    "apply_candidate",
    "separating_flight",
    "single_parameter_set_candidates",
    "select_candidates",
]

#: Acceptance thresholds (held-out where it says so).
THRESHOLDS = {
    "min_rms_reduction": 0.05,  # held-out RMS of the normalised residual falls by >= 5%
    "min_excess_explained": 0.5,  # and >= half of the residual power above the noise floor
    "max_delta_bic": -10.0,
    "max_fold_spread": 0.5,  # fold fits move the prediction by <= 50% of the effect itself
    "twin_cos": 0.95,  # |cos| of two fitted contributions: VIF >= 10
    "twin_excess_gap": 0.1,  # ... unless the held-out excess explained differs by > 10 points
    "max_param_corr": 0.95,  # within a candidate
    # a candidate that fits more parameters of the same effect than another passing one
    # (drag versus drag_quadratic) is preferred only when its delta-BIC is lower by this
    "nested_bic_gain": 10.0,
    # below the noise floor (no excess to explain) a candidate must instead remove this
    # share of the held-out binned structure (analysis.structure) that compare found
    "min_structure_explained": 0.5,
    # forward selection adds a candidate only when the fit together explains this much
    # more of the residual power above the noise floor (and lowers delta-BIC by
    # nested_bic_gain)
    "forward_excess_gain": 0.1,
    # ... or this share of the residual power above the noise floor that the current fit
    # leaves (near the end of a selection, when little is left to gain in absolute terms)
    "forward_left_share": 0.25,
}


@dataclass(frozen=True)
class FitParam:
    """A fitted parameter: name, unit, plausible fit bounds and search scale."""

    name: str
    unit: str
    lower: float
    upper: float
    scale: str = "lin"  # "lin" | "log" (search grids)

    @classmethod
    def from_param(cls, p: Param) -> FitParam:
        """The fit of an effect's :class:`~gainsched.model.effects.Param` (its fit range)."""
        return cls(p.name, p.unit, *p.fit_range, p.scale)


@dataclass(frozen=True)
class CandidateModel:
    """A candidate at given parameters: the config it makes (a model variant: ``text`` is
    the base's) and, when given, the only residual ``axes`` it can change (the others are
    the base model's, reused)."""

    config: Config
    axes: frozenset | None = None

    @property
    def latency(self) -> float:
        """The pose's lag behind the commands, s (``analysis.latency_s``)."""
        return self.config.analysis.latency_s


class Candidate:
    """A candidate missing effect. Subclasses define ``params``, ``search`` and the hooks."""

    name: str = ""
    doc: str = ""
    params: tuple[FitParam, ...] = ()
    search: int | None = None  # index of the parameter found by 1-D search
    affine: bool = True  # residual affine in the other parameters (one LSQ step is exact)
    grid_size: int = 13

    def start(self, cfg: Config) -> np.ndarray:
        """Current values in the config (the model as it is)."""
        raise NotImplementedError

    def variant(self, cfg: Config, theta) -> CandidateModel:
        raise NotImplementedError

    def apply_text(self, text: str, cfg: Config, theta, comments: list[str], header: str,
                   keep: frozenset = frozenset()) -> str:
        """``text`` with the candidate at ``theta`` (fit parametrisation); ``comments`` per
        parameter. ``keep``: names of parameters not identified by the fit, whose ``theta``
        is already the config's value; a candidate whose written keys derive from several
        parameters (the tether's damping from compliance and damping time) leaves the keys
        of those alone."""
        raise NotImplementedError

    def report_values(self, theta) -> dict:
        """Parameter values as written to the config (may differ from the fit parametrisation)."""
        return {p.name: float(v) for p, v in zip(self.params, theta, strict=True)}

    def present(self, cfg: Config) -> bool:
        return False


def _replaced(cfg: Config, section: str, key: str, value: float) -> Config:
    """``cfg`` with ``section.key`` set to ``value``: a model variant for a fit, made in
    place (``text`` stays the base's; a fit stays inside its bounds, so nothing to
    validate). Re-parsing the TOML per evaluation (:meth:`Config.with_values`) cost more
    than the evaluations themselves; written configs go through :func:`apply_candidate`."""
    return dataclasses.replace(cfg, **{section: dataclasses.replace(getattr(cfg, section),
                                                                    **{key: value})})


def _specs_with(cfg: Config, kind: str, values: dict) -> tuple:
    """Effects of ``cfg`` with effect ``kind`` set to ``values`` (added when absent)."""
    cls = EFFECTS[kind]
    old = next((s.param_dict() for s in cfg.effects if s.name == kind), {})
    full = {p.name: float(values.get(p.name, old.get(p.name, p.default))) for p in cls.params}
    specs = [s for s in cfg.effects if s.name != kind]
    specs.append(EffectSpec(kind, tuple(full.items())))
    specs.sort(key=lambda s: s.name)
    return tuple(specs)


class EffectCandidate(Candidate):
    """Refit (or add) parameters of one effect of the library, as its
    :class:`~gainsched.model.effects.Refit` says."""

    def __init__(self, kind: str, refit: Refit):
        cls = EFFECTS[kind]
        by_name = {p.name: p for p in cls.params}
        self.name, self.kind, self.doc = refit.name, kind, refit.doc
        self.params = tuple(FitParam.from_param(by_name[n]) for n in refit.params)
        self.search = None if refit.search is None else refit.params.index(refit.search)
        self.affine = refit.affine
        self.orders = refit.orders
        self.empirical = cls.empirical
        self.refit = refit

    def restricted(self, n: int) -> EffectCandidate:
        """The candidate fitting only the first ``n`` of its parameters (one of its
        ``orders``); the others keep their values."""
        r = self.refit
        doc = f"{r.doc}, first {n} of {len(r.params)} terms" if n < len(r.params) else r.doc
        return EffectCandidate(self.kind, Refit(r.name, r.params[:n], doc, r.search,
                                                r.affine, contains=r.contains))

    def present(self, cfg):
        return any(s.name == self.kind for s in cfg.effects)

    def start(self, cfg):
        cur = next((s.param_dict() for s in cfg.effects if s.name == self.kind), None)
        defaults = {p.name: p.default for p in EFFECTS[self.kind].params}
        return np.array([(defaults if cur is None else cur)[p.name] for p in self.params],
                        dtype=float)

    def variant(self, cfg, theta):
        vals = dict(zip((p.name for p in self.params), map(float, theta), strict=True))
        new = dataclasses.replace(cfg, effects=_specs_with(cfg, self.kind, vals))
        return CandidateModel(new)

    def apply_text(self, text, cfg, theta, comments, header, keep=frozenset()):
        vals = dict(zip((p.name for p in self.params), map(float, theta), strict=True))
        spec = next(s for s in _specs_with(cfg, self.kind, vals) if s.name == self.kind)
        spec = spec.param_dict()
        cmt = dict(zip((p.name for p in self.params), comments, strict=True))
        items = [(k, v, cmt.get(k, "kept")) for k, v in spec.items()]
        return set_section(text, f"effects.{self.kind}", items, header)


class ConfigCandidate(Candidate):
    """Refit one scalar config parameter (``section.key``)."""

    def __init__(self, name, section, key, param, doc, affine=True, bounds_rel=None):
        self.name, self.section, self.key, self.doc = name, section, key, doc
        self.params = (param,)
        self.affine = affine
        self.search = None
        self.bounds_rel = bounds_rel

    def _get(self, cfg):
        return float(getattr(getattr(cfg, self.section), self.key))

    def start(self, cfg):
        return np.array([self._get(cfg)])

    def variant(self, cfg, theta):
        new = _replaced(cfg, self.section, self.key, float(theta[0]))
        return CandidateModel(new)

    def apply_text(self, text, cfg, theta, comments, header, keep=frozenset()):
        return set_value(text, self.section, self.key, float(theta[0]),
                         f"{comments[0]}; {header}")


class LatencyCandidate(Candidate):
    """Measurement latency: the pose lags the logged commands (``analysis.latency_s``)."""

    name = "latency"
    doc = "measurement latency: the motion-capture pose lags the commands and load cell"
    params = (FitParam("latency_s", "s", 0.0, 0.06, "lin"),)
    search = 0
    grid_size = 13

    def start(self, cfg):
        return np.array([cfg.analysis.latency_s])

    def variant(self, cfg, theta):
        return CandidateModel(_replaced(cfg, "analysis", "latency_s", float(theta[0])))

    def apply_text(self, text, cfg, theta, comments, header, keep=frozenset()):
        return set_value(text, "analysis", "latency_s", float(theta[0]), f"{comments[0]}; {header}")


#: tether keys of the other elastic links (the SLS's and the chain's), refused elsewhere
_ELASTIC_LINK_KEYS = ("series_stiffness", "mass", "segments")


class ElasticityCandidate(Candidate):
    """Tether elasticity (Kelvin-Voigt spring-damper): fitted as compliance 1/k (affine)
    and damping time c/k (1-D search); written as ``[tether] link = "spring-damper"``."""

    name = "tether_elasticity"
    doc = "elastic tether (spring-damper): stretch = tension / k, lagged by c / k"
    params = (
        FitParam("compliance", "m/N", 0.0, 1e-2, "lin"),
        FitParam("damping_time", "s", 0.0, 0.05, "lin"),
    )
    search = 1
    grid_size = 11

    def present(self, cfg):
        return cfg.tether.link == "spring-damper"

    def start(self, cfg):
        t = cfg.tether
        if t.link == "rigid":
            return np.array([0.0, 0.0])
        return np.array([1.0 / t.stiffness, t.damping / t.stiffness])

    def variant(self, cfg, theta):
        # a model variant only, never written: the tether replaced in place (its text
        # stays the base config's), because re-parsing the TOML for each of the ~100
        # evaluations of a fit cost more than the fit itself (60 % of diagnose)
        comp, tc = float(theta[0]), float(theta[1])
        if comp <= 1e-12:
            tether = dataclasses.replace(cfg.tether, link="rigid")
        else:
            k = 1.0 / comp
            tether = dataclasses.replace(cfg.tether, link="spring-damper", stiffness=k,
                                         damping=tc * k)
        return CandidateModel(dataclasses.replace(cfg, tether=tether), frozenset({"stretch"}))

    def report_values(self, theta):
        comp, tc = float(theta[0]), float(theta[1])
        k = 1.0 / comp if comp > 0 else math.inf
        return {"stiffness": k, "damping": tc * k if comp > 0 else 0.0}

    def apply_text(self, text, cfg, theta, comments, header, keep=frozenset()):
        v = self.report_values(theta)
        for key in _ELASTIC_LINK_KEYS:
            text = remove_key(text, "tether", key)
        text = set_value(text, "tether", "link", "spring-damper", header)
        text = set_value(text, "tether", "stiffness", v["stiffness"], f"N/m; {comments[0]}")
        if "damping_time" not in keep:
            return set_value(text, "tether", "damping", v["damping"], f"N s/m; {comments[1]}")
        # an unidentified damping is not written: the config's own value stays, or (from a
        # rigid link) the key is left out and the link's default applies
        if cfg.tether.link == "spring-damper":
            return set_value(text, "tether", "damping", cfg.tether.damping,
                             f"N s/m; {comments[1]}")
        text = remove_key(text, "tether", "damping")
        return set_value(text, "tether", "stiffness", v["stiffness"],
                         f"N/m; {comments[0]}; damping: not identified on these flights, so "
                         f"not written (the link's default {Tether.damping:g} N s/m applies)")


class JointCandidate(Candidate):
    """Two or three candidates fitted together, for when no single one explains the
    residual: the parameters of all, started at their single fits and refined by
    Gauss-Newton steps (a searched parameter too, from its single estimate). The model is
    the config with each part's edit applied in turn (:meth:`Candidate.apply_text`), so the
    parts must edit different keys (different effects or config parameters)."""

    affine = False

    def __init__(self, parts, starts, bounds):
        self.parts = tuple(parts)
        self.name = " + ".join(p.name for p in self.parts)
        self.doc = "; ".join(p.doc for p in self.parts)
        self.params = tuple(q for p in self.parts for q in p.params)
        self.search = None
        self._start = np.concatenate(starts)
        self.bounds = (np.concatenate([b[0] for b in bounds]),
                       np.concatenate([b[1] for b in bounds]))
        self._cut = np.cumsum([len(p.params) for p in self.parts])[:-1]

    def present(self, cfg):
        return any(p.present(cfg) for p in self.parts)

    def start(self, cfg):
        return self._start.copy()

    def _split(self, values):
        return np.split(np.asarray(values, dtype=float), self._cut)

    def apply_text(self, text, cfg, theta, comments, header, keep=frozenset()):
        for p, th, cm in zip(self.parts, self._split(theta),
                             np.split(np.asarray(comments, dtype=object), self._cut),
                             strict=True):
            mine = frozenset(q.name for q in p.params) & keep
            text = p.apply_text(text, cfg, th, list(cm), header, keep=mine)
        return text

    def variant(self, cfg, theta):
        # the parts' variants in turn (each changes the config it is given); the text is
        # the base's: apply_text writes the same edits into the TOML
        new = cfg
        for p, th in zip(self.parts, self._split(theta), strict=True):
            new = p.variant(new, th).config
        return CandidateModel(new)

    def report_values(self, theta):
        out = {}
        for p, th in zip(self.parts, self._split(theta), strict=True):
            out.update(p.report_values(th))
        return out


#: single candidates whose best are combined into joint fits when none passes
JOINT_TOP = 4
#: candidates never fitted in the pairs of :func:`_fit_joint` (their single fit switches
#: the link model); forward selection (:func:`_forward`) adds them
_NOT_JOINT = frozenset({"tether_elasticity"})
#: the most candidates forward selection fits together
FORWARD_PARTS = 4


def candidate_library() -> dict[str, Candidate]:
    """The candidate library, by name: every :meth:`~gainsched.model.effects.Effect.refits`
    of every effect nameable in configs (built-in or registered with
    :func:`~gainsched.model.effects.registered_effect`), then config parameters, the
    measurement latency and the tether elasticity."""
    P = FitParam
    out: list[Candidate] = [EffectCandidate(kind, r)
                            for kind, cls in EFFECTS.items() for r in cls.refits()]
    out += [
        ConfigCandidate("mass", "vehicle", "mass", P("mass", "kg", 0.0, 0.0),
                        "mass error", affine=False, bounds_rel=(0.5, 1.5)),
        LatencyCandidate(),
        ElasticityCandidate(),
        ConfigCandidate("attachment_offset", "tether", "attachment_offset",
                        P("attachment_offset", "m", 0.0, 0.0),
                        "attachment offset L_e error", affine=False, bounds_rel=(0.0, 3.0)),
        ConfigCandidate("tether_length", "tether", "length", P("length", "m", 0.0, 0.0),
                        "tether length error", affine=True, bounds_rel=(0.8, 1.2)),
    ]
    by_name: dict[str, Candidate] = {}
    for c in out:
        if c.name in by_name:
            raise ValueError(f"two diagnose candidates are named {c.name!r}")
        by_name[c.name] = c
    return by_name


def single_parameter_set_candidates(library=None) -> list[str]:
    """The physical candidates without the refits that fit a superset of another
    candidate's parameters of the same effect (``drag`` beside ``drag_linear`` and
    ``drag_quadratic``) and without the empirical ones: the library as it was before
    issue 16 (the benchmark's baseline)."""
    library = candidate_library() if library is None else library

    def nested(c):
        kind, ps = getattr(c, "kind", None), {p.name for p in c.params}
        return kind is not None and any(
            getattr(o, "kind", None) == kind and {p.name for p in o.params} < ps
            for o in library.values())

    return [n for n, c in library.items()
            if not nested(c) and not getattr(c, "empirical", False)]


#: The candidate library of the built-in effects, by name (:func:`candidate_library`).
CANDIDATES: dict[str, Candidate] = candidate_library()

_TILTED_CONSTANT_SPEED = (
    "tilted circles at constant speed: the thrust changes around the circle while the "
    "airspeed does not (rotor drag scales with thrust)"
)
_SLOW_AND_FAST_CIRCLE = (
    "a slow (3 m/s) and a fast (12+ m/s) circle at the same tilt: a scale error does not "
    "change with airspeed"
)

#: What separates two candidates that look alike on the flights at hand.
_SEPARATE = {
    frozenset({"drag_linear", "drag_quadratic"}):
        "steady circles over the whole speed range (3 to 15 m/s): linear and quadratic drag "
        "part at the ends",
    frozenset({"rotor_drag", "drag_linear"}):
        _TILTED_CONSTANT_SPEED,
    frozenset({"rotor_drag", "drag_quadratic"}):
        _TILTED_CONSTANT_SPEED,
    frozenset({"thrust_scale", "mass"}):
        "speed-ups and braking (the mass multiplies the tangential acceleration, a thrust "
        "scale does not), or log the tether load cell",
    frozenset({"thrust_airspeed", "thrust_momentum"}):
        "steady circles at more speeds including 12-15 m/s and tilts, where the polynomial "
        "and the momentum-theory curves part",
    frozenset({"thrust_scale", "thrust_airspeed"}):
        _SLOW_AND_FAST_CIRCLE,
    frozenset({"thrust_scale", "thrust_momentum"}):
        _SLOW_AND_FAST_CIRCLE,
    frozenset({"motor_lag", "latency"}):
        "manoeuvres with sharp thrust changes (hard braking, speed-ups with a high jerk): a lag "
        "filters the command, a delay only shifts it",
    frozenset({"tether_length", "attachment_offset"}):
        "measure the tether length on the ground, or fly high-tension circles with pitch and "
        "yaw excitation (the offset sets the tether's restoring torque)",
    frozenset({"tether_elasticity", "tether_length"}):
        "a speed staircase: an elastic tether stretches with the tension, a length error does not",
    frozenset({"tether_elasticity", "attachment_offset"}):
        "a speed staircase: an elastic tether stretches with the tension, an offset error does not",
    frozenset({"mass", "drag_linear"}):
        "speed-ups and braking at several speeds: the mass acts on the acceleration, drag on "
        "the speed",
}


def separating_flight(a: str, b: str) -> str:
    """The flight (or measurement) that tells candidates ``a`` and ``b`` apart."""
    return _SEPARATE.get(
        frozenset({a, b}),
        "flights over a wider range of speed, tilt and acceleration, where the two "
        "predictions differ",
    )


# --------------------------------------------------------------------------- the problem


class _Problem:
    """The logs, the base config, the weights; evaluates variants on every flight."""

    def __init__(self, config: Config, measured, segs, noise: dict, residuals):
        self.config = config
        self.residuals = residuals  # the base comparison's, for their binning variables
        self.segs = segs
        self._meas = {config.tether.attachment_offset: measured}
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
        self.structure_keys: list[tuple[str, str]] = []
        self._base: list[dict] | None = None
        self._p_before: tuple | None = None

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

    def measured(self, L_e: float):
        base_L = self.config.tether.attachment_offset
        if L_e not in self._meas:
            for key in [x for x in self._meas if x != base_L]:  # keep the base and one more
                del self._meas[key]
            cfg = self.config.with_values({"tether.attachment_offset": L_e})
            base = self._meas[self.config.tether.attachment_offset]
            self._meas[L_e] = [measure(s, cfg, name=m.name)
                               for s, m in zip(self.segs, base, strict=True)]
        return self._meas[L_e]

    def _base_residuals(self) -> list[dict]:
        """Unweighted residual axes of the base config per segment (computed once)."""
        if self._base is None:
            model = Model(self.config)
            self._base = [residual_axes(model, m, self.config.analysis.latency_s)
                          for m in self.measured(self.config.tether.attachment_offset)]
        return self._base

    def vectors(self, var: CandidateModel, only: int | None = None) -> list[dict]:
        """Weighted residual per flight and axis: list over flights of {axis: (n,)}
        (only flight ``only`` when given: a one-element list)."""
        meas = self.measured(var.config.tether.attachment_offset)
        model = Model(var.config)
        groups = self.flights if only is None else [self.flights[only]]
        self.n_evals += 1 if only is None else 1 / len(self.flights)
        base = None
        if (var.axes is not None and var.latency == self.config.analysis.latency_s
                and var.config.tether.attachment_offset == self.config.tether.attachment_offset):
            base = self._base_residuals()
        out = []
        for g in groups:
            if base is None:
                per_seg = {i: residual_axes(model, meas[i], var.latency) for i in g}
            else:
                per_seg = {i: {**base[i], **residual_axes(model, meas[i], var.latency, var.axes)}
                           for i in g}
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


def _sq(vecs) -> np.ndarray:
    """Sum of squares per flight and axis, shape (n_flights, n_axes)."""
    return np.array([[float(np.sum(v * v)) for v in f.values()] for f in vecs])


def _qp(A, b, lo, hi):
    """argmin of d^T A d + 2 b^T d over lo <= d <= hi: exact active sets for k <= 3
    parameters, bounded least squares (BVLS) on the Cholesky factor for more."""
    k = b.size
    if k > 3:
        return _qp_bvls(A, b, lo, hi)
    best, best_val = None, math.inf
    Ar = A + 1e-12 * np.trace(A) / max(k, 1) * np.eye(k) + 1e-300 * np.eye(k)
    for pattern in itertools.product((0, 1, 2), repeat=k):  # free / at lo / at hi
        d = np.where(np.array(pattern) == 1, lo, np.where(np.array(pattern) == 2, hi, 0.0))
        free = np.array(pattern) == 0
        if free.any():
            rhs = -(b[free] + A[np.ix_(free, ~free)] @ d[~free])
            try:
                d[free] = np.linalg.solve(Ar[np.ix_(free, free)], rhs)
            except np.linalg.LinAlgError:
                continue
        if np.any(d < lo - 1e-15 * (1 + abs(lo))) or np.any(d > hi + 1e-15 * (1 + abs(hi))):
            continue
        val = float(d @ A @ d + 2 * b @ d)
        if val < best_val:
            best, best_val = d, val
    return (np.zeros(k) if best is None else best), (0.0 if best is None else best_val)


def _qp_bvls(A, b, lo, hi):
    """:func:`_qp` for many parameters: ``d^T A d + 2 b^T d = |L^T d + L^-1 b|^2 -
    |L^-1 b|^2`` with ``A = L L^T``, minimised by scipy's bounded-variable least squares."""
    from scipy.linalg import cho_factor, solve_triangular
    from scipy.optimize import lsq_linear

    k = b.size
    Ar = A + (1e-12 * np.trace(A) / k + 1e-300) * np.eye(k)
    L = cho_factor(Ar, lower=True)[0]
    L = np.tril(L)
    y = solve_triangular(L, -b, lower=True)
    sol = lsq_linear(L.T, y, bounds=(lo, hi), method="bvls")
    d = np.clip(sol.x, lo, hi)
    return d, float(d @ A @ d + 2 * b @ d)


# --------------------------------------------------------------------------- results


@dataclass(frozen=True)
class CandidateResult:
    """Fit and scores of one candidate (see the module docstring).

    ``theta``/``ci``: fitted parameters and their 95% confidence half-widths (fit
    parametrisation, :attr:`Candidate.params`); ``folds``: (n_flights, k) leave-one-out
    estimates; ``values``: parameters as written to the config; ``axis_rms``: per axis
    held-out RMS (normalised) before and after; ``corr``: parameter correlation matrix.
    """

    name: str
    doc: str
    params: tuple
    theta: np.ndarray
    ci: np.ndarray
    folds: np.ndarray
    start: np.ndarray
    values: dict
    rms_reduction: float
    excess_explained: float
    delta_bic: float
    plausible: bool
    fold_spread: float
    stable: bool
    corr: np.ndarray
    heldout_sse: float
    n_eff: float
    axis_rms_before: dict
    axis_rms_after: dict
    in_sample_reduction: float
    notes: tuple = ()
    contribution: np.ndarray | None = field(default=None, repr=False)
    structure_reduction: float | None = None
    empirical: bool = False
    law: str = ""
    candidate: Candidate | None = field(default=None, repr=False)
    structure_left: tuple = ()
    implausible: tuple = ()

    def __repr__(self) -> str:
        """One line: the candidate, its parameters and its scores."""
        vals = ", ".join(f"{k}={v:.4g}" for k, v in list(self.values.items())[:6])
        more = ", ..." if len(self.values) > 6 else ""
        return (f"CandidateResult({self.name!r}, {vals}{more}, held-out RMS "
                f"{-self.rms_reduction:+.0%}, excess {self.excess_explained:.0%}, "
                f"passes={self.passes})")

    @property
    def below_noise(self) -> bool:
        """Judged on the binned structure: every axis at its noise floor, but significant
        binned structure to remove (``structure_reduction`` is set only then)."""
        return self.structure_reduction is not None

    @property
    def passes(self) -> bool:
        return not self.failed()

    def failed(self) -> list[str]:
        """Which thresholds the candidate misses, in words (empty: it passes)."""
        t = THRESHOLDS
        out = []
        if self.below_noise:
            # at the noise floor the in-sample delta-BIC (with its conservative n_eff)
            # cannot see a sector-locked effect: the held-out binned structure judges, and
            # the held-out residual must fall
            if not self.structure_reduction >= t["min_structure_explained"]:
                out.append(f"removes {self.structure_reduction:.0%} of the held-out binned "
                           f"structure (< {t['min_structure_explained']:.0%})")
            if not self.rms_reduction > 0:
                out.append(f"held-out RMS changes by {-self.rms_reduction:+.1%}")
        else:
            if not self.rms_reduction >= t["min_rms_reduction"]:
                out.append(f"held-out RMS reduction {self.rms_reduction:.1%} < "
                           f"{t['min_rms_reduction']:.0%}")
            if not (np.isfinite(self.excess_explained)
                    and self.excess_explained >= t["min_excess_explained"]):
                out.append(f"explains {self.excess_explained:.0%} of the residual above noise "
                           f"(< {t['min_excess_explained']:.0%})")
        if not self.below_noise and not self.delta_bic <= t["max_delta_bic"]:
            out.append(f"delta-BIC {self.delta_bic:.1f} > {t['max_delta_bic']:g}")
        if self.structure_left and not self.below_noise:
            out.append(f"leaves structure a right model would remove: {self.structure_left[0]}")
        if not self.plausible:
            out.append("estimate implausible (at the edge of its range)")
        out += [f"implausible: {why}" for why in self.implausible]
        if not self.stable:
            out.append(f"unstable across folds (spread {self.fold_spread:.2f})")
        return out

    def to_json(self) -> dict:
        ps = [p.name for p in self.params]
        return {
            "doc": self.doc,
            "params": {n: {"estimate": float(v), "ci95": float(c), "unit": p.unit,
                           "folds": self.folds[:, j].tolist(), "start": float(s),
                           "bounds": [p.lower, p.upper]}
                       for j, (n, v, c, p, s) in enumerate(
                           zip(ps, self.theta, self.ci, self.params, self.start, strict=True))},
            "values": self.values,
            "heldout_rms_reduction": self.rms_reduction,
            "heldout_excess_explained": _num(self.excess_explained),
            "delta_bic": self.delta_bic,
            "plausible": self.plausible,
            "fold_spread": _num(self.fold_spread),
            "stable": self.stable,
            "param_corr": self.corr.tolist(),
            "heldout_axis_rms_normalised": {"before": self.axis_rms_before,
                                            "after": self.axis_rms_after},
            "in_sample_rms_reduction": self.in_sample_reduction,
            "heldout_structure_reduction": _num(self.structure_reduction),
            "empirical": self.empirical,
            "law": self.law,
            "structure_left": list(self.structure_left),
            "implausible": list(self.implausible),
            "passes": self.passes,
            "failed": self.failed(),
            "notes": list(self.notes),
        }


def _num(x):
    return float(x) if x is not None and np.isfinite(x) else None


@dataclass(frozen=True, eq=False)
class Diagnosis:
    """Which effect is missing: the ranked candidates, the verdict and the twins.

    What :func:`diagnose` returns; ``d.to_json()`` is the report's JSON.

    Attributes
    ----------
    config : Config
        The model that was diagnosed.
    base : Comparison
        Its comparison with the logs: the residual the candidates were fitted to.
    results : list of CandidateResult
        Every fitted candidate (joint fits ``"a + b"`` included when they ran), ranked by
        held-out RMS reduction, then delta-BIC: the parameters with their 95 % CIs
        (``theta``, ``ci``; ``values`` as written to the config), the held-out scores
        (``rms_reduction``, ``excess_explained``), ``delta_bic``, ``passes`` and
        ``failed()`` (the thresholds missed, in words)
        (:class:`~gainsched.analysis.diagnose.CandidateResult`).
    accepted : CandidateResult or None
        The verdict's candidate: the best-ranked one clearing every threshold of
        :data:`THRESHOLDS` (a nested fit of the same effect preferred unless the larger
        lowers delta-BIC clearly); None when none does. :func:`apply_candidate` writes
        it into the config.
    twins : list of (str, float, str)
        Candidates that cannot be told apart from the accepted one on these flights:
        ``(name, |cos| of their fitted contributions to the residual, the flight that
        would separate them)``.
    verdict : str
        The conclusion in one paragraph (what ``gainsched diagnose`` prints).
    at_noise_floor : bool
        Every residual axis of ``base`` was within ``AT_NOISE_FLOOR`` (1.25) times its
        noise floor: candidates were then judged on the binned structure they remove.
    flights : list of str
        The flights (one per log file), the folds of the leave-one-flight-out scores.
    evaluations : int
        How many times the model was evaluated on all flights (the cost of the fits).
    similarity : dict of str to float
        ``|cos|`` of each other candidate's fitted contribution to the accepted one's
        (empty without an accepted candidate).
    """

    config: Config
    base: Comparison
    results: list  # ranked CandidateResult
    accepted: CandidateResult | None
    twins: list  # (name, |cos|, separating flight)
    verdict: str
    at_noise_floor: bool
    flights: list
    evaluations: int
    similarity: dict = field(default_factory=dict)  # |cos| of each fit to the accepted one

    def __repr__(self) -> str:
        """One line: the config, the flights, the candidates fitted and the verdict's start."""
        v = self.verdict if len(self.verdict) <= 100 else self.verdict[:97] + "..."
        return (f"Diagnosis({self.config.name!r}, {len(self.flights)} flights, "
                f"{len(self.results)} fits, accepted="
                f"{None if self.accepted is None else self.accepted.name!r}, verdict={v!r})")

    def to_json(self) -> dict:
        return {
            "config": self.config.source,
            "flights": self.flights,
            "verdict": self.verdict,
            "accepted": self.accepted.name if self.accepted else None,
            "twins": [{"candidate": n, "abs_cos": c, "separating_flight": s}
                      for n, c, s in self.twins],
            "at_noise_floor": self.at_noise_floor,
            "thresholds": THRESHOLDS,
            "ranking": [r.name for r in self.results],
            "candidates": {r.name: r.to_json() for r in self.results},
            "base_where_it_fails": self.base.where["sentence"],
            "model_evaluations": self.evaluations,
            "abs_cos_to_accepted": self.similarity,
        }


# --------------------------------------------------------------------------- fitting


def _bounds(cand: Candidate, cfg: Config, start):
    if getattr(cand, "bounds", None) is not None:
        return cand.bounds
    lo = np.array([p.lower for p in cand.params], float)
    hi = np.array([p.upper for p in cand.params], float)
    rel = getattr(cand, "bounds_rel", None)
    if rel is not None:
        lo, hi = np.array([rel[0] * start[0]]), np.array([rel[1] * start[0]])
        if hi[0] <= lo[0]:  # zero start (e.g. no attachment offset)
            lo, hi = np.array([0.0]), np.array([0.5])
    return lo, hi


def _jacobian(prob: _Problem, cand: Candidate, theta, base_vecs, cols, lo, hi):
    """Forward-difference columns of the weighted residual for parameters ``cols``."""
    out = []
    for j in cols:
        h = 1e-3 * (hi[j] - lo[j]) if cand.affine else 1e-4 * max(abs(theta[j]), hi[j] - lo[j])
        sgn = 1.0 if theta[j] + h <= hi[j] else -1.0
        th = theta.copy()
        th[j] += sgn * h
        v = prob.vectors(cand.variant(prob.config, th))
        out.append([{a: (f1[a] - f0[a]) / (sgn * h) for a in f0}
                    for f0, f1 in zip(base_vecs, v, strict=True)])
    return out  # [col][flight][axis]


def _stats(vecs, jac):
    """Per flight and axis: (A (k,k), b (k,), c) of ||r + J d||^2."""
    nf, na = len(vecs), len(vecs[0])
    k = len(jac)
    A = np.zeros((nf, na, k, k))
    b = np.zeros((nf, na, k))
    c = np.zeros((nf, na))
    for i, f in enumerate(vecs):
        for a_i, a in enumerate(f):
            r = f[a]
            c[i, a_i] = float(np.sum(r * r))
            for j in range(k):
                Jj = jac[j][i][a]
                b[i, a_i, j] = float(np.sum(Jj * r))
                for l in range(j, k):
                    A[i, a_i, j, l] = A[i, a_i, l, j] = float(np.sum(Jj * jac[l][i][a]))
    return A, b, c


def _profile(prob, cand, theta_search, lin, lo, hi, start):
    """Linear parameters solved at a fixed search value: (theta, vecs at theta, stats)."""
    th = start.copy()
    th[cand.search] = theta_search
    vecs = prob.vectors(cand.variant(prob.config, th))
    if not lin:
        return th, vecs, None
    jac = _jacobian(prob, cand, th, vecs, lin, lo, hi)
    A, b, c = _stats(vecs, jac)
    d, _ = _qp(A.sum((0, 1)), b.sum((0, 1)), lo[lin] - th[lin], hi[lin] - th[lin])
    th2 = th.copy()
    th2[lin] += d
    return th2, None, (A, b, c, d, vecs, jac)


def _grid(prob, cand, values, lin, lo, hi, start, nf, na, k):
    """Per search value: training SSE with each flight left out (G, nf), held-out SSE per
    axis (G, nf, na), fold parameters (G, nf, k) and the all-data SSE (G,)."""
    G = len(values)
    sse_tr = np.zeros((G, nf))
    held_g = np.zeros((G, nf, na))
    th_g = np.zeros((G, nf, k))
    sse_all = np.zeros(G)
    for gi, sv in enumerate(values):
        th, vecs, st = _profile(prob, cand, float(sv), lin, lo, hi, start)
        if st is None:
            sq = _sq(vecs)
            sse_all[gi] = sq.sum()
            for i in range(nf):
                sse_tr[gi, i] = sq.sum() - sq[i].sum()
                held_g[gi, i] = sq[i]
                th_g[gi, i] = th
            continue
        A, b, c, d_all, _, _ = st
        sse_all[gi] = float(c.sum() + 2 * b.sum((0, 1)) @ d_all + d_all @ A.sum((0, 1)) @ d_all)
        base_th = th.copy()
        base_th[lin] -= d_all
        for i in range(nf):
            m_ = np.arange(nf) != i
            d, val = _qp(A[m_].sum((0, 1)), b[m_].sum((0, 1)),
                         lo[lin] - base_th[lin], hi[lin] - base_th[lin])
            sse_tr[gi, i] = c[m_].sum() + val
            held_g[gi, i] = c[i] + 2 * b[i] @ d + np.einsum("j,ajk,k->a", d, A[i], d)
            th_g[gi, i] = base_th
            th_g[gi, i, lin] += d
    return sse_tr, held_g, th_g, sse_all


def _choose_order(prob: _Problem, cand: Candidate):
    """The order of a series candidate (its ``orders``: nested fits of the first n
    parameters): the lowest whose held-out SSE (leave-one-flight-out) is within one
    standard error of the best order's, the one-standard-error rule of cross-validation
    (Hastie, Tibshirani and Friedman, The Elements of Statistical Learning, 2nd ed.,
    Springer 2009, Sec. 7.10), with the standard error from the flight-to-flight spread
    of the SSE differences. One Jacobian of the full series (the residual is affine in
    it); each order's folds from its blocks.

    Returns the restricted candidate and its start ``(vecs, jac)`` for
    :func:`_fit_candidate`.
    """
    cfg = prob.config
    start = cand.start(cfg)
    lo, hi = _bounds(cand, cfg, start)
    start = np.clip(start, lo, hi)
    vecs = prob.vectors(cand.variant(cfg, start))
    jac = _jacobian(prob, cand, start, vecs, list(range(len(cand.params))), lo, hi)
    A, b, c = _stats(vecs, jac)
    A, b, c = A.sum(1), b.sum(1), c.sum(1)  # per flight
    nf = c.size
    held = np.zeros((len(cand.orders), nf))  # per order and held-out flight
    for o, n in enumerate(cand.orders):
        for i in range(nf):
            m = np.arange(nf) != i
            d, _ = _qp(A[m].sum(0)[:n, :n], b[m].sum(0)[:n], (lo - start)[:n],
                       (hi - start)[:n])
            held[o, i] = c[i] + 2 * b[i, :n] @ d + d @ A[i, :n, :n] @ d
    n = cand.orders[_one_se_order(held)]
    return cand.restricted(n), (vecs, jac[:n])


def _one_se_order(held) -> int:
    """Index of the lowest order whose held-out SSE is within one standard error of the
    best order's; ``held``: (n_orders, n_flights) held-out SSE per order and flight, the
    standard error of a sum of differences from their flight-to-flight spread."""
    held = np.asarray(held, dtype=float)
    best = int(np.argmin(held.sum(1)))
    nf = held.shape[1]
    for o in range(best):
        diff = held[o] - held[best]
        se = float(np.std(diff, ddof=1)) * math.sqrt(nf) if nf > 1 else 0.0
        if diff.sum() <= se:
            return o
    return best


def _fit_candidate(prob: _Problem, cand: Candidate, base_sq, base_vecs,
                   pre=None) -> CandidateResult:
    """Fit ``cand`` and score it (module docstring). ``pre``: ``(vecs, jac)`` at the
    start values for an affine candidate without search (:func:`_choose_order`)."""
    cfg = prob.config
    start = cand.start(cfg)
    lo, hi = _bounds(cand, cfg, start)
    start = np.clip(start, lo, hi)
    k = len(cand.params)
    nf, na = base_sq.shape
    lin = [j for j in range(k) if j != cand.search]
    notes = []
    if cand.search is None:
        theta = start.copy()
        vecs = pre[0] if pre else prob.vectors(cand.variant(cfg, theta))
        for it in range(1 if cand.affine else 4):
            jac = pre[1] if pre and it == 0 else _jacobian(prob, cand, theta, vecs, lin, lo, hi)
            A, b, c = _stats(vecs, jac)
            d, _ = _qp(A.sum((0, 1)), b.sum((0, 1)), lo - theta, hi - theta)
            theta = theta + d
            vecs = prob.vectors(cand.variant(cfg, theta))
            if np.all(np.abs(d) <= 1e-6 * (hi - lo)):
                break
        if not cand.affine:
            jac = _jacobian(prob, cand, theta, vecs, lin, lo, hi)
        A, b, c = _stats(vecs, jac)
        Atot = A.sum((0, 1))
        folds = np.zeros((nf, k))
        held = np.zeros((nf, na))
        spread = 0.0
        eff = np.concatenate([np.concatenate([bv[a] - v[a] for a in bv])
                              for bv, v in zip(base_vecs, vecs, strict=True)])
        eff_norm = float(np.sqrt(np.sum(eff * eff)))
        held_vecs = []
        for i in range(nf):
            Ai = A.sum(1)[np.arange(nf) != i].sum(0)
            bi = b.sum(1)[np.arange(nf) != i].sum(0)
            d, _ = _qp(Ai, bi, lo - theta, hi - theta)
            folds[i] = theta + d
            held[i] = c[i] + 2 * b[i] @ d + np.einsum("j,ajk,k->a", d, A[i], d)
            held_vecs.append({a: v + sum(d[j] * jac[j][i][a] for j in range(k))
                              for a, v in vecs[i].items()})
            dd = math.sqrt(max(float(d @ Atot @ d), 0.0))
            spread = max(spread, dd / eff_norm if eff_norm > 0 else math.inf)
        J_all = jac
        fit_sq = c
    else:
        s = cand.search
        p = cand.params[s]
        g = (np.geomspace(p.lower, p.upper, cand.grid_size) if p.scale == "log"
             else np.linspace(p.lower, p.upper, cand.grid_size))
        sse_tr, held_g, th_g, sse_all = _grid(prob, cand, g, lin, lo, hi, start, nf, na, k)
        # all data: refine the search value between the grid neighbours of the best point
        G = g.size
        gbest = int(np.argmin(sse_all))
        a_, b_ = g[max(gbest - 1, 0)], g[min(gbest + 1, G - 1)]

        def f(sv):
            th, vecs, st = _profile(prob, cand, sv, lin, lo, hi, start)
            if st is None:
                return float(_sq(vecs).sum())
            A, b, c, d, *_ = st
            return float(c.sum() + 2 * b.sum((0, 1)) @ d + d @ A.sum((0, 1)) @ d)

        if a_ < b_:
            tol = 1e-3 * max(g[gbest], (b_ - a_) * 0.01)
            opt = minimize_scalar(f, bounds=(a_, b_), method="bounded", options={"xatol": tol})
            sbest = float(opt.x) if opt.fun <= sse_all[gbest] else float(g[gbest])
        else:
            sbest = float(g[gbest])
        theta, vecs, st = _profile(prob, cand, sbest, lin, lo, hi, start)
        if st is not None:
            vecs = prob.vectors(cand.variant(cfg, theta))
        fit_sq = _sq(vecs)
        # folds: each fold's search value from a parabola through its training SSE on a
        # fine local grid around the all-data estimate (or, when its optimum lies outside,
        # on the coarse grid), linear parameters from the nearest grid point; then the
        # held-out flight evaluated exactly there
        to_u = (np.log if p.scale == "log" else (lambda x: np.asarray(x, float)))
        from_u = (np.exp if p.scale == "log" else (lambda x: x))
        h = 0.05 if p.scale == "log" else 0.02 * (p.upper - p.lower)
        u0 = float(to_u(sbest))
        ul = np.clip(u0 + h * np.arange(-2, 3), to_u(p.lower), to_u(p.upper))
        ul = np.unique(ul)
        loc = _grid(prob, cand, from_u(ul), lin, lo, hi, start, nf, na, k) if ul.size >= 3 else None
        u = to_u(g)
        folds = np.zeros((nf, k))
        held = np.zeros((nf, na))
        held_vecs = []
        for i in range(nf):
            uo = None
            if loc is not None:
                y = loc[0][:, i]
                cc = np.polyfit(ul - u0, y, 2)
                if cc[0] > 0:
                    cand_u = u0 - cc[1] / (2 * cc[0])
                    if ul[0] <= cand_u <= ul[-1]:
                        uo = float(cand_u)
                        j = int(np.argmin(np.abs(ul - uo)))
                        folds[i] = loc[2][j, i]
            if uo is None:
                j = int(np.argmin(sse_tr[:, i]))
                jl, jr = max(j - 1, 0), min(j + 1, G - 1)
                folds[i] = th_g[j, i]
                uo = float(u[j])
                if jr - jl == 2:
                    x3, y3 = u[jl : jr + 1], sse_tr[jl : jr + 1, i]
                    cc = np.polyfit(x3 - x3[1], y3, 2)
                    if cc[0] > 0:
                        uo = float(np.clip(x3[1] - cc[1] / (2 * cc[0]), x3[0], x3[2]))
            folds[i, s] = float(from_u(uo))
            held_vecs += prob.vectors(cand.variant(cfg, folds[i]), only=i)
            held[i] = _sq(held_vecs[-1:])[0]
        J_all = None
        spread = None  # below, from the Jacobian at the estimate
    # confidence intervals from the Jacobian at the estimate (all parameters)
    if J_all is None or len(J_all) != k:
        J_all = _jacobian(prob, cand, theta, vecs, list(range(k)), lo, hi)
    Aci, _, cci = _stats(vecs, J_all)
    Atot = Aci.sum((0, 1))
    if spread is None:
        # how far the fold estimates move the prediction (linearised at the estimate),
        # relative to the effect itself: robust to a poorly determined second parameter
        eff = np.concatenate([np.concatenate([bv[a] - v[a] for a in bv])
                              for bv, v in zip(base_vecs, vecs, strict=True)])
        eff_norm = float(np.sqrt(np.sum(eff * eff)))
        moves = [math.sqrt(max(float(d @ Atot @ d), 0.0)) for d in folds - theta]
        spread = (max(moves) / eff_norm if eff_norm > 0 else math.inf) if nf > 1 else 0.0
    n_total = sum(v.size for f_ in vecs for v in f_.values())
    sse_fit = float(fit_sq.sum())
    s2 = sse_fit / max(n_total - k, 1)
    # a parameter the residual does not see at all (a zero Jacobian column: a joint
    # fit's unidentified damping) has no interval; the others have theirs
    ci, corr = np.full(k, math.inf), np.full((k, k), math.nan)
    seen = np.diag(Atot) > 1e-12 * max(float(np.max(np.diag(Atot))), 1e-300)
    try:
        cov = np.linalg.inv(Atot[np.ix_(seen, seen)]) * s2 * prob.window
        ci[seen] = 1.96 * np.sqrt(np.maximum(np.diag(cov), 0.0))
        sd = np.sqrt(np.maximum(np.diag(cov), 1e-300))
        corr[np.ix_(seen, seen)] = cov / np.outer(sd, sd)
    except np.linalg.LinAlgError:
        pass
    for j, q in enumerate(cand.params):
        if not ci[j] < (hi[j] - lo[j]):
            notes.append(f"{q.name} is not identified on these flights (95% CI wider than "
                         "its range)")
    sub = corr[np.ix_(seen, seen)]
    if sub.shape[0] > 1 and np.all(np.isfinite(sub)):
        off = np.abs(sub - np.diag(np.diag(sub))).max()
        if off >= THRESHOLDS["max_param_corr"]:
            names = [q.name for q in cand.params]
            notes.append(f"parameters {' and '.join(names)} are correlated ({off:.3f}, VIF "
                         f"{1 / max(1 - off**2, 1e-12):.0f}): only their combination is "
                         "identified on these flights")
    # scores
    sse_base = float(base_sq.sum())
    held_base = base_sq.sum()
    held_fit = float(held.sum())
    red = 1 - math.sqrt(held_fit / held_base) if held_base > 0 else 0.0
    excess = held_base - n_total
    exc = (held_base - held_fit) / excess if excess > 0.02 * n_total else math.nan
    n_eff = n_total / prob.window
    dbic = n_eff * math.log(max(sse_fit, 1e-300) / sse_base) + k * math.log(n_eff)
    rng = hi - lo
    edge = np.any((theta - lo < 0.01 * rng) & (lo > 0)) or np.any(hi - theta < 0.01 * rng)
    names_ = [q.name for q in cand.params]
    if edge:
        notes.append(f"{', '.join(names_)} at the edge of the plausible range")
    plausible = not edge
    stable = spread <= THRESHOLDS["max_fold_spread"]
    axes = list(prob.axes)
    n_ax = np.array([[v.size for v in f_.values()] for f_ in vecs]).sum(0)
    rb = {a: float(np.sqrt(base_sq[:, j].sum() / n_ax[j])) for j, a in enumerate(axes)}
    ra = {a: float(np.sqrt(held[:, j].sum() / n_ax[j])) for j, a in enumerate(axes)}
    contrib = np.concatenate([np.concatenate([bv[a] - v[a] for a in bv])
                              for bv, v in zip(base_vecs, vecs, strict=True)])
    contrib = contrib.astype(np.float32)
    p_before = prob.base_structure_power()
    structure = None
    if p_before:
        structure = 1 - math.sqrt(prob.structure_power(held_vecs) / p_before)
    empirical = bool(getattr(cand, "empirical", False))
    # what a right model would not leave: significant binned structure (in azimuth,
    # airspeed, thrust or time) on any axis of the held-out residual (at the noise floor
    # the structure removed judges instead: CandidateResult.failed)
    left = () if structure is not None else tuple(
        f.sentence() for f in prob.structure_left(held_vecs))
    # an empirical law, or a physical effect's own words (the weak motor), of the
    # candidate or of the parts of a joint one; and what no such effect could be
    kinds = [k for k in (getattr(c, "kind", None) for c in getattr(cand, "parts", (cand,)))
             if k is not None]
    effects = [e for e in Model(cand.variant(cfg, theta).config).effects if e.kind in kinds]
    law = "; ".join(e.law() for e in effects
                    if EFFECTS[e.kind].empirical or EFFECTS[e.kind].law is not Effect.law)
    implausible = tuple(why for e in effects
                        for why in [e.implausible(prob.airspeed_range)] if why)
    return CandidateResult(
        cand.name, cand.doc, cand.params, theta, ci, folds, start, cand.report_values(theta),
        float(red), float(exc), float(dbic), bool(plausible), float(spread), bool(stable), corr,
        held_fit, n_eff, rb, ra, float(1 - math.sqrt(sse_fit / sse_base)), tuple(notes), contrib,
        structure, empirical, law, cand, left, implausible,
    )


# --------------------------------------------------------------------------- entry points


def diagnose(config: Config, logs, *, candidates=None, comparison: Comparison | None = None,
             progress=None, joint: bool = False, forward: bool = True,
             channel_map=None, exclude=(), trust=()) -> Diagnosis:
    """Find which physical effect the model misses: fit candidates, score them held out.

    The whole of ``gainsched diagnose`` (docs/model-vs-measurement.md, the module
    docstring): each candidate (a missing effect, a config parameter, the measurement
    latency) is refitted to the residual of :func:`~gainsched.analysis.compare.compare`,
    every axis weighted by its noise floor; it is scored on held-out flights
    (leave-one-flight-out: the RMS reduction and the share of the residual above the
    noise floor it explains), by delta-BIC, plausibility and fold stability; the
    candidates are ranked, near-collinear twins are named with the flight that would
    separate them, and the first candidate clearing every threshold of
    :data:`THRESHOLDS` is the verdict.

    Parameters
    ----------
    config : Config
        The model to improve.
    logs : iterable of str, path-like or FlightLog
        Flight log files or segments, from at least two flights (log files) for held-out
        scores. Not read when ``comparison`` is given.
    candidates : list of str, optional
        Names of the candidates to fit
        (:func:`~gainsched.analysis.diagnose.candidate_library`: ``"drag_quadratic"``,
        ``"thrust_momentum"``, ``"motor_lag"``, ``"latency"``, ``"mass"``, ...). Default:
        all of them. Empirical candidates (a law with no physics behind it, such as
        ``"thrust_azimuth"``) are fitted only when no physical one is accepted.
    comparison : Comparison, optional
        ``compare(config, logs)`` if already computed: it is reused, not recomputed.
    progress : callable, optional
        ``progress(name)`` before each candidate is fitted.
    joint : bool, default False
        Fit pairs of the best single candidates even when one passes (without
        ``joint`` they run only when none passes and the residual is above the noise
        floor): a passing joint fit then replaces the accepted single when its delta-BIC
        is lower by ``THRESHOLDS["nested_bic_gain"]``.
    forward : bool, default True
        Forward selection (:func:`_forward`): when the accepted fit, or the best single if
        none passes, leaves more than ``THRESHOLDS["forward_excess_gain"]`` of the
        residual above noise, add the next best effects while each explains clearly
        more; False: the single and joint fits only.
    channel_map : ChannelMap, str or path-like, optional
        For PX4 ULogs and ROS 2 bags among ``logs`` (:func:`compare`).
    exclude : sequence of str
        Candidates or effect kinds to leave out (:func:`select_candidates`): the library
        told that an effect is not there. When no other effect explains what it would
        have, the verdict says that no library effect explains it and fits an empirical
        term.
    trust : iterable of str, optional
        Consistency checks of the log files to skip (:func:`compare`).

    Returns
    -------
    Diagnosis
        The ranked candidates, the accepted one (or None), the twins, the verdict.

    Raises
    ------
    InputError
        Fewer than two flights, an unknown candidate name, or a log :func:`compare`
        refuses.

    Examples
    --------
    Two candidates on the seven example flights (held out: each flight predicted by the
    fit to the six others; the accepted one leaves a residual above noise, so forward
    selection tries the other with it, which does not explain clearly more):

    >>> import glob
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> logs = sorted(glob.glob("examples/flights/*.csv"))
    >>> d = gs.diagnose(cfg, logs, candidates=["drag_quadratic", "thrust_momentum"])
    >>> for r in d.results:
    ...     print(f"{r.name:32s} held-out RMS -{r.rms_reduction:.0%}, passes: {r.passes}")
    thrust_momentum                  held-out RMS -31%, passes: True
    thrust_momentum + drag_quadratic held-out RMS -30%, passes: True
    drag_quadratic                   held-out RMS -2%, passes: False
    >>> d.accepted.name, f"{d.accepted.values['disk_area']:.4f} m^2"
    ('thrust_momentum', '0.0061 m^2')
    >>> d.verdict
    'missing effect: thrust_momentum (thrust change with airspeed by momentum theory ...'
    """
    from ..errors import InputError

    base = comparison or compare(config, logs, channel_map=channel_map, trust=trust)
    meas = base.measured
    segs = base.segs
    prob = _Problem(config, meas, segs, base.noise, base.residuals)
    if len(prob.flights) < 2:
        raise InputError("command line", "LOG", "diagnose needs at least two flights (log "
                         "files) for held-out scores")
    library = candidate_library()
    names = select_candidates(candidates, exclude, library)
    names = _logged(names, library, meas, asked=candidates is not None)
    at_floor = all(s.rms_over_noise < AT_NOISE_FLOOR for s in base.stats.values())
    if at_floor:
        prob.track_structure(base)
    base_vecs = prob.base_vectors()
    base_sq = _sq(base_vecs)

    def fit(names_):
        for n in names_:
            if progress is not None:
                progress(n)
            cand, pre = library[n], None
            if getattr(cand, "orders", ()):
                cand, pre = _choose_order(prob, cand)
            results.append(_fit_candidate(prob, cand, base_sq, base_vecs, pre))
        results.sort(key=lambda r: (-r.rms_reduction, r.delta_bic))
        return _parsimonious([r for r in results if r.passes], library)

    results: list[CandidateResult] = []
    empirical = [n for n in names if getattr(library[n], "empirical", False)]
    accepted = fit([n for n in names if n not in empirical])
    if (accepted is None and not at_floor) or joint:
        both = _fit_joint(prob, library, results, base_sq, base_vecs, progress)
        if both is not None and (accepted is None or both.delta_bic < accepted.delta_bic
                                 - THRESHOLDS["nested_bic_gain"]):
            accepted = both
    # beyond the library: empirical laws only when no physical effect explains what is
    # there (an excess over the noise floor or binned structure), or when asked for
    if accepted is None and empirical and (candidates is not None or base.structure
                                           or not at_floor):
        accepted = fit(empirical)
    # several effects of similar size: add the next best while it explains clearly more
    if forward and not at_floor and (accepted is None or accepted.excess_explained
                                     < 1 - THRESHOLDS["forward_excess_gain"]):
        if empirical and not any(r.empirical for r in results):
            fit(empirical)  # what no effect of the library named may be the rest
        start = accepted or next((r for r in _physical_first(
            [r for r in results if " + " not in r.name], library) if r.rms_reduction > 0), None)
        if start is not None:
            accepted = _forward(prob, library, results, start, base_sq, base_vecs, progress)
    twins = []
    similarity = {}
    if accepted is not None and not accepted.empirical:
        ca = accepted.contribution.astype(float)
        na_ = float(np.sqrt(np.sum(ca * ca)))
        for r in results:
            if r is accepted or r.contribution is None:
                continue
            cb = r.contribution.astype(float)
            nb = float(np.sqrt(np.sum(cb * cb)))
            if na_ == 0 or nb == 0:
                continue
            cos = abs(float(np.sum(ca * cb)) / (na_ * nb))
            similarity[r.name] = cos
            if (_same_effect(library, r.name, accepted.name) or _nested(library, r, accepted)
                    or _nested(library, accepted, r)):
                continue  # another fit of the same effect (drag_linear of drag), or one
                # containing the other (thrust_scale in motor_efficiency): no twin
            # told apart anyway when the held-out fits differ clearly: the twin leaves more
            # than a tenth of the residual above noise that the accepted one explains
            clear = accepted.excess_explained - r.excess_explained > THRESHOLDS["twin_excess_gap"]
            if cos >= THRESHOLDS["twin_cos"] and not clear:
                twins.append((r.name, cos, separating_flight(accepted.name, r.name)))
    verdict = _verdict(base, results, accepted, twins, at_floor)
    return Diagnosis(config, base, results, accepted, twins, verdict, at_floor,
                     prob.flight_names, int(round(prob.n_evals)), similarity)


def select_candidates(candidates=None, exclude=(), library=None) -> list[str]:
    """The names of the candidates a diagnosis fits: ``candidates`` (default the whole
    library) without ``exclude``, checked.

    Parameters
    ----------
    candidates : sequence of str, optional
        Candidate names (:func:`candidate_library`).
    exclude : sequence of str
        Candidate names or effect kinds to leave out (an effect kind drops every candidate
        that fits it: ``"motor_efficiency"``, ``"thrust_time"``): the library told that
        an effect is not there, or a check that nothing else is taken for it.
    library : dict, optional
        Default :func:`candidate_library`.

    Raises
    ------
    InputError
        An unknown name, naming ``--candidate`` or ``--exclude``.

    Examples
    --------
    >>> names = select_candidates(exclude=["thrust_time"])
    >>> "thrust_time" in names, "thrust_scale" in names
    (False, True)
    """
    from ..errors import InputError

    library = candidate_library() if library is None else library
    names = list(library) if candidates is None else list(candidates)
    for n in names:
        if n not in library:
            raise InputError("command line", "--candidate",
                             f"unknown candidate {n!r} (known: {', '.join(library)})")
    kinds = {getattr(c, "kind", None) for c in library.values()} - {None}
    for n in exclude:
        if n not in library and n not in kinds:
            raise InputError("command line", "--exclude",
                             f"unknown candidate or effect {n!r} (known: "
                             f"{', '.join(library)})")
    out = set(exclude)
    return [n for n in names if n not in out and getattr(library[n], "kind", None) not in out]


def _logged(names, library, measured, asked: bool) -> list[str]:
    """``names`` without the candidates of effects that take their states from a log
    column (``Effect.log_channel``: ``vbat`` for ``thrust_voltage``) that a segment lacks
    or misses a sample of: not offered; asked for by name (``asked``), InputError
    naming the candidate and the log."""
    from ..errors import InputError

    out = []
    for n in names:
        cls = EFFECTS.get(getattr(library[n], "kind", None) or "")
        ch = getattr(cls, "log_channel", "")
        bad = next((m for m in measured if ch and not has_channel(m, ch)), None)
        if bad is None:
            out.append(n)
        elif asked:
            raise InputError("command line", "--candidate", f"{n} takes its state from the "
                             f"logged {ch} on every sample, which {bad.source} lacks "
                             "(docs/flight-log.md)")
    return out


def _fit_joint(prob, library, results, base_sq, base_vecs, progress):
    """When no single candidate passes: the :data:`JOINT_TOP` best singles (held-out RMS
    reduction, distinct effects) fitted in pairs, and the best pair with each of the
    others as a triple. Appends to ``results`` (re-ranked) and returns the accepted one:
    the best passing pair, or a triple whose delta-BIC is lower by
    ``THRESHOLDS["nested_bic_gain"]`` (parsimony)."""
    top: list[CandidateResult] = []
    for r in results:  # ranked already
        if (r.rms_reduction > 0 and r.name in library and r.name not in _NOT_JOINT
                and not r.empirical
                and not any(_same_effect(library, r.name, t.name) or _nested(library, r, t)
                            or _nested(library, t, r) for t in top)):
            top.append(r)
        if len(top) == JOINT_TOP:
            break
    if len(top) < 2:
        return None

    def joint(parts):
        return _joint_fit(prob, parts, base_sq, base_vecs, progress)

    pairs = [joint(pr) for pr in itertools.combinations(top, 2)]
    pairs.sort(key=lambda r: (-r.rms_reduction, r.delta_bic))
    best = pairs[0]
    names = set(best.name.split(" + "))
    triples = [joint([*(t for t in top if t.name in names), r]) for r in top
               if r.name not in names]
    results.extend(pairs + triples)
    results.sort(key=lambda r: (-r.rms_reduction, r.delta_bic))
    ok_pairs = [r for r in pairs if r.passes]
    ok_triples = sorted((r for r in triples if r.passes), key=lambda r: r.delta_bic)
    pick = ok_pairs[0] if ok_pairs else None
    if ok_triples and (pick is None or ok_triples[0].delta_bic
                       < pick.delta_bic - THRESHOLDS["nested_bic_gain"]):
        pick = ok_triples[0]
    return pick


def _joint_fit(prob, parts, base_sq, base_vecs, progress) -> CandidateResult:
    """The candidates of the fits ``parts`` (CandidateResult, single or joint) fitted
    together (:class:`JointCandidate`), started at their fits."""
    cfg = prob.config
    cands, starts, bounds = [], [], []
    for r in parts:
        subs = r.candidate.parts if isinstance(r.candidate, JointCandidate) else (r.candidate,)
        thetas = (np.split(np.asarray(r.theta, dtype=float), r.candidate._cut)
                  if isinstance(r.candidate, JointCandidate) else (r.theta,))
        for c, th in zip(subs, thetas, strict=True):
            b = _bounds(c, cfg, c.start(cfg))
            cands.append(c)
            bounds.append(b)
            starts.append(np.clip(th, b[0], b[1]))
    cand = JointCandidate(cands, starts, bounds)
    if progress is not None:
        progress(cand.name)
    return _fit_candidate(prob, cand, base_sq, base_vecs)


def _forward(prob, library, results, start, base_sq, base_vecs, progress):
    """Forward selection from the fit ``start`` (the accepted one, or the best single
    when none passes): add a single of another effect (held-out RMS reduction > 0; the
    tether's elasticity and empirical terms included; those whose fitted contribution
    projects most on what the current fit leaves tried first), all fitted
    together, while the fit leaves something (more than ``forward_excess_gain`` of the
    residual above noise, or binned structure) and the addition lowers delta-BIC by
    ``THRESHOLDS["nested_bic_gain"]`` and explains ``THRESHOLDS["forward_excess_gain"]``
    more of the residual above noise or removes the structure left; at most
    :data:`FORWARD_PARTS` parts, the best :data:`JOINT_TOP` tried at each step, a passing
    addition preferred. Appends its fits to ``results`` and returns the last passing fit
    (None when ``start`` did not pass and no extension does)."""
    current = start
    accepted = start if start.passes else None
    gain = THRESHOLDS["forward_excess_gain"]

    def better(t):  # explains clearly more (of the whole, or of what is left), or
        # removes the structure the current one left
        left = 1.0 - current.excess_explained
        return (t.excess_explained >= current.excess_explained + gain
                or t.excess_explained >= current.excess_explained
                + THRESHOLDS["forward_left_share"] * left
                or (bool(current.structure_left) and not t.structure_left))

    base = np.concatenate([np.concatenate(list(bv.values())) for bv in base_vecs])

    def leftover_explained(r, left):
        # the share of what the current fit leaves that the single's own fitted
        # contribution could take (its projection on it): matching pursuit's choice
        c = r.contribution.astype(float)
        cc = float(c @ c)
        return float(c @ left) ** 2 / cc if cc > 0 else 0.0

    while current.name.count(" + ") + 1 < FORWARD_PARTS and (
            current.excess_explained < 1 - gain or current.structure_left):
        names = current.name.split(" + ")
        left = base - current.contribution.astype(float)
        eligible = [r for r in results
                    if not (" + " in r.name or r.name in names or r.rms_reduction <= 0
                            or r.candidate is None or r.contribution is None
                            or any(_same_effect(library, r.name, n) for n in names)
                            or any(_nested(library, r, t) or _nested(library, t, r)
                                   for t in results if t.name in names))]
        pool = sorted(_physical_first(eligible, library),
                      key=lambda r: -leftover_explained(r, left))[:JOINT_TOP]
        fitted = {frozenset(r.name.split(" + ")): r for r in results}
        tries = [fitted.get(frozenset([*names, r.name]))
                 or _joint_fit(prob, [current, r], base_sq, base_vecs, progress) for r in pool]
        known = {id(r) for r in results}
        results.extend(t for t in tries if id(t) not in known)
        ok = [t for t in tries if better(t)
              and t.delta_bic < current.delta_bic - THRESHOLDS["nested_bic_gain"]]
        if not ok:
            break
        # a passing extension first; one that does not pass yet may still lead to one
        current = min([t for t in ok if t.passes] or ok, key=lambda t: t.delta_bic)
        if current.passes:
            accepted = current
    results.sort(key=lambda r: (-r.rms_reduction, r.delta_bic))
    return accepted


def _same_effect(library, a: str, b: str) -> bool:
    """Whether candidates ``a`` and ``b`` fit the same effect of the library (joint fits:
    whether they share one)."""
    if " + " in a or " + " in b:
        return any(_same_effect(library, x, y) for x in a.split(" + ") for y in b.split(" + "))
    ka, kb = getattr(library[a], "kind", None), getattr(library[b], "kind", None)
    return ka is not None and ka == kb


def _nested(library, small: CandidateResult, big: CandidateResult) -> bool:
    """Whether every model of candidate ``small`` is one of ``big``'s: a subset of the
    same effect's parameters (drag_quadratic in drag), or a candidate ``big``'s refit
    declares it contains (thrust_scale in motor_efficiency, :class:`Refit` ``contains``)."""
    if ({p.name for p in small.params} < {p.name for p in big.params}
            and _same_effect(library, small.name, big.name)):
        return True
    refit = getattr(library.get(big.name), "refit", None)
    return refit is not None and small.name in refit.contains


def _physical_first(singles: list[CandidateResult], library) -> list[CandidateResult]:
    """``singles`` without the empirical candidates that contain a physical one of them
    (:func:`_nested`: ``thrust_motor`` holds every ``motor_efficiency``) which fits about as
    well (delta-BIC within ``THRESHOLDS["nested_bic_gain"]``): forward selection then
    builds on the effect with a physical story, as the parsimony of nested fits does for
    the single candidates (:func:`_parsimonious`)."""
    gain = THRESHOLDS["nested_bic_gain"]
    return [r for r in singles
            if not (r.empirical and any(not q.empirical and _nested(library, q, r)
                                        and r.delta_bic > q.delta_bic - gain
                                        for q in singles))]


def _parsimonious(passing: list[CandidateResult], library) -> CandidateResult | None:
    """The best-ranked passing candidate, or a passing one nested in it
    (:func:`_nested`) unless the larger fit lowers delta-BIC by
    ``THRESHOLDS["nested_bic_gain"]`` more: the parsimony between nested models that the
    held-out ranking alone does not give."""
    if not passing:
        return None
    best = passing[0]
    for r in passing[1:]:
        if (_nested(library, r, best)
                and best.delta_bic > r.delta_bic - THRESHOLDS["nested_bic_gain"]):
            best = r
    return best


def _fmt_values(r: CandidateResult) -> str:
    parts = []
    for p, v, c in zip(r.params, r.theta, r.ci, strict=True):
        parts.append(f"{p.name} = {v:.4g} +- {c:.2g} {p.unit}")
    return ", ".join(parts)


def _table_refusal(result: CandidateResult) -> str:
    """Why no table can hold the effect ``result`` fitted, at its values (the build's
    check, :func:`~gainsched.model.symmetry.table_refusal`); "" when one can or when the
    candidate is not one effect's."""
    kind = getattr(result.candidate, "kind", None)
    if kind not in EFFECTS:
        return ""
    cls = EFFECTS[kind]
    names = {p.name for p in cls.params}
    return table_refusal(cls(**{k: v for k, v in result.values.items() if k in names}))


def _verdict(base, results, accepted, twins, at_floor) -> str:
    if at_floor and accepted is None and base.structure:
        # the overall RMS hides it; averaging over revolutions (or airspeed, thrust bins)
        # shows a systematic residual: name it instead of "no effect needed"
        f = base.structure[0]
        more = (f" ({len(base.structure) - 1} more in the structure table)"
                if len(base.structure) > 1 else "")
        best = results[0] if results else None
        tail = (f" No candidate explains it (the best, {best.name}, fails: "
                f"{'; '.join(best.failed())})." if best is not None else "")
        return (f"significant structure below the noise floor: {f.sentence()}{more}; every "
                f"axis is within {AT_NOISE_FLOOR:g}x its noise floor overall, but averaged over "
                f"the revolutions it is systematic.{tail}")
    grey = [f"{a} (Q {st.whiteness_q:.1f} > {st.whiteness_limit:.1f})"
            for a, st in base.stats.items() if not st.white]
    if at_floor and accepted is None and grey:
        # "no effect needed" needs a white residual too: a correlation in time that no
        # bin shows is still something the model does not explain
        best = results[0] if results else None
        tail = (f" No candidate explains it (the best, {best.name}, fails: "
                f"{'; '.join(best.failed())})." if best is not None else "")
        return (f"residual correlated in time: {', '.join(grey)} not white at the 99% "
                f"level (see the autocorrelation plot), although every axis is within "
                f"{AT_NOISE_FLOOR:g}x its noise floor with no significant structure in "
                f"azimuth, airspeed, thrust or time bins.{tail}")
    if at_floor and accepted is None:
        return (f"no effect needed: every residual axis is within {AT_NOISE_FLOOR:g}x its "
                "noise floor, and white, with no significant structure in azimuth, "
                "airspeed, thrust or time bins")
    if accepted is None:
        best = results[0] if results else None
        tail = ""
        if best is not None:
            tail = (f" The best candidate, {best.name}, removes {best.rms_reduction:.0%} of the "
                    f"held-out RMS but fails: {'; '.join(best.failed())}.")
        if base.structure:
            tail += f" Averaged over the revolutions: {base.structure[0].sentence()}."
        return (f"no library effect explains it: {base.where['sentence']}.{tail}")
    if accepted.below_noise:
        score = (f"held-out binned structure -{accepted.structure_reduction:.0%}, held-out "
                 f"RMS -{accepted.rms_reduction:.1%}")
    else:
        score = (f"held-out RMS -{accepted.rms_reduction:.0%}, explains "
                 f"{accepted.excess_explained:.0%} of the residual above noise")
    if accepted.empirical:
        what = (base.structure[0].sentence() if base.structure
                else base.where["sentence"])
        refusal = _table_refusal(accepted)
        where = (f"; no table can hold it: it {refusal}" if refusal
                 else " (and, by the table's symmetries, their mirror images)")
        return (f"no physical effect of the library explains the residual ({what}); "
                f"empirical correction: {accepted.name}, {accepted.law}; "
                f"{score}, delta-BIC {accepted.delta_bic:.0f}. It is a fit, not a model: "
                f"it holds on the circles flown{where}")
    parts = getattr(accepted.candidate, "parts", ())
    what = "missing effects, fitted together" if parts else "missing effect"
    law = f" ({accepted.law})" if accepted.law else ""
    s = (f"{what}: {accepted.name} ({accepted.doc}), {_fmt_values(accepted)}{law}; "
         f"{score}, delta-BIC {accepted.delta_bic:.0f}")
    fits = [q.name for q in parts if getattr(q, "empirical", False)]
    if fits:
        s += (f". {' and '.join(fits)} is an empirical correction: a fit, not a model, that "
              "holds on the circles flown (and, by the table's symmetries, their mirror "
              "images)")
    why = unidentified(accepted)
    if why:
        s += ". Not identified, so --apply keeps the config's value: " + "; ".join(
            f"{n} ({w})" for n, w in why.items())
    for name, cos, sep in twins:
        s += (f". It cannot be told apart from {name} on these flights (|cos| {cos:.3f}); "
              f"to separate them: {sep}")
    return s


def unidentified(result: CandidateResult) -> dict[str, str]:
    """Parameters of a fit that must not be written as fitted, with the reason: a 95 %
    CI wider than the estimate itself or than the parameter's fit range (it could be
    anything on these flights), or an estimate on a bound of that range."""
    out = {}
    for j, p in enumerate(result.params):
        v, c = float(result.theta[j]), float(result.ci[j])
        rng = p.upper - p.lower  # 0: bounds relative to the config's value (mass)
        on_bound = rng > 0 and min(v - p.lower, p.upper - v) <= 1e-9 * rng  # clipped there
        bound = f"estimate {v:.3g} {p.unit} on a bound of [{p.lower:g}, {p.upper:g}]"
        if result.empirical:
            # a series: its order was chosen held-out (one-SE rule), not its terms one by
            # one, and a small harmonic's wide CI is no reason to drop it from the law
            if on_bound:
                out[p.name] = bound
        elif not np.isfinite(c) or (rng > 0 and c >= rng):
            out[p.name] = f"95% CI +-{c:.2g} {p.unit} wider than its range"
        elif c >= abs(v):
            out[p.name] = f"95% CI +-{c:.2g} {p.unit} wider than the estimate {v:.3g}"
        elif on_bound:
            out[p.name] = bound
    return out


def apply_candidate(config: Config, result: CandidateResult, *, name: str | None = None) -> str:
    """Write a fitted candidate into the config: the new config text, CIs as comments.

    ``config``'s own text (its comments and layout kept) with the candidate's fitted
    values: an effect section added or updated, or a config key changed. Each value
    carries its unit, 95 % CI and leave-one-flight-out range as a comment, and the
    section a comment with the held-out scores. A parameter the flights did not identify (a CI wider
    than the estimate or than its range, or an estimate on a bound) keeps its value
    before the fit, with the reason as a comment. The text is validated with
    :func:`~gainsched.config.config_from_text` before it is returned.

    Parameters
    ----------
    config : Config
        The config the candidate was fitted to (``Diagnosis.config``).
    result : CandidateResult
        A fitted candidate: ``Diagnosis.accepted`` or any of ``Diagnosis.results``.
    name : str, optional
        A new ``name`` for the config; default: the config's own, so that the tables
        rebuilt from it keep their header and C symbol names (``<name>_gains.h``,
        ``<name>_...``) and firmware built on them keeps compiling through the loop
        compare -> diagnose -> apply -> build (replaced only when the text has a
        ``name`` key).

    Returns
    -------
    str
        The new config text (TOML), ready to write to a file or to load with
        :func:`~gainsched.config.config_from_text`.

    Raises
    ------
    InputError
        The edited text is not a valid config.

    Examples
    --------
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> logs = ["examples/flights/v3.csv", "examples/flights/v9.csv",
    ...         "examples/flights/v15.csv"]
    >>> d = gs.diagnose(cfg, logs, candidates=["thrust_momentum"])
    >>> text = gs.apply_candidate(cfg, d.accepted, name="paper_momentum")
    >>> print(text[text.index("[effects.thrust_momentum]"):])
    [effects.thrust_momentum]              # gainsched diagnose: thrust_momentum, held-out RMS ...
    disk_area = 0.0060...       # m^2, 95% CI [...], folds ...
    rho_air = 1.225                        # kept
    ...
    >>> improved = gs.config_from_text(text, "paper_momentum.toml")
    >>> improved.name, [e.name for e in improved.effects]
    ('paper_momentum', ['drag', 'thrust_momentum'])

    The residual falls on the same flights (normalised RMS, 1 = measurement noise):

    >>> before, after = d.base.normalized_rms(), gs.compare(improved, logs).normalized_rms()
    >>> f"{before:.1f} -> {after:.1f}"
    '5.3 -> 2.0'
    """
    from ..configedit import get_value

    cand = result.candidate or candidate_library()[result.name]
    why = unidentified(result)
    comments = []
    theta = result.theta.copy()
    for j, p in enumerate(result.params):
        if p.name in why:
            theta[j] = result.start[j]
            comments.append(f"not identified on these flights ({why[p.name]}), so not "
                            "written as fitted: the value before the fit")
            continue
        lo, hi = result.theta[j] - result.ci[j], result.theta[j] + result.ci[j]
        f = result.folds[:, j]
        comments.append(
            f"{p.unit}, 95% CI [{lo:.4g}, {hi:.4g}], folds {f.min():.4g}..{f.max():.4g}"
        )
    header = (f"gainsched diagnose: {result.name}, held-out RMS -{result.rms_reduction:.0%}, "
              f"delta-BIC {result.delta_bic:.0f}")
    if why:
        header += f"; not identified, not written: {', '.join(why)}"
    text = cand.apply_text(config.text, config, theta, comments, header,
                           keep=frozenset(why))
    if name is not None and get_value(text, "", "name") is not None:
        text = set_value(text, "", "name", name)
    cfg = config_from_text(text, "<diagnose --apply>")  # raises if the edit is invalid
    del cfg
    return text
