"""Reports of the model-versus-measurement loop: terminal text, Markdown with PNG plots, JSON.

- :func:`compare_lines` / :func:`write_compare`: per-axis statistics, where the model
  fails, the paper's analyses (Sec. V.C, Figs. 5 and 6).
- :func:`before_after_lines` / :func:`write_before_after`: two comparisons on the same
  logs side by side (table and plots): the error falling after an effect is added.
- :func:`diagnose_lines` / :func:`write_diagnose`: the candidate ranking and the verdict.

Every number of the reports is in the JSON; plots are written with matplotlib (Agg).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from .compare import BIN_VARIABLES, Comparison
from .diagnose import THRESHOLDS, Diagnosis
from .paperfits import PaperFits

__all__ = [
    "compare_lines",
    "before_after_lines",
    "diagnose_lines",
    "write_compare",
    "write_before_after",
    "write_diagnose",
    "write_json",
]


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _clean(x):
    """JSON-safe: numpy scalars/arrays to Python, nan/inf to None."""
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    if isinstance(x, np.ndarray):
        return _clean(x.tolist())
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(float(x)) else None
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x


def write_json(path, data) -> Path:
    """Write ``data`` as JSON (sorted keys, nan as null) atomically."""
    from ..publish import write_atomic

    write_atomic(path, (json.dumps(_clean(data), indent=2, sort_keys=True) + "\n").encode())
    return Path(path)


def _g(x, n=3):
    return "n/a" if x is None or not np.isfinite(x) else f"{x:.{n}g}"


# --------------------------------------------------------------------------- compare


def _header(cmp: Comparison) -> str:
    n = sum(len(r) for r in cmp.residuals)
    flights = sorted({r.source for r in cmp.residuals})
    tens = sorted({r.tension_source for r in cmp.residuals})
    return (f"model {cmp.config.name} ({cmp.config.source}) on {len(flights)} flight(s), "
            f"{len(cmp.residuals)} segment(s), {n} samples; tension from "
            f"{' / '.join(tens)}")


def _axis_table(cmp: Comparison):
    rows = []
    for a, s in cmp.stats.items():
        sig = [(k, v) for k, v in s.ccf.items() if v[3]]
        if sig:
            k, v = max(sig, key=lambda kv: kv[1][0] / kv[1][2])
            cc = f"{k} {v[0]:.2f} at {v[1]:+.3f} s"
        else:
            cc = "none significant"
        rows.append((a, s.unit, _g(s.rms), f"{s.bias:+.3g}", f"{s.fit_percent:.1f}",
                     _g(s.noise_floor), f"{s.rms_over_noise:.2f}", "yes" if s.white else "no",
                     cc))
    return ("axis", "unit", "RMS", "bias", "fit %", "noise", "RMS/noise", "white",
            "strongest input correlation"), rows


def _text_table(head, rows, widths) -> list[str]:
    """Fixed-width columns, the last one free."""

    def line(cells):
        body = " ".join(str(c).ljust(x) for c, x in zip(cells, widths, strict=False))
        return f"  {body} {cells[-1]}"

    return [line(head)] + [line(r) for r in rows]


def compare_lines(cmp: Comparison, paper: PaperFits | None = None) -> list[str]:
    """Terminal summary of a comparison (and of the paper's analyses, if given)."""
    head, rows = _axis_table(cmp)
    w = [10, 7, 9, 9, 7, 9, 9, 5]
    out = [_header(cmp)]
    out += _text_table(head, rows, w)
    out.append(f"  normalised RMS (1 = noise): {cmp.normalized_rms():.3f}")
    for line in cmp.sensor_lines():
        out.append(f"sensors: {line}")
    out.append(f"where it fails: {cmp.where['sentence']}")
    for f in cmp.structure[:3]:
        out.append(f"structure: {f.sentence()}")
    if not cmp.structure:
        out.append("structure: no significant residual in azimuth, airspeed, thrust or time bins "
                   "(block means over revolutions)")
    for tr in cmp.tracking:
        out.append(f"tracking {tr['segment']}: RMS along-track {tr['rms_along_track_m']:.4f} m, "
                   f"max {tr['max_along_track_m']:.4f} m, final azimuth error "
                   f"{tr['final_azimuth_error_rad']:+.4f} rad, lap slips {tr['lap_slips']}")
    for note in cmp.notes:
        out.append(f"note: {note}")
    if paper is not None:
        out += _paper_lines(paper)
    return out


def _paper_lines(p: PaperFits) -> list[str]:
    eta = p.bins["eta"]["mean"]
    edges = p.bins["edges"]
    pairs = [f"{(edges[i] + edges[i + 1]) / 2:g} m/s: {e:.3f}"
             for i, e in enumerate(eta) if e is not None]
    return [
        f"paper Sec. V.C, Fig. 6: drag fit mu1 = {p.mu1:.4g} +- {p.mu1_ci:.2g} N s/m, "
        f"mu2 = {p.mu2:.4g} +- {p.mu2_ci:.2g} N s^2/m^2 (RMS {p.drag_rms:.3g} N)",
        f"paper Sec. V.C, Fig. 5: thrust efficiency eta_f by airspeed: {', '.join(pairs)}",
        f"  momentum theory (eq. 29) fitted: disk area {p.disk_area:.3g} m^2, "
        f"RMS eta - T/T_h {p.momentum_rms:.3f}",
    ]


def _plot_residuals(cmp: Comparison, path: Path):
    plt = _plt()
    axes = cmp.axes
    fig, ax = plt.subplots(len(axes), 1, figsize=(10, 1.7 * len(axes) + 0.8), sharex=True)
    ax = np.atleast_1d(ax)
    offset = 0.0
    for r in cmp.residuals:
        x = np.arange(len(r)) + offset
        for k, a in enumerate(axes):
            ax[k].plot(x, r.residual[a], lw=0.5)
        for k in range(len(axes)):
            ax[k].axvline(offset, color="0.7", lw=0.5)
        ax[0].text(offset, 1.02, r.name, transform=ax[0].get_xaxis_transform(), fontsize=6,
                   rotation=30)
        offset += len(r)
    for k, a in enumerate(axes):
        nf = cmp.noise[a]
        ax[k].axhspan(-nf, nf, color="0.9", zorder=0)
        ax[k].set_ylabel(f"{a}\n({cmp.stats[a].unit})", fontsize=7)
    ax[-1].set_xlabel("sample (flights concatenated; grey band: +-noise floor)")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _plot_acf_ccf(cmp: Comparison, path: Path):
    plt = _plt()
    axes = cmp.axes
    fig, ax = plt.subplots(len(axes), 2, figsize=(11, 1.7 * len(axes) + 0.8))
    ax = np.atleast_2d(ax)
    for k, a in enumerate(axes):
        s = cmp.stats[a]
        ax[k, 0].plot(s.acf_lags, s.acf, lw=0.8)
        ax[k, 0].axhspan(-s.acf_band, s.acf_band, color="0.85")
        W = cmp.residuals[0].window * float(np.median(np.diff(cmp.residuals[0].t)))
        ax[k, 0].axvline(W, color="r", lw=0.5)
        ax[k, 0].set_ylabel(a, fontsize=7)
        for nm, rho in s.ccf_curves.items():
            ax[k, 1].plot(s.ccf_lags, rho, lw=0.6, label=nm)
        band = max(v[2] for v in s.ccf.values())
        ax[k, 1].axhspan(-band, band, color="0.85")
    ax[0, 0].set_title("residual autocorrelation (red: filter window)", fontsize=8)
    ax[0, 1].set_title("cross-correlation with inputs and rates (grey: band)", fontsize=8)
    ax[0, 1].legend(fontsize=5, ncol=4)
    ax[-1, 0].set_xlabel("lag (s)")
    ax[-1, 1].set_xlabel("lag (s), positive: residual follows the input")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _plot_where(cmp: Comparison, path: Path, other: Comparison | None = None):
    plt = _plt()
    fig, ax = plt.subplots(2, 3, figsize=(12, 6.5))
    for k, v in enumerate(BIN_VARIABLES):
        a_ = ax.flat[k]
        for src, style in ((cmp, "-o"), (other, ":x")):
            if src is None:
                continue
            t = src.where["tables"][v]
            x = np.array(t["centers"])
            cnt = np.array(t["count"])
            for j, a in enumerate(src.axes):
                y = np.array(t[a]["rms"], dtype=float) / src.noise[a]
                y[cnt < 10] = np.nan
                a_.plot(x, y, style, ms=3, lw=0.8, color=f"C{j}",
                        label=a if src is cmp else None)
        a_.axhline(1.0, color="k", lw=0.5)
        a_.set_xlabel(f"{v} ({BIN_VARIABLES[v][0]})")
        a_.set_ylabel("bin RMS / noise floor")
    ax.flat[0].legend(fontsize=6)
    title = "residual RMS by regime" + (" (solid: before, dotted: after)" if other else "")
    import textwrap

    fig.suptitle(title + "\n" + textwrap.fill(cmp.where["sentence"], 150), fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _plot_structure(cmp: Comparison, path: Path):
    """Block-averaged residual per azimuth bin with its 95 % interval, in noise floors."""
    plt = _plt()
    tab = cmp.structure_tables.get("azimuth", {})
    axes = [a for a in cmp.axes if a in tab]
    fig, ax = plt.subplots(len(axes), 1, figsize=(8, 1.4 * len(axes) + 1), sharex=True,
                           squeeze=False)
    for a_, a in zip(ax[:, 0], axes, strict=True):
        bm = tab[a]
        nf = cmp.noise[a]
        a_.errorbar(bm.centers, bm.mean / nf, yerr=1.96 * bm.se / nf, fmt="o", ms=3, lw=0.8)
        for f in cmp.structure:
            if f.axis == a and f.variable == "azimuth":
                a_.axvspan(f.lo % 360, f.lo % 360 + (f.hi - f.lo), color="r", alpha=0.15)
        a_.axhline(0.0, color="k", lw=0.5)
        a_.set_ylabel(f"{a}\n/ floor", fontsize=7)
    ax[-1, 0].set_xlabel("azimuth (deg)")
    title = ("residual averaged over revolutions (95 % intervals; shaded: significant)"
             + ("\n" + cmp.structure[0].sentence() if cmp.structure else ""))
    fig.suptitle(title, fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _plot_paper(p: PaperFits, out: Path) -> list[Path]:
    plt = _plt()
    paths = []
    fig, ax = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    ax[0].plot(p.airspeed, p.eta, ".", ms=1, alpha=0.3, label="eta_f (eq. 28)")
    order = np.argsort(p.airspeed)
    ax[0].plot(p.airspeed[order], p.momentum[order], "r.", ms=1,
               label=f"momentum theory eq. 29, A = {p.disk_area:.3g} m^2")
    ax[0].set_ylabel("T_hat / T_commanded")
    ax[0].legend(fontsize=7, markerscale=8)
    ax[0].set_title("thrust efficiency (paper Fig. 5)")
    ax[1].plot(p.airspeed, p.momentum, ".", ms=1, alpha=0.3)
    ax[1].set_ylabel("T / T_h (eq. 29)")
    ax[1].set_xlabel("airspeed (m/s)")
    fig.tight_layout()
    paths.append(out / "paper_thrust_efficiency.png")
    fig.savefig(paths[-1], dpi=90)
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(p.airspeed, p.drag, ".", ms=1, alpha=0.3, label="estimated drag (eq. 26)")
    v = np.linspace(0, p.airspeed.max(), 100)
    ax.plot(v, p.mu1 * v + p.mu2 * v * v, "r",
            label=f"fit (eq. 10): mu1 = {p.mu1:.4g}, mu2 = {p.mu2:.4g}")
    ax.set_xlabel("airspeed (m/s)")
    ax.set_ylabel("drag (N)")
    ax.set_title("drag identification (paper Fig. 6)")
    ax.legend(fontsize=7, markerscale=8)
    fig.tight_layout()
    paths.append(out / "paper_drag.png")
    fig.savefig(paths[-1], dpi=90)
    plt.close(fig)
    return paths


def _md_table(head, rows) -> list[str]:
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    out += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return out


def compare_json(cmp: Comparison, paper: PaperFits | None = None) -> dict:
    d = cmp.to_json()
    if paper is not None:
        d["paper_sec_v_c"] = paper.to_json()
    return d


def write_compare(cmp: Comparison, out_dir, paper: PaperFits | None = None,
                  prefix: str = "compare") -> list[Path]:
    """Write the report of a comparison: Markdown with PNG plots, and every number in JSON.

    The files of ``gainsched compare -o OUT_DIR``: ``PREFIX.md`` (the per-axis table,
    where the model fails, the structure averaged over revolutions, the residual by
    regime as RMS over the noise floor per bin, the reading notes), ``PREFIX.json``
    (every number, :func:`compare_json`) and the plots ``PREFIX_residuals.png``
    (residual time series with the noise band), ``PREFIX_acf_ccf.png``
    (autocorrelation and input cross-correlation), ``PREFIX_where.png`` (residual by
    regime) and ``PREFIX_structure.png`` (binned structure); with ``paper``, also the
    paper's Figs. 5 and 6 (thrust efficiency, drag fit).

    Parameters
    ----------
    cmp : Comparison
        The comparison to report (:func:`~gainsched.analysis.compare.compare`).
    out_dir : str or path-like
        Directory to write into, made if missing; files of the same names are replaced.
    paper : PaperFits, optional
        The paper's analyses of Sec. V.C on the same logs
        (:func:`gainsched.analysis.paperfits.paper_fits`): adds their section and plots.
    prefix : str, default "compare"
        The files' common name.

    Returns
    -------
    list of Path
        The files written: the JSON, the Markdown, then the plots.

    Examples
    --------
    >>> import tempfile
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> cmp = gs.compare(cfg, ["examples/flights/v9.csv", "examples/flights/v15.csv"])
    >>> out = tempfile.mkdtemp()
    >>> paths = gs.write_compare(cmp, out)
    >>> [p.name for p in paths]
    ['compare.json', 'compare.md', 'compare_residuals.png', 'compare_acf_ccf.png',
     'compare_where.png', 'compare_structure.png']
    >>> import json
    >>> report = json.loads(paths[0].read_text())  # RMS over the noise floor, per axis
    >>> {axis: round(report["axes"][axis]["rms_over_noise"], 1) for axis in cmp.axes}
    {'tangential': 4.5, 'normal': 7.8, 'radial': 1.1, 'roll': 12.6, 'pitch': 1.4,
     'yaw': 1.0, 'stretch': 1.0}
    """
    from ..publish import write_atomic

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = [write_json(out / f"{prefix}.json", compare_json(cmp, paper))]
    pics = {"residuals": out / f"{prefix}_residuals.png", "corr": out / f"{prefix}_acf_ccf.png",
            "where": out / f"{prefix}_where.png",
            "structure": out / f"{prefix}_structure.png"}
    _plot_structure(cmp, pics["structure"])
    _plot_residuals(cmp, pics["residuals"])
    _plot_acf_ccf(cmp, pics["corr"])
    _plot_where(cmp, pics["where"])
    paths += list(pics.values())
    md = [f"# Model versus measurement: {cmp.config.name}", "", _header(cmp) + ".", ""]
    head, rows = _axis_table(cmp)
    md += _md_table(head, rows)
    md += ["", f"Normalised RMS (1 = measurement noise): {cmp.normalized_rms():.3f}.", "",
           "## Where it fails", "", cmp.where["sentence"] + ".", "",
           f"![residual by regime]({pics['where'].name})", "",
           "## Structure averaged over revolutions", "",
           *([f"- {f.sentence()}" for f in cmp.structure]
             or ["No significant residual in azimuth, airspeed, thrust or time bins."]), "",
           f"![structure]({pics['structure'].name})", "",
           f"![residuals]({pics['residuals'].name})", "",
           "## Whiteness and input correlation", "",
           f"![acf and ccf]({pics['corr'].name})", ""]
    md += ["## Residual by regime (RMS / noise floor per bin)", ""]
    for v, t in cmp.where["tables"].items():
        unit = BIN_VARIABLES[v][0]
        head = [f"{v} ({unit})", "samples", *cmp.axes]
        rws = []
        for i in range(len(t["centers"])):
            rws.append([f"{t['edges'][i]:.3g}..{t['edges'][i + 1]:.3g}", t["count"][i],
                        *(_g(t[a]["rms"][i] / cmp.noise[a], 3) for a in cmp.axes)])
        md += _md_table(head, rws) + [""]
    if paper is not None:
        pp = _plot_paper(paper, out)
        paths += pp
        md += ["## The paper's analyses (Sec. V.C)", ""] + [f"- {ln}" for ln in _paper_lines(paper)]
        md += ["", f"![thrust efficiency]({pp[0].name})", "", f"![drag]({pp[1].name})", ""]
    if cmp.notes:
        md += ["## Notes", ""] + [f"- {n}" for n in cmp.notes] + [""]
    write_atomic(out / f"{prefix}.md", "\n".join(md).encode())
    paths.insert(1, out / f"{prefix}.md")
    return paths


# --------------------------------------------------------------------------- before / after


def _ba_rows(before: Comparison, after: Comparison):
    rows = []
    for a in before.axes:
        if a not in after.stats:
            continue
        b, f = before.stats[a], after.stats[a]
        change = 100 * (f.rms / b.rms - 1) if b.rms > 0 else 0.0
        rows.append((a, b.unit, b.rms, f.rms, change, b.noise_floor, b.rms_over_noise,
                     f.rms_over_noise, b.white, f.white))
    return rows


def before_after_lines(before: Comparison, after: Comparison) -> list[str]:
    """Side-by-side table: RMS before and after, change, RMS/noise, whiteness."""
    out = [f"before: {before.config.name} ({before.config.source})",
           f"after:  {after.config.name} ({after.config.source})",
           "  axis       unit     RMS before  RMS after  change   noise     "
           "before/noise after/noise white before->after"]
    for a, u, rb, ra, ch, nf, qb, qa, wb, wa in _ba_rows(before, after):
        yn = {True: "yes", False: "no"}
        out.append(f"  {a:10s} {u:8s} {rb:10.4g} {ra:10.4g} {ch:+6.1f}%  {nf:9.3g} "
                   f"{qb:12.2f} {qa:11.2f} {yn[wb]} -> {yn[wa]}")
    out.append(f"  normalised RMS {before.normalized_rms():.3f} -> {after.normalized_rms():.3f}")
    out.append(f"  before: {before.where['sentence']}")
    out.append(f"  after:  {after.where['sentence']}")
    return out


def write_before_after(before: Comparison, after: Comparison, out_dir,
                       diagnosis: Diagnosis | None = None) -> list[Path]:
    """before_after.{json,md,png} and the regime plot with both models."""
    from ..publish import write_atomic

    plt = _plt()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rows = _ba_rows(before, after)
    data = {
        "before": {"config": before.config.source, "normalized_rms": before.normalized_rms(),
                   "where": before.where["sentence"]},
        "after": {"config": after.config.source, "normalized_rms": after.normalized_rms(),
                  "where": after.where["sentence"]},
        "axes": {r[0]: {"unit": r[1], "rms_before": r[2], "rms_after": r[3],
                        "change_percent": r[4], "noise_floor": r[5],
                        "rms_over_noise_before": r[6], "rms_over_noise_after": r[7],
                        "white_before": r[8], "white_after": r[9]} for r in rows},
    }
    if diagnosis is not None and diagnosis.accepted is not None:
        acc = diagnosis.accepted
        data["heldout"] = {"candidate": acc.name, "rms_reduction": acc.rms_reduction,
                           "excess_explained": acc.excess_explained,
                           "axis_rms_normalised_before": acc.axis_rms_before,
                           "axis_rms_normalised_after": acc.axis_rms_after}
    paths = [write_json(out / "before_after.json", data)]
    fig, ax = plt.subplots(figsize=(8, 4))
    x = np.arange(len(rows))
    ax.bar(x - 0.2, [r[6] for r in rows], 0.4, label=f"before ({before.config.name})")
    ax.bar(x + 0.2, [r[7] for r in rows], 0.4, label=f"after ({after.config.name})")
    ax.axhline(1.0, color="k", lw=0.6)
    ax.set_xticks(x, [r[0] for r in rows])
    ax.set_ylabel("RMS / noise floor")
    ax.set_title("residual before and after")
    ax.legend(fontsize=7)
    fig.tight_layout()
    pic = out / "before_after.png"
    fig.savefig(pic, dpi=90)
    plt.close(fig)
    pic2 = out / "before_after_where.png"
    _plot_where(before, pic2, other=after)
    paths += [pic, pic2]
    md = ["# Before and after", "", f"- before: `{before.config.source}`",
          f"- after: `{after.config.source}`", ""]
    head = ("axis", "unit", "RMS before", "RMS after", "change", "noise floor",
            "RMS/noise before", "RMS/noise after", "white before", "white after")
    md += _md_table(head, [(r[0], r[1], _g(r[2], 4), _g(r[3], 4), f"{r[4]:+.1f}%", _g(r[5]),
                            f"{r[6]:.2f}", f"{r[7]:.2f}", r[8], r[9]) for r in rows])
    md += ["", f"Normalised RMS {before.normalized_rms():.3f} -> {after.normalized_rms():.3f} "
           "(1 = measurement noise).", "", f"Before: {before.where['sentence']}.", "",
           f"After: {after.where['sentence']}.", ""]
    if "heldout" in data:
        h = data["heldout"]
        md += [f"Held out (leave-one-flight-out, {h['candidate']}): normalised RMS "
               f"-{100 * h['rms_reduction']:.0f}%, "
               f"{100 * h['excess_explained']:.0f}% of the residual above noise "
               "explained.", ""]
    md += [f"![before and after]({pic.name})", "", f"![by regime]({pic2.name})", ""]
    write_atomic(out / "before_after.md", "\n".join(md).encode())
    paths.insert(1, out / "before_after.md")
    return paths


# --------------------------------------------------------------------------- diagnose


def _rank_rows(d: Diagnosis):
    rows = []
    for r in d.results:
        vals = r.law if r.empirical else ", ".join(
            f"{p.name}={v:.4g}+-{c:.2g}" for p, v, c in zip(r.params, r.theta, r.ci, strict=True))
        rows.append((r.name, f"{100 * r.rms_reduction:.1f}%",
                     "n/a" if not np.isfinite(r.excess_explained)
                     else f"{100 * r.excess_explained:.0f}%",
                     "-" if r.structure_reduction is None
                     else f"{100 * r.structure_reduction:.0f}%",
                     f"{r.delta_bic:.0f}", "yes" if r.plausible else "no",
                     _g(r.fold_spread, 2), "PASS" if r.passes else "-", vals))
    return ("candidate", "held-out RMS", "excess expl.", "structure", "dBIC", "plausible",
            "fold spread", "verdict", "parameters (95% CI) or law"), rows


def diagnose_lines(d: Diagnosis) -> list[str]:
    """Terminal summary: ranking table, notes, verdict."""
    head, rows = _rank_rows(d)
    out = [f"diagnose {d.config.name} on {len(d.flights)} flights "
           f"({', '.join(d.flights)}); {d.evaluations} model evaluations"]
    w = [18, 12, 12, 9, 8, 9, 11, 7]
    out += _text_table(head, rows, w)
    for r in d.results:
        for n in r.notes:
            if r.rms_reduction >= THRESHOLDS["min_rms_reduction"]:
                out.append(f"  note ({r.name}): {n}")
    # why the candidates that explain something fail (all of them: diagnose.md)
    out += [f"  fails ({r.name}): {'; '.join(r.failed())}" for r in d.results
            if r.rms_reduction > 0 and not r.passes]
    out.append(f"verdict: {d.verdict}")
    return out


def write_diagnose(d: Diagnosis, out_dir) -> list[Path]:
    """Write the report of a diagnosis: Markdown with the ranking plot, and every number in JSON.

    The files of ``gainsched diagnose -o OUT_DIR``: ``diagnose.md`` (the flights, the
    verdict, the ranking table with each candidate's fitted values and held-out scores,
    the thresholds, the candidates' notes), ``diagnose.json`` (every number,
    ``Diagnosis.to_json()``) and ``ranking.png`` (held-out RMS reduction and residual
    above noise explained, %, per candidate).

    Parameters
    ----------
    d : Diagnosis
        The diagnosis to report (:func:`~gainsched.analysis.diagnose.diagnose`).
    out_dir : str or path-like
        Directory to write into, made if missing; files of the same names are replaced.

    Returns
    -------
    list of Path
        ``[out_dir / "diagnose.json", out_dir / "diagnose.md", out_dir / "ranking.png"]``.

    Examples
    --------
    Two flights and two candidates (the example flights' motor lag left out: the
    momentum-theory fit leaves its structure, so none is accepted):

    >>> import tempfile
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> logs = ["examples/flights/v9.csv", "examples/flights/v15.csv"]
    >>> d = gs.diagnose(cfg, logs, candidates=["drag_quadratic", "thrust_momentum"])
    >>> out = tempfile.mkdtemp()
    >>> paths = gs.write_diagnose(d, out)
    >>> [p.name for p in paths]
    ['diagnose.json', 'diagnose.md', 'ranking.png']
    >>> print(paths[1].read_text()[:200])
    # Which effect is missing: paper
    <BLANKLINE>
    Flights: sim-v9, sim-v15.
    <BLANKLINE>
    **Verdict:** no library effect explains it: ...
    """
    from ..publish import write_atomic

    plt = _plt()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = [write_json(out / "diagnose.json", d.to_json())]
    fig, ax = plt.subplots(figsize=(8, 4))
    names = [r.name for r in d.results]
    y = np.arange(len(names))
    ax.barh(y - 0.2, [100 * r.rms_reduction for r in d.results], 0.4,
            label="held-out RMS reduction")
    ax.barh(y + 0.2, [100 * (r.excess_explained if np.isfinite(r.excess_explained) else 0)
                      for r in d.results], 0.4, label="residual above noise explained")
    ax.set_yticks(y, names, fontsize=7)
    ax.invert_yaxis()
    ax.axvline(100 * THRESHOLDS["min_excess_explained"], color="r", lw=0.6)
    ax.set_xlabel("%")
    ax.legend(fontsize=7)
    ax.set_title("candidate effects (leave-one-flight-out)")
    fig.tight_layout()
    pic = out / "ranking.png"
    fig.savefig(pic, dpi=90)
    plt.close(fig)
    paths.append(pic)
    head, rows = _rank_rows(d)
    md = [f"# Which effect is missing: {d.config.name}", "",
          f"Flights: {', '.join(d.flights)}.", "", f"**Verdict:** {d.verdict}.", ""]
    md += _md_table(head, rows)
    md += ["", "Thresholds: " + ", ".join(f"{k} = {v:g}" for k, v in THRESHOLDS.items()), "",
           f"![ranking]({pic.name})", ""]
    fails = [f"- {r.name}: {'; '.join(r.failed())}" for r in d.results if not r.passes]
    if fails:
        md += ["## Thresholds each failing candidate misses", "", *fails, ""]
    notes = [f"- {r.name}: {n}" for r in d.results for n in r.notes]
    if notes:
        md += ["## Notes", "", *notes, ""]
    write_atomic(out / "diagnose.md", "\n".join(md).encode())
    paths.insert(1, out / "diagnose.md")
    return paths
