"""Builds whose effects leave the closed form (issue 39) against the drag-only build of
the same grid, in a process pinned like the ``gainsched`` command
(:mod:`gainsched.native.reproducible`), one worker, each case's best of rounds that take
every case in turn (:func:`bench.interleaved`): ``python -m
bench._effects`` prints one line per figure and the figures as JSON on its last line
(run by :func:`bench.bench_build.bench_effect_builds`).

- the paper's grid cut to 5 speeds x 3 tilts, with each effect of :data:`TRIM_EFFECTS`;
- the whole paper grid with rotor drag, with a motor lag, and with what ``gainsched
  improve`` finds on the example flights
  (:data:`IMPROVED`: momentum theory and a motor lag, docs/model-vs-measurement.md): the
  rebuild every user of the paper's loop waits for;
- a user's vehicle whose grid the build chooses (bench/configs/user_quad.toml; the chosen
  grid may differ with the effect, as the user's rebuild's would).

The quick mode (:func:`bench.quick`): the cut grid only, best of 2 rounds.
"""

from __future__ import annotations

from gainsched.native.reproducible import pin_environ

pin_environ()  # before numpy, as the command does

import json  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from bench import interleaved  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "configs" / "paper.toml"

#: library effects that leave the closed form (their nominal is the numerical trim), with
#: the parameters of the hidden-effect campaigns (gainsched.sim.campaign.HIDDEN)
TRIM_EFFECTS = {
    "rotor_drag": {"k_rd": 0.015},
    "motor_lag": {"tau": 0.035},
    "thrust_momentum": {"disk_area": 0.006},
    "thrust_airspeed": {"c1": -0.01, "c2": 0.0},
}
#: what ``gainsched improve configs/paper.toml examples/flights/*.csv`` fits
IMPROVED = {"thrust_momentum": {"disk_area": 0.005986}, "motor_lag": {"tau": 0.02979}}
#: the effects of issue 39's whole-paper-grid cases (the campaigns' values)
PAPER_EFFECTS = {kind: TRIM_EFFECTS[kind] for kind in ("rotor_drag", "motor_lag")}
#: the automatic-grid case: a user's vehicle whose speeds and tilts the build chooses
USER_QUAD = ROOT / "bench" / "configs" / "user_quad.toml"
#: the effects of the automatic-grid case, the ones issue 39 measured (values: that
#: vehicle's size)
AUTO_EFFECTS = {"rotor_drag": {"k_rd": 0.01}, "motor_lag": {"tau": 0.03}}


def _each(effects):
    """One case per effect: ``{kind: {kind: values}}``."""
    return {kind: {kind: values} for kind, values in effects.items()}


def _with(text, effects):
    from gainsched.config import set_section

    for kind, values in effects.items():
        text = set_section(text, f"effects.{kind}", [(k, v, None) for k, v in values.items()])
    return text


def _against_drag_only(out, prefix, make, text, name, effects, repeat, title, detail):
    """Time the drag-only build of ``text`` and one with each of ``effects`` (case name ->
    its effects, kind -> values) in interleaved rounds; print them with their ratios and
    store them in ``out`` under ``prefix``. ``make(text, name)``: the call to time;
    ``title`` and ``detail`` describe the drag-only result and an effect's result."""
    got = interleaved({"drag_only": make(text, name)} | {
        kind: make(_with(text, case), f"{kind}.toml") for kind, case in effects.items()},
        repeat)
    t0, r0 = got.pop("drag_only")
    out[f"{prefix}drag_only_s"] = t0
    print(f"  {title(r0)}: {t0:.2f} s")
    for kind, (t, r) in got.items():
        print(f"    + {kind}: {t:.2f} s{detail(r)}, x{t / t0:.2f} the drag-only build")
        out[f"{prefix}{kind}_s"], out[f"{prefix}{kind}_ratio"] = t, t / t0


def main() -> dict:
    from bench import quick
    from bench.bench_build import _variant
    from gainsched.config import config_from_text
    from gainsched.schedule.grid import build_grid
    from gainsched.schedule.refine import refine_grid

    def build(text, name):
        return lambda: build_grid(config_from_text(text, name), n_jobs=1)

    def auto(text, name):
        def run():
            choice = refine_grid(config_from_text(text, name), n_jobs=1)
            return len(choice.config.grid.speeds) * len(choice.config.grid.tilts)
        return run

    out = {}
    text = _variant(PAPER.read_text(), speeds=[3, 6, 9, 12, 15], tilts=[0, 20, 40])
    def gains(g):
        return f" ({int(np.isfinite(g.spectral_radius).sum())} circles with gains)"

    _against_drag_only(out, "", build, text, "cut.toml", _each(TRIM_EFFECTS), 2 if quick()
                       else 3, lambda g: (
        f"build of the paper grid cut to 5 speeds x 3 tilts ({g.spectral_radius.size} "
        "circles), drag only (closed form)"), lambda g: "")
    if quick():
        print("  the whole paper grid's and the automatic grid's effect builds: not in the "
              "quick mode (make bench)")
        return out
    _against_drag_only(out, "paper_", build, PAPER.read_text(), "paper.toml",
                       _each(PAPER_EFFECTS) | {"improved": IMPROVED}, 2, lambda g: (
                           f"the paper grid ({g.spectral_radius.size} circles), drag only"
                           f"{gains(g)}"), gains)
    _against_drag_only(out, "auto_", auto, USER_QUAD.read_text(), "user_quad.toml",
                       _each(AUTO_EFFECTS), 2, lambda n: (
                           "automatic grid of a user's vehicle (bench/configs/user_quad.toml), "
                           f"drag only ({n} circles chosen)"), lambda n: f" ({n} circles chosen)")
    return out


if __name__ == "__main__":
    print(json.dumps(main()))
