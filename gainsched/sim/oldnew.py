"""The standard flights flown with an old and a new table on one plant (``gainsched
improve``'s before/after of the tracking).

After the model loop has improved a config and the tables have been rebuilt from it, the
question a user flies for is whether the new tables fly the vehicle better than the old
ones. :func:`fly_old_new` answers it in simulation: the standard flights of a campaign
(:func:`gainsched.sim.campaign.default_flights`: level circles 3-15 m/s, 8 m/s at 20 deg,
7 m/s at 40 deg, a speed-up and a braking, motion-capture noise) are flown on one plant,
the improved model by default (the best available stand-in for the vehicle), once by the
old controller (the original config's nominal and its table) and once by the new one (the
improved config's nominal and the rebuilt table), each flight with the same sensor noise.
Each flight is what ``gainsched simulate`` flies (:func:`gainsched.sim.loop.simulate`,
the gains through :func:`gainsched.sim.loop.table_scheduler` as ``gainsched campaign``
looks them up) and is scored by :func:`gainsched.sim.loop.metrics` (what
``metrics.json`` holds). Flights outside either table's speeds or tilts are not flown
(they would test the gains of the table's edge, not the table), and neither is a flight
where a table has no usable gains at the start or the design model no nominal; a flight
whose nominal under either model needs a motor thrust outside the vehicle's range over
more than :data:`BEYOND_SHARE` of it is flown but not compared (both controllers
saturate: it tells nothing of the tables). All are listed with the reason.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from .campaign import default_flights, outside_table
from .loop import metrics, simulate, table_scheduler

__all__ = ["BEYOND_SHARE", "METRICS", "N_FLIGHTS", "FlightPair", "OldNewFlights", "fly_old_new"]

#: how many standard flights there are (each flown twice)
N_FLIGHTS = len(default_flights())

#: the metrics of :func:`gainsched.sim.loop.metrics` the comparison reports: name ->
#: (label, unit of the report, factor from the metric's SI unit to it)
METRICS = {
    "rms_along_track_m": ("RMS along-track", "m", 1.0),
    "rms_out_of_plane_m": ("RMS out-of-plane", "m", 1.0),
    "rms_speed_error_mps": ("RMS speed error", "m/s", 1.0),
    "final_azimuth_error_rad": ("final azimuth error", "deg", 180.0 / math.pi),
    "saturation_fraction": ("saturated", "%", 100.0),
    "slack_events": ("slack", "", 1.0),
}
#: the share of a flight over which a nominal may need a motor thrust beyond the vehicle's
#: range and the flight still be compared: a few control steps (a motor lag's lead at the
#: start of a manoeuvre) saturate briefly and leave the tracking to the gains; beyond it
#: the errors are the saturation's, whichever table flies
BEYOND_SHARE = 0.05
#: the metrics whose all-flight figure is the RMS over the flights (the others: the largest
#: magnitude, except slack events: their count)
_RMS_OVER_FLIGHTS = ("rms_along_track_m", "rms_out_of_plane_m", "rms_speed_error_mps",
                     "final_azimuth_error_rad")


def _ratio(old: float, new: float) -> float | None:
    """``new / old``; None when the old is 0 (nothing to compare with)."""
    return float(new / old) if old != 0 else None


@dataclass(frozen=True)
class FlightPair:
    """One standard flight flown with both tables.

    Attributes
    ----------
    name : str
        The flight (a name of :func:`gainsched.sim.campaign.default_flights`).
    old, new : dict
        The flight's :data:`METRICS` flown with the old and with the new table (SI units,
        as :func:`gainsched.sim.loop.metrics` names them).
    """

    name: str
    old: dict
    new: dict

    def ratio(self, key: str) -> float | None:
        """New over old of metric ``key`` (magnitudes); None when the old is 0."""
        return _ratio(abs(self.old[key]), abs(self.new[key]))


@dataclass(frozen=True, eq=False)
class OldNewFlights:
    """What :func:`fly_old_new` flew.

    Attributes
    ----------
    plant : str
        Name of the plant's config.
    plant_is_new : bool
        Whether the plant is the new design (the improved model), the default.
    duration : float
        Seconds per flight.
    flights : tuple of FlightPair
        The flights flown, in the order of the standard set.
    skipped : tuple of (str, str)
        The flights not flown, or flown but not compared, and why.
    meta : dict
        What the report says about the tables (paths, config hashes).
    """

    plant: str
    plant_is_new: bool
    duration: float
    flights: tuple
    skipped: tuple = ()
    meta: dict | None = None

    def summary(self) -> dict:
        """Per metric of :data:`METRICS`, ``{"old", "new", "ratio"}`` over all flights:
        the RMS over the flights of the RMS errors and of the final azimuth error (equal
        durations: the RMS of the whole time flown), the largest saturation, the number
        of slack events; empty when nothing was flown."""
        out = {}
        if not self.flights:
            return out
        for key in METRICS:
            both = {}
            for side in ("old", "new"):
                v = np.abs([getattr(f, side)[key] for f in self.flights])
                both[side] = float(np.sqrt(np.mean(v**2)) if key in _RMS_OVER_FLIGHTS
                                   else v.sum() if key == "slack_events" else v.max())
            out[key] = {**both, "ratio": _ratio(both["old"], both["new"])}
        return out

    def to_json(self) -> dict:
        """The comparison as JSON data (SI units, metric names of ``metrics.json``)."""
        return {
            "plant": self.plant,
            "plant_is_new_design": self.plant_is_new,
            "duration_s": self.duration,
            **(self.meta or {}),
            "summary": self.summary(),
            "flights": [{"name": f.name, "old": f.old, "new": f.new,
                         "ratio": {k: f.ratio(k) for k in METRICS}} for f in self.flights],
            "not_flown": [{"name": n, "reason": why} for n, why in self.skipped],
        }

    def lines(self) -> list[str]:
        """What ``gainsched improve`` prints: the tracking over all flights, old -> new
        (x new / old), and the flights not flown."""
        s = self.summary()
        if not s:
            return ["flights: none flown (" + "; ".join(f"{n}: {why}" for n, why in
                                                       self.skipped) + ")"]
        out = [f"flights on the {self._plant_text()}, old -> new table ({len(self.flights)} "
               f"flights of {self.duration:g} s; all: RMS over the flights):"]
        for key in _RMS_OVER_FLIGHTS:
            label, unit, f = METRICS[key]
            r = s[key]["ratio"]
            out.append(f"  {label} {s[key]['old'] * f:.3g} -> {s[key]['new'] * f:.3g} {unit}"
                       + ("" if r is None else f" (x{r:.3g})"))
        if self.skipped:
            out.append("  not compared: " + ", ".join(n for n, _ in self.skipped))
        return out

    def _plant_text(self) -> str:
        return (f"improved model `{self.plant}`" if self.plant_is_new
                else f"plant `{self.plant}`")

    def markdown_lines(self) -> list[str]:
        """The comparison as a Markdown table: per flight and over all flights, each
        metric old / new (report units) and the ratio new / old of the tracking errors."""
        head = ["flight"]
        for key in METRICS:
            label, unit, _ = METRICS[key]
            head.append(f"{label}, {unit}: old / new" if unit and unit != "%" else
                        f"{label}{' %' if unit == '%' else ''}: old / new")
            if key in _RMS_OVER_FLIGHTS:
                head.append("new / old")
        lines = ["| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]

        def row(name, old, new, ratio):
            cells = [name]
            for key, (_, unit, f) in METRICS.items():
                if key == "slack_events":
                    cells.append(f"{int(old[key])} / {int(new[key])}")
                else:
                    o, n = abs(old[key]) * f, abs(new[key]) * f
                    cells.append(f"{o:.3g} / {n:.3g}" if unit != "%" else f"{o:.1f} / {n:.1f}")
                if key in _RMS_OVER_FLIGHTS:
                    r = ratio(key)
                    cells.append("-" if r is None else f"{r:.3g}")
            return "| " + " | ".join(cells) + " |"

        for fl in self.flights:
            lines.append(row(fl.name, fl.old, fl.new, fl.ratio))
        s = self.summary()
        if s:
            lines.append(row("**all**", {k: v["old"] for k, v in s.items()},
                             {k: v["new"] for k, v in s.items()}, lambda k: s[k]["ratio"]))
        return lines

    def plot(self, ax) -> None:
        """Bars of the RMS along-track and out-of-plane errors per flight, old (light)
        against new (dark), mm on a log scale, on the matplotlib axes ``ax``."""
        names = [f.name for f in self.flights]
        x = np.arange(len(names))
        w = 0.2
        bars = (("rms_along_track_m", "along-track", "tab:blue"),
                ("rms_out_of_plane_m", "out-of-plane", "tab:orange"))
        top = 1e-6
        for i, (key, label, color) in enumerate(bars):
            for j, side in enumerate(("old", "new")):
                v = [max(1000 * abs(getattr(f, side)[key]), 1e-6) for f in self.flights]
                top = max(top, *v)
                ax.bar(x + (2 * i + j - 1.5) * w, v, w, color=color, alpha=0.4 if j == 0 else 1,
                       label=f"{label}, {side} table")
        ax.set_yscale("log")
        ax.set_ylim(top=top * 30)  # room for the legend above the bars
        ax.set_xticks(x)
        ax.set_xticklabels(names, rotation=30, ha="right", fontsize=7)
        ax.set_ylabel("RMS tracking error, mm")
        ax.set_title(f"the standard flights on the {self._plant_text()}: old vs new table",
                     fontsize=9)
        ax.legend(fontsize=6, ncol=2)


def _beyond_the_motors(side: str, design, res) -> str | None:
    """Why a flight is not compared when ``design``'s nominal along it (the feed-forward
    ``res.u_d`` of its flight ``res``) needs a motor thrust outside the design vehicle's
    range over more than :data:`BEYOND_SHARE` of the flight; None otherwise."""
    v = design.vehicle
    out = np.any((res.u_d < v.thrust_min) | (res.u_d > v.thrust_max), axis=-1)
    if out.mean() <= BEYOND_SHARE:
        return None
    return (f"beyond the vehicle under the {side} model: its nominal needs motor thrust "
            f"outside {v.thrust_min:g}-{v.thrust_max:g} N over {100 * out.mean():.0f} % of "
            "the flight (both tables saturate)")


def fly_old_new(old_design, old_table, new_design, new_table, plant=None, *,
                duration: float = 3.0, seed: int = 1, progress=None,
                meta: dict | None = None) -> OldNewFlights:
    """Fly the standard flights on one plant with the old and with the new table.

    Parameters
    ----------
    old_design : Config
        The config the old table was built from (the original model): the old
        controller's nominal.
    old_table : Table
        The old gain table.
    new_design : Config
        The config the new table was built from (the improved model).
    new_table : Table
        The new gain table.
    plant : Config, optional
        The truth flown (default: ``new_design``, the improved model).
    duration : float
        Seconds per flight (the manoeuvres of the speed-up and the braking start at
        0.6 s).
    seed : int
        Seed of the sensor noise of the first flight (each next flight the next seed),
        as ``gainsched campaign --seed``; both tables fly the same noise.
    progress : callable, optional
        ``progress(n)`` after each flight flown (n = 1) or not flown: two per standard
        flight in all (:data:`N_FLIGHTS` of them).
    meta : dict, optional
        Facts about the tables for the report (paths, config hashes), kept as given.

    Returns
    -------
    OldNewFlights
        The flights flown with their metrics, and those not flown with the reason.
    """
    plant_is_new = plant is None
    plant = new_design if plant is None else plant
    flights = default_flights(duration, seed)
    outside = set(outside_table(flights, old_table)) | set(outside_table(flights, new_table))
    old_sched, new_sched = table_scheduler(old_table), table_scheduler(new_table)
    step = progress if progress is not None else (lambda n: None)
    pairs, skipped = [], []
    for scn in flights:
        if scn.name in outside:
            skipped.append((scn.name, "outside the tables' speeds or tilts"))
            step(2)
            continue
        flown, beyond = [], None
        try:
            for side, design, sched in (("old", old_design, old_sched),
                                        ("new", new_design, new_sched)):
                res = simulate(design, sched, scn, plant)
                flown.append(metrics(res))
                beyond = beyond or _beyond_the_motors(side, design, res)
                step(1)
        except InputError as e:  # no usable gains where it starts, or no nominal along it
            skipped.append((scn.name, e.message))
            step(2 - len(flown))
            continue
        if beyond:  # a comparison of two saturating flights says nothing of the tables
            skipped.append((scn.name, beyond))
            continue
        old, new = flown
        pairs.append(FlightPair(scn.name, {k: old[k] for k in METRICS},
                                {k: new[k] for k in METRICS}))
    return OldNewFlights(plant.name, plant_is_new, float(duration), tuple(pairs),
                         tuple(skipped), meta)
