"""The next flight of a diagnosis (``gainsched plan``)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ._report import SILENT, Reporter, config_of
from ._tables import table_for

__all__ = ["Planned", "plan", "read_report"]


@dataclass(frozen=True, eq=False)
class Planned:
    """What :func:`plan` proposed and wrote.

    Attributes
    ----------
    plan : Plan
        The flights, best first (:class:`gainsched.sim.plan.Plan`).
    out_dir : Path or None
        Where the plan was written.
    """

    plan: object
    out_dir: Path | None

    def lines(self) -> list[str]:
        """What ``gainsched plan`` prints: the table, then what was written."""
        out = self.plan.lines()
        if self.out_dir is not None:
            n = len(self.plan.flights)
            out.append(f"wrote {self.out_dir}: plan.md, plan.json, and per flight NN.toml "
                       f"(gainsched simulate) and NN-reference.csv ({n} flights)")
        return out


def read_report(path) -> tuple[dict, Path]:
    """A diagnose report's JSON: ``diagnose.json``, or the report folder holding it.

    Raises
    ------
    InputError
        Naming the file: missing, unreadable or not JSON.
    """
    p = Path(path)
    if p.is_dir():
        p = p / "diagnose.json"
    try:
        data = json.loads(p.read_text(encoding="utf-8"))
    except OSError as exc:
        raise InputError(p, "", f"cannot read ({exc.strerror or exc}): give a diagnose "
                         "report (diagnose.json, or the folder of diagnose --report)") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(p, "", f"not a diagnose report (not JSON: {exc})") from None
    if not isinstance(data, dict) or "candidates" not in data:
        raise InputError(p, "candidates", "not a diagnose report (no candidates): give the "
                         "diagnose.json of diagnose --report")
    return data, p


def _reference_csv(scn, dt: float, r: float) -> bytes:
    """``t, xi_ref, xi_dot_ref, xi_ddot_ref`` at the control step: the reference a
    firmware controller is given each step."""
    from ..sim.loop import profile_path

    t = np.arange(int(round(scn.duration / dt)) + 1) * dt
    path = profile_path(scn, r, t)
    rows = np.stack([t, path.xi, path.d[0], path.d[1]], -1)
    head = ("# the reference of gainsched plan's flight: azimuth (rad), its rate (rad/s) and "
            f"acceleration (rad/s^2) at the control step {dt:g} s; {scn.name}\n"
            "t,xi_ref,xi_dot_ref,xi_ddot_ref\n")
    body = "".join(",".join(repr(float(x)) for x in row) + "\n" for row in rows)
    return (head + body).encode()


def plan(config, report, out_dir=None, *, duration: float = 10.0,
         reporter: Reporter = SILENT) -> Planned:
    """Propose the flights that would settle a diagnosis: what ``gainsched plan CONFIG
    REPORT -o DIR`` does (:mod:`gainsched.sim.plan`, docs/model-vs-measurement.md).

    Parameters
    ----------
    config : Config or path-like
        The config the report diagnosed (its table flies the flights).
    report : path-like or dict
        The diagnose report (``diagnose.json`` or its folder), or its data.
    out_dir : path-like, optional
        Where to write ``plan.md``, ``plan.json`` and per flight ``NN.toml`` and
        ``NN-reference.csv``, published at once; None: nothing written.
    duration : float
        Seconds per flight.
    reporter : Reporter, optional
        Shows the flights' progress; default: nothing.

    Returns
    -------
    Planned

    Examples
    --------
    >>> try:
    ...     gs.studies.plan("configs/paper.toml", "no-report/")
    ... except gs.InputError as e:
    ...     print(str(e).split(" (")[0])
    no-report: cannot read
    """
    from ..model.reduced import Model
    from ..publish import check_out_dir, publish
    from ..sim.loop import scenario_text
    from ..sim.plan import menu, plan_flights

    cfg = config_of(config)
    data, source = (report, "report") if isinstance(report, dict) else read_report(report)
    if out_dir is not None:
        out_dir = Path(out_dir)
        check_out_dir(out_dir, names=["plan.md", "plan.json"])
    table, _ = table_for(cfg, reporter=reporter)
    n = len(menu(table, duration))
    with reporter.bar(f"plan {cfg.name}", n, "flight") as bar:
        p = plan_flights(cfg, data, table, duration=duration, source=str(source),
                         progress=bar.update)
    if out_dir is not None:
        r = Model(cfg).r
        files = {"plan.md": p.markdown().encode(),
                 "plan.json": (json.dumps(p.to_json(), indent=1) + "\n").encode()}
        for i, f in enumerate(p.flights, 1):
            files[f"{i:02d}.toml"] = scenario_text(f.scenario).encode()
            files[f"{i:02d}-reference.csv"] = _reference_csv(f.scenario, cfg.control.dt, r)
        publish(out_dir, files)
    return Planned(p, out_dir)
