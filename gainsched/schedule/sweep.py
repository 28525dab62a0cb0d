"""Vehicle-variant and Monte Carlo sweeps: many gain tables from one base config.

A sweep changes scalar parameters of a base config (``--vary KEY=v1,v2,...``,
Cartesian product over several keys) and/or draws ``N`` Monte Carlo samples
(``--sigma KEY=rel``: value = nominal x (1 + rel z), z ~ N(0, 1) from
``numpy.random.default_rng(seed)``; with ``--vary`` too, each combination gets
the same N draws: common random numbers). Every variant is a full config text
(the base TOML with the changed values and the variant name), written next to
its table as ``NAME.toml``, so ``gainsched build DIR/NAME.toml`` reproduces
``DIR/NAME.h5`` byte for byte and the table's config hash names the variant,
not the base.

Keys are dotted paths of the :class:`~gainsched.config.Config` dataclass
fields holding one real number, in SI units: ``vehicle.mass``,
``vehicle.arm_length``, ``vehicle.kappa``, ``vehicle.thrust_min``,
``vehicle.thrust_max``, ``vehicle.inertia.xx`` / ``.yy`` / ``.zz`` (diagonal
of the inertia matrix), ``tether.length``, ``tether.attachment_offset``,
``tether.stiffness``, ``tether.damping``, ``g`` (alias ``environment.g``),
``control.rate_hz``, ``feasibility.min_tension``,
``feasibility.thrust_margin`` and ``effects.NAME.PARAM`` for the effects in
the config. Every variant is validated like any config before the first build
starts, so a bad key or an impossible value fails at once, naming the key.

Results (``sweep.csv`` and ``sweep.json`` in the output folder, deterministic,
no timestamps, identical whatever backend ran the builds) have one row per
variant: name, parameter values, feasible % of grid points, worst closed-loop
monodromy spectral radius, max |K| over feasible points, min tension margin
(nominal tension minus ``feasibility.min_tension`` over feasible points, N) and
the SHA-256 of the variant's HDF5 table.
"""

from __future__ import annotations

import csv
import hashlib
import io
import itertools
import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from ..config import Config, config_from_text, set_values
from ..constants import MAX_SEED, MAX_SWEEP_VARIANTS
from ..errors import InputError

__all__ = [
    "Sweep",
    "Variant",
    "COLUMNS",
    "SCHEMA",
    "scalar_parameters",
    "parse_vary",
    "parse_sigma",
    "make_sweep",
    "variant_text",
    "summarize",
    "run_sweep",
    "results_csv",
    "results_json",
    "format_rows",
]

SCHEMA = "gainsched-sweep/1"
#: metric columns of the results table, after ``variant`` and the parameter columns.
COLUMNS = ("feasible_pct", "worst_spectral_radius", "max_abs_K", "min_tension_margin_N",
           "table_sha256", "table")
_SRC = "command line"
_SECTIONS = ("vehicle", "tether", "control", "feasibility")
_INERTIA = {"xx": 0, "yy": 1, "zz": 2}
_ALIASES = {"environment.g": "g"}


@dataclass(frozen=True)
class Variant:
    """One member of a sweep.

    Attributes
    ----------
    name : str
        ``BASE-vNNN``; also the config ``name`` and the file stem of its outputs.
    params : tuple of (key, value)
        The swept parameters (SI units), in results-column order.
    config : Config
        The validated variant config (its ``text`` is what ``NAME.toml`` holds).
    """

    name: str
    params: tuple[tuple[str, float], ...]
    config: Config


@dataclass(frozen=True)
class Sweep:
    """A planned sweep: the base config, what changes, and every variant (in order).

    Attributes
    ----------
    base : Config
    vary : tuple of (key, values)
        Canonical keys and their grid values (SI).
    sigma : tuple of (key, rel)
        Canonical keys sampled by Monte Carlo and their relative standard deviations.
    monte_carlo : int
        Samples per ``vary`` combination (0: none).
    seed : int
    variants : tuple of Variant
    """

    base: Config
    vary: tuple[tuple[str, tuple[float, ...]], ...]
    sigma: tuple[tuple[str, float], ...]
    monte_carlo: int
    seed: int
    variants: tuple[Variant, ...]

    @property
    def keys(self) -> tuple[str, ...]:
        """Parameter columns of the results table: vary keys, then sampled keys."""
        return tuple(k for k, _ in self.vary) + tuple(k for k, _ in self.sigma)

    def meta(self) -> dict:
        """What defines the sweep (for ``sweep.json``)."""
        return {
            "base_config": self.base.name,
            "base_config_sha256": self.base.sha256,
            "vary": {k: list(v) for k, v in self.vary},
            "monte_carlo": self.monte_carlo,
            "seed": self.seed if self.monte_carlo else None,
            "sigma": dict(self.sigma),
        }


# --------------------------------------------------------------------------- keys


def scalar_parameters(config: Config) -> dict[str, tuple]:
    """The keys a sweep can change, each with its path in the TOML document.

    Returns ``{key: path}``; a path is a tuple of TOML table keys, ending in an
    inertia diagonal index for ``vehicle.inertia.xx/yy/zz``.
    """
    out: dict[str, tuple] = {}
    for f in fields(Config):
        if isinstance(getattr(config, f.name), float):
            out[f.name] = ("environment", f.name)  # g lives in [environment]
    for section in _SECTIONS:
        obj = getattr(config, section)
        for f in fields(obj):
            v = getattr(obj, f.name)
            if isinstance(v, float) and not isinstance(v, bool):
                out[f"{section}.{f.name}"] = (section, f.name)
        if section == "vehicle":
            for ax, i in _INERTIA.items():
                out[f"vehicle.inertia.{ax}"] = ("vehicle", "inertia", i)
    for spec in config.effects:
        for p, _ in spec.params:
            out[f"effects.{spec.name}.{p}"] = ("effects", spec.name, p)
    return out


def _resolve(config: Config, key: str, option: str) -> str:
    """Canonical key for ``key`` or an InputError naming the key and what exists."""
    key = _ALIASES.get(key, key)
    known = scalar_parameters(config)
    if key in known:
        return key
    parts = key.split(".")
    head = parts[0]
    same = ", ".join(k for k in known if k.startswith(head + "."))
    if head == "effects" and len(parts) > 1 and parts[1] not in {e.name for e in config.effects}:
        have = ", ".join(e.name for e in config.effects) or "none"
        msg = f"the config has no [effects.{parts[1]}] (its effects: {have})"
    elif head == "effects":
        msg = f"unknown parameter (known: {same or 'none'})"
    elif head in _SECTIONS and len(parts) == 2 and parts[1] in {
        f.name for f in fields(getattr(config, head))
    }:
        msg = f"is not a real-valued parameter (vary one of: {same})"
    elif head in _SECTIONS:
        msg = f"unknown parameter (known: {same})"
    elif head in {f.name for f in fields(Config)}:
        msg = "cannot be varied (not a scalar physical parameter)"
    else:
        msg = f"unknown parameter (known: {', '.join(known)})"
    raise InputError(_SRC, f"{option} {key}", msg)


def _value(config: Config, key: str) -> float:
    """Current value of a canonical key, SI units."""
    parts = key.split(".")
    if parts[0] == "effects":
        return next(e for e in config.effects if e.name == parts[1]).param_dict()[parts[2]]
    if parts[:2] == ["vehicle", "inertia"]:
        i = _INERTIA[parts[2]]
        return float(config.vehicle.inertia[i, i])
    obj = config
    for p in parts:
        obj = getattr(obj, p)
    return float(obj)


def _split(spec: str, option: str) -> tuple[str, str]:
    key, sep, rest = spec.partition("=")
    key = key.strip()
    if not sep or not key or not rest.strip():
        raise InputError(_SRC, option, f"expected KEY=VALUE(S), got {spec!r}")
    return key, rest


def _number(text: str, where: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise InputError(_SRC, where, f"not a number: {text.strip()!r}") from None
    if not math.isfinite(v):
        raise InputError(_SRC, where, f"must be finite, got {text.strip()!r}")
    return v


def parse_vary(spec: str) -> tuple[str, tuple[float, ...]]:
    """``"vehicle.mass=0.45,0.5,0.55"`` -> ``("vehicle.mass", (0.45, 0.5, 0.55))``."""
    key, rest = _split(spec, "--vary")
    values = tuple(_number(t, f"--vary {key}") for t in rest.split(","))
    for i, v in enumerate(values):
        if v in values[:i]:  # two variants alike: the same table built twice
            raise InputError(_SRC, f"--vary {key}", f"{v:g} given twice: each value once")
    return key, values


def parse_sigma(spec: str) -> tuple[str, float]:
    """``"vehicle.mass=0.05"`` -> ``("vehicle.mass", 0.05)`` (relative standard deviation)."""
    key, rest = _split(spec, "--sigma")
    rel = _number(rest, f"--sigma {key}")
    if rel < 0:
        raise InputError(_SRC, f"--sigma {key}", f"must be >= 0 (relative), got {rel:g}")
    return key, rel


def variant_text(base: Config, name: str, values: Sequence[tuple[str, float]]) -> str:
    """The TOML text of ``base`` with ``values`` (canonical keys) applied and ``name`` set:
    the base text edited as a document (:mod:`gainsched.config` (``_edit``)), comments kept,
    values in full precision."""
    paths = scalar_parameters(base)
    edits = {".".join(map(str, paths[key])): float(v) for key, v in values}
    edits["name"] = name
    changed = ", ".join(f"{k} = {float(v)!r}" for k, v in values)
    head = (f"# gainsched sweep variant {name} of config {base.name!r} "
            f"(sha256 {base.sha256[:12]}): {changed}\n")
    return head + set_values(base.text, edits)


# --------------------------------------------------------------------------- variants


def make_sweep(base: Config, vary: Sequence[tuple[str, Sequence[float]]] = (), *,
               monte_carlo: int = 0, seed: int = 0,
               sigma: Sequence[tuple[str, float]] = ()) -> Sweep:
    """Plan a sweep: every variant, validated, in a deterministic order.

    Parameters
    ----------
    base : Config
    vary : sequence of (key, values)
        Grid values per key (SI); the variants are the Cartesian product, last key fastest.
    monte_carlo : int
        Samples per ``vary`` combination (0: no Monte Carlo).
    seed : int
        Seed of ``numpy.random.default_rng``; the draws are shared by every combination.
    sigma : sequence of (key, rel)
        Relative standard deviation per sampled key: value = nominal (1 + rel z).

    Raises
    ------
    InputError
        Unknown or repeated key, Monte Carlo options missing or inconsistent, or a
        variant that is not a valid config (names the variant and the key).
    """
    if not vary and not monte_carlo:
        raise InputError(_SRC, "--vary", "give --vary KEY=v1,v2,... and/or --monte-carlo N")
    if monte_carlo < 0:
        raise InputError(_SRC, "--monte-carlo", f"must be >= 0, got {monte_carlo}")
    # counted before any variant is made (a product of --vary lists can be astronomical)
    n_variants = math.prod(len(v) for _, v in vary) * max(monte_carlo, 1)
    if n_variants > MAX_SWEEP_VARIANTS:
        option = "--monte-carlo" if monte_carlo > MAX_SWEEP_VARIANTS or not vary else "--vary"
        raise InputError(_SRC, option, f"{n_variants:,} variants (tables); a sweep may have at "
                         f"most {MAX_SWEEP_VARIANTS:,} (each is a whole table build)")
    if monte_carlo and not sigma:
        raise InputError(_SRC, "--monte-carlo", "needs at least one --sigma KEY=rel")
    if sigma and not monte_carlo:
        raise InputError(_SRC, "--sigma", "is only used with --monte-carlo N")
    if not 0 <= seed <= MAX_SEED:
        raise InputError(_SRC, "--seed", f"must be an integer in [0, {MAX_SEED}], got {seed}")
    keys: list[str] = []
    for option, key in [("--vary", k) for k, _ in vary] + [("--sigma", k) for k, _ in sigma]:
        canon = _resolve(base, key, option)
        if canon in keys:
            raise InputError(_SRC, f"{option} {key}", "is given more than once")
        keys.append(canon)
    vary_keys, sigma_keys = keys[: len(vary)], keys[len(vary) :]
    for key, values in vary:
        if not values:
            raise InputError(_SRC, f"--vary {key}", "needs at least one value")

    combos = list(itertools.product(*(v for _, v in vary)))
    z = np.random.default_rng(seed).standard_normal((monte_carlo, len(sigma)))
    rel = np.array([r for _, r in sigma])
    nominal = np.array([_value(base, k) for k in sigma_keys])
    samples = nominal * (1 + rel * z) if monte_carlo else np.zeros((1, 0))

    n = len(combos) * samples.shape[0]
    width = max(3, len(str(n - 1)))
    out = []
    for i, (combo, draw) in enumerate(itertools.product(combos, samples)):
        name = f"{base.name}-v{i:0{width}d}"
        params = tuple(zip(keys, [float(x) for x in (*combo, *draw)], strict=True))
        text = variant_text(base, name, params)
        try:
            cfg = config_from_text(text, f"sweep variant {name}")
        except InputError as exc:  # named by the options that made the variant
            vals = ", ".join(f"{k}={v:g}" for k, v in params)
            opts = " and ".join(o for o, given in (("--vary", vary), ("--sigma", sigma))
                                if given)
            where = f"{exc.where}: " if exc.where else ""
            raise InputError(_SRC, opts, f"variant {name} ({vals}): {where}"
                             f"{exc.message}") from None
        out.append(Variant(name, params, cfg))
    vary_c = tuple(
        (k, tuple(float(x) for x in v)) for k, (_, v) in zip(vary_keys, vary, strict=True)
    )
    sigma_c = tuple((k, float(r)) for k, (_, r) in zip(sigma_keys, sigma, strict=True))
    return Sweep(base, vary_c, sigma_c, int(monte_carlo), int(seed), tuple(out))


# --------------------------------------------------------------------------- results


def summarize(config: Config, grid) -> dict[str, float]:
    """Metrics of one built grid (``grid.GridResult``).

    Returns ``feasible_pct`` (% of (tilt, speed, xi) points), ``worst_spectral_radius``
    (max closed-loop monodromy spectral radius, NaN if no feasible circle), ``max_abs_K``
    (max |K_ij| over feasible points, SI) and ``min_tension_margin_N`` (min over feasible
    points of nominal tension - ``feasibility.min_tension``, N; NaN if none).
    """
    ok = grid.reasons == 0
    K = np.abs(grid.K[ok])
    K = K[np.isfinite(K)]
    rho = grid.spectral_radius[np.isfinite(grid.spectral_radius)]
    margin = grid.tension[ok] - config.feasibility.min_tension
    return {
        "feasible_pct": 100.0 * float(np.count_nonzero(ok)) / ok.size,
        "worst_spectral_radius": float(rho.max()) if rho.size else math.nan,
        "max_abs_K": float(K.max()) if K.size else math.nan,
        "min_tension_margin_N": float(margin.min()) if margin.size else math.nan,
    }


def run_sweep(sweep: Sweep, out_dir, *, n_jobs: int = -1,
              backend: str | None = None,
              progress: Callable[[int], None] | None = None) -> list[dict]:
    """Build every variant, one after the other, each swept over its speeds in parallel.

    Writes ``OUT/NAME.toml`` and ``OUT/NAME.h5`` per variant (atomically; one grid
    in memory at a time), then the results ``OUT/sweep.csv`` and ``OUT/sweep.json``.
    ``n_jobs`` and ``backend`` go to :func:`gainsched.schedule.grid.build_grid` (take them from
    :func:`gainsched.schedule.distributed.executor`); ``progress(1)`` is called per finished speed.
    A config whose axes the build chooses is refined per variant
    (:func:`gainsched.schedule.refine.refine_grid`; ``progress`` counts circles then), and
    ``NAME.toml`` is the chosen config.

    Returns the result rows (dicts: ``variant``, the parameter keys, then :data:`COLUMNS`).
    """
    from ..model.reduced import Model
    from ..publish import write_atomic
    from .grid import build_grid
    from .refine import refine_grid
    from .tables import table_bytes

    out_dir = Path(out_dir)
    rows = []
    for v in sweep.variants:
        config, record = v.config, None
        if config.grid.auto:
            choice = refine_grid(config, n_jobs=n_jobs, progress=progress, backend=backend)
            config, grid, record = choice.config, choice.grid, choice.record()
        else:
            grid = build_grid(config, n_jobs=n_jobs, progress=progress, backend=backend)
        data = table_bytes(config, grid, Model(config), record)
        write_atomic(out_dir / f"{v.name}.toml", config.text.encode())
        write_atomic(out_dir / f"{v.name}.h5", data)
        row = {"variant": v.name, **dict(v.params), **summarize(config, grid)}
        row["table_sha256"] = hashlib.sha256(data).hexdigest()
        row["table"] = f"{v.name}.h5"
        rows.append(row)
        del grid, data
    write_atomic(out_dir / "sweep.csv", results_csv(rows).encode())
    write_atomic(out_dir / "sweep.json", results_json(sweep, rows).encode())
    return rows


def _csv_cell(x) -> str:
    if isinstance(x, float):
        return "nan" if math.isnan(x) else repr(x)
    return str(x)


def results_csv(rows: Sequence[dict]) -> str:
    """The results table as CSV text (header row; floats in shortest round-trip form)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    if rows:
        w.writerow(list(rows[0]))
        for r in rows:
            w.writerow([_csv_cell(x) for x in r.values()])
    return buf.getvalue()


def results_json(sweep: Sweep, rows: Sequence[dict]) -> str:
    """The results as JSON text: schema, tool version, the sweep definition, the column
    names, then one object per variant (NaN written as null)."""
    from .. import __version__

    def clean(x):
        return None if isinstance(x, float) and math.isnan(x) else x

    doc = {
        "schema": SCHEMA,
        "tool_version": __version__,
        **sweep.meta(),
        "columns": ["variant", *sweep.keys, *COLUMNS],
        "variants": [{k: clean(x) for k, x in r.items()} for r in rows],
    }
    return json.dumps(doc, indent=2, allow_nan=False) + "\n"


def format_rows(sweep: Sweep, rows: Sequence[dict], limit: int = 30) -> list[str]:
    """Lines for the terminal: one per variant (at most ``limit``), then the ranges."""

    def f(x, spec):
        return "n/a" if isinstance(x, float) and math.isnan(x) else format(x, spec)

    keys = sweep.keys
    head = ["variant", *keys, "feasible%", "rho_max", "max|K|", "T_margin_N", "sha256"]
    width = [max(len(h), 10) for h in head]
    lines = ["  ".join(h.rjust(w) for h, w in zip(head, width, strict=True))]
    for r in rows[:limit]:
        cells = [r["variant"], *(f(r[k], ".6g") for k in keys), f(r["feasible_pct"], ".1f"),
                 f(r["worst_spectral_radius"], ".5f"), f(r["max_abs_K"], ".4g"),
                 f(r["min_tension_margin_N"], ".3f"), r["table_sha256"][:12]]
        lines.append("  ".join(c.rjust(w) for c, w in zip(cells, width, strict=True)))
    if len(rows) > limit:
        lines.append(f"  ... {len(rows) - limit} more in sweep.csv")
    for col, unit in (("feasible_pct", "%"), ("worst_spectral_radius", ""),
                      ("max_abs_K", ""), ("min_tension_margin_N", " N")):
        v = np.array([r[col] for r in rows], dtype=float)
        v = v[np.isfinite(v)]
        if v.size:
            lines.append(f"  {col}: {v.min():.6g} .. {v.max():.6g}{unit} "
                         f"(median {np.median(v):.6g}) over {v.size} variants")
    return lines
