"""The candidate library: what a diagnosis can fit, and how each candidate edits a config.

A candidate (:class:`Candidate`) is a missing effect or a config parameter error, with
its fitted parameters (:class:`FitParam`: plausible bounds and search scale): a refit of
an effect of :mod:`gainsched.model.effects` (:class:`EffectCandidate`, as the effect's
:class:`~gainsched.model.effects.Refit` says), a scalar config parameter
(:class:`ConfigCandidate`: mass, attachment offset, tether length), the measurement
latency (:class:`LatencyCandidate`), the tether elasticity
(:class:`ElasticityCandidate`), or several of them fitted together
(:class:`JointCandidate`). Each makes the model variant at given parameters
(:meth:`Candidate.variant`, a :class:`CandidateModel`) and writes itself into the config
text (:meth:`Candidate.apply_text`).

Also here: the library by name (:func:`candidate_library`, :data:`CANDIDATES`,
:func:`single_parameter_set_candidates`), the names a diagnosis fits
(:func:`select_candidates`, :func:`_logged`) and the flight that tells two look-alike
candidates apart (:func:`separating_flight`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ...config import Config, EffectSpec, Tether, remove_key, set_section, set_value
from ...model.effects import EFFECTS, Param, Refit
from ..compare import (
    has_channel,
)


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
        # an effect of the tether's stretch alone changes the stretch axis only
        return CandidateModel(new, frozenset({"stretch"}) if EFFECTS[self.kind].stretch_only
                              else None)

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


class InertiaCandidate(Candidate):
    """Refit one principal moment of inertia (a diagonal entry of ``vehicle.inertia``):
    the angular accelerations about that axis scale with its inverse. Bounds 0.5-2x the
    config's value (a CAD estimate or a pendulum test is good to tens of percent)."""

    affine = False

    def __init__(self, axis: int):
        a = "xyz"[axis]
        self.axis = axis
        self.name = f"inertia_{a}"
        self.doc = (f"moment of inertia about the body {a} axis (vehicle.inertia J{a}{a}) "
                    "error")
        self.params = (FitParam(f"J{a}{a}", "kg m^2", 0.0, 0.0),)  # bounds: fit_bounds

    def start(self, cfg):
        return np.array([float(cfg.vehicle.inertia[self.axis, self.axis])])

    def fit_bounds(self, cfg, start):
        """0.5-2x the config's value, within the triangle inequalities of a rigid body's
        principal moments (each at most the sum of the other two)."""
        d = np.diag(np.asarray(cfg.vehicle.inertia, dtype=float))
        others = np.delete(d, self.axis)
        lo = max(0.5 * start[0], abs(others[0] - others[1]))
        hi = min(2.0 * start[0], others.sum())
        return np.array([lo]), np.array([hi])

    def _inertia(self, cfg, value):
        J = np.array(cfg.vehicle.inertia, dtype=float)
        J[self.axis, self.axis] = value
        return J

    def variant(self, cfg, theta):
        return CandidateModel(_replaced(cfg, "vehicle", "inertia",
                                        self._inertia(cfg, float(theta[0]))))

    def apply_text(self, text, cfg, theta, comments, header, keep=frozenset()):
        J = self._inertia(cfg, float(theta[0]))
        value = ([float(v) for v in np.diag(J)] if np.count_nonzero(J - np.diag(np.diag(J))) == 0
                 else [[float(v) for v in row] for row in J])
        return set_value(text, "vehicle", "inertia", value,
                         f"kg m^2; J{'xyz'[self.axis] * 2}: {comments[0]}; {header}")


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
        # what every real quadcopter has a little of: the moments of inertia
        # and the rotors' reaction-torque coefficient, each known to tens of percent
        *(InertiaCandidate(i) for i in range(3)),
        ConfigCandidate("kappa", "vehicle", "kappa", P("kappa", "m", 0.0, 0.0),
                        "rotor reaction-torque coefficient (vehicle.kappa: yaw torque per "
                        "newton of thrust) error", affine=True, bounds_rel=(0.3, 3.0)),
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
    ``drag_quadratic``) and without the empirical ones: the benchmark's baseline library."""
    library = candidate_library() if library is None else library

    def nested(c):
        kind, ps = getattr(c, "kind", None), {p.name for p in c.params}
        return kind is not None and any(
            getattr(o, "kind", None) == kind and {p.name for p in o.params} < ps
            for o in library.values())

    return [n for n, c in library.items()
            if not nested(c) and not getattr(c, "empirical", False)]


#: the candidates of effects every real flight has a little of (the tether's own stretch):
#: when one is needed on its own (:func:`_nuisance`), every other candidate is fitted with
#: it in the model, and the accepted one is fitted together with it
NUISANCE = ("tether_elasticity",)


#: The candidate library of the built-in effects, by name (:func:`candidate_library`).
CANDIDATES: dict[str, Candidate] = candidate_library()


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
    from ...errors import InputError

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
    from ...errors import InputError

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
    frozenset({"inertia_y", "inertia_z"}):
        "pitch or yaw manoeuvres (a yaw step, a pitch doublet): on steady circles only "
        "Jzz - Jyy shows, through the gyroscopic roll torque of the turning vehicle",
    frozenset({"kappa", "inertia_z"}):
        "yaw manoeuvres at low thrust and at high thrust: the reaction torque scales with "
        "the thrust, the yaw inertia does not",
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
