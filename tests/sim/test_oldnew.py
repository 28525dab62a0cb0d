"""The standard flights flown with an old and a new table (gainsched/sim/oldnew.py).

- the figures over all flights: the RMS over the flights of the RMS errors and of the
  final azimuth error, the largest saturation, the slack events counted; ratios new / old,
  None where the old is 0;
- the report's lines (Markdown, the command's) and JSON carry them;
- flown on small tables: flights outside the tables are not flown and said so, each
  flight is scored by simulate's metrics, and the same table twice gives ratios of 1;
- a flight whose nominal needs a thrust beyond the motors is not compared, and says so.
"""

from __future__ import annotations

import json
import math

import pytest

from gainsched.sim.oldnew import METRICS, N_FLIGHTS, FlightPair, OldNewFlights, fly_old_new


def _m(**kw):
    base = dict.fromkeys(METRICS, 0.0)
    base.update(kw)
    return base


def test_the_figures_over_all_flights():
    a = FlightPair("a", _m(rms_along_track_m=0.3, final_azimuth_error_rad=-0.4,
                           saturation_fraction=0.1, slack_events=1),
                   _m(rms_along_track_m=0.03, final_azimuth_error_rad=0.04))
    b = FlightPair("b", _m(rms_along_track_m=0.4, final_azimuth_error_rad=0.3),
                   _m(rms_along_track_m=0.04, saturation_fraction=0.2))
    fl = OldNewFlights("p", True, 2.0, (a, b), (("c", "outside the tables' speeds or tilts"),),
                       {"old_table": "old.h5"})
    s = fl.summary()
    assert s["rms_along_track_m"]["old"] == pytest.approx(math.sqrt((0.09 + 0.16) / 2))
    assert s["rms_along_track_m"]["ratio"] == pytest.approx(0.1)
    assert s["final_azimuth_error_rad"]["old"] == pytest.approx(math.sqrt((0.16 + 0.09) / 2))
    assert s["saturation_fraction"] == {"old": 0.1, "new": 0.2, "ratio": pytest.approx(2.0)}
    assert s["slack_events"] == {"old": 1.0, "new": 0.0, "ratio": 0.0}
    assert s["rms_out_of_plane_m"]["ratio"] is None and a.ratio("rms_out_of_plane_m") is None
    data = json.loads(json.dumps(fl.to_json()))  # JSON as written
    assert data["old_table"] == "old.h5" and data["plant_is_new_design"]
    assert [f["name"] for f in data["flights"]] == ["a", "b"]
    assert data["not_flown"] == [{"name": "c", "reason": "outside the tables' speeds or tilts"}]
    md = fl.markdown_lines()
    assert len(md) == 2 + 2 + 1 and md[-1].startswith("| **all** | 0.354 / 0.0354 | 0.1 |")
    assert fl.lines()[0].startswith("flights on the improved model `p`, old -> new table (2 ")
    assert "  RMS along-track 0.354 -> 0.0354 m (x0.1)" in fl.lines()
    assert fl.lines()[-1] == "  not compared: c"
    assert OldNewFlights("p", False, 2.0, ()).summary() == {}


@pytest.fixture(scope="module")
def small(small_config):
    """The small config (6-9 m/s, 0-20 deg) and its table, built here."""
    from gainsched.model.reduced import Model
    from gainsched.schedule.grid import build_grid
    from gainsched.schedule.tables import table_bytes, table_from_bytes

    cfg = small_config()
    return cfg, table_from_bytes(table_bytes(cfg, build_grid(cfg), Model(cfg)))


def test_the_same_table_twice_flies_the_same_inside_the_tables(small):
    cfg, table = small
    steps = []
    fl = fly_old_new(cfg, table, cfg, table, duration=1.0, progress=steps.append)
    assert sum(steps) == 2 * N_FLIGHTS
    assert [f.name for f in fl.flights] == ["v9", "tilt20-v8"]
    assert {n for n, _ in fl.skipped} == {"v3", "v15", "tilt40-v7", "speedup", "braking"}
    for f in fl.flights:
        assert f.old == f.new and f.ratio("rms_along_track_m") == 1.0
        assert 0 < f.old["rms_along_track_m"] < 0.01  # the design plant: tracked
    assert fl.plant == cfg.name and fl.plant_is_new and fl.duration == 1.0


def test_a_flight_beyond_the_motors_is_not_compared(small):
    """A new model under which a flight's nominal needs more thrust than the motors give
    (here: the same vehicle with weaker motors) is flown but not compared: two saturating
    flights say nothing of the tables; the flights inside the motors' range still are."""
    from gainsched.config import config_from_text
    from gainsched.sim.campaign import default_flights
    from gainsched.sim.loop import simulate, table_scheduler

    cfg, table = small
    v9 = next(s for s in default_flights(1.0) if s.name == "v9")
    need = simulate(cfg, table_scheduler(table), v9).u_d.max()
    weak = config_from_text(cfg.text.replace(f"thrust_max = {cfg.vehicle.thrust_max:g}",
                                             f"thrust_max = {need - 0.05:.3f}"), "weak")
    assert weak.vehicle.thrust_max < need
    fl = fly_old_new(cfg, table, weak, table, duration=1.0)
    why = dict(fl.skipped)
    assert why["v9"].startswith("beyond the vehicle under the new model: its nominal needs "
                                f"motor thrust outside {weak.vehicle.thrust_min:g}-")
    for f in fl.flights:  # what is compared stays inside the weaker motors
        scn = next(s for s in default_flights(1.0) if s.name == f.name)
        assert simulate(weak, table_scheduler(table), scn).u_d.max() <= weak.vehicle.thrust_max
