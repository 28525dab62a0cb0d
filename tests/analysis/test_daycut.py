"""A flight day cut into flights (issue 55): gainsched/analysis/logs/_daycut.py.

The day is built as a lab's is: 5 s on the ground, a take-off onto the sphere, a
simulated flight of 30 s (6 m/s at 20 deg tilt, heading 30 deg, a speed-up to 10 m/s at
8 s and a braking to 5 m/s at 18 s), a transition, a simulated level circle at 8 m/s
for 12 s, a landing, 5 s on the ground; 100 Hz, the pose and the commanded thrusts. The
take-off, the transition and the landing are drawn (a smooth path, thrust ramps), the
flights are the closed-loop simulator's. The cut must find the circles and the
manoeuvres with their speeds and planes, and drop the rest with its reason.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from gainsched.analysis.logs._daycut import cut_day

RATE = 100.0


def _bridge(p0, p1, v0, v1, seconds):
    """A cubic Hermite path from (p0, v0) to (p1, v1) over ``seconds``, at RATE."""
    s = np.arange(1, int(seconds * RATE) + 1) / (seconds * RATE)
    h = seconds
    h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
    h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
    return (h00[:, None] * p0 + h10[:, None] * h * v0 + h01[:, None] * p1
            + h11[:, None] * h * v1)


@pytest.fixture(scope="module")
def day(paper_config, paper_table):
    """``(t, p_I, T_cmd, truth)``: the day at 100 Hz and the pieces it was built of."""
    from gainsched.sim.loop import Maneuver, Scenario, simulate, table_scheduler

    sched = table_scheduler(paper_table)
    one = simulate(paper_config, sched, Scenario(
        "one", math.radians(20.0), 6.0, 30.0, gamma=math.radians(30.0),
        maneuvers=(Maneuver(8.0, 10.0, 2.0), Maneuver(18.0, 5.0, 2.0))))
    two = simulate(paper_config, sched, Scenario("two", 0.0, 8.0, 12.0))
    w = paper_config.vehicle.mass * paper_config.g
    ground = np.array([1.0, 0.0, -0.2])
    parts, thrust = [], []

    def add(p, T):
        parts.append(p)
        thrust.append(np.broadcast_to(T, (p.shape[0], 4)) if np.ndim(T) < 2 else T)

    def flight(res):
        k = np.arange(0, res.t.size, int(round(1e-3 ** -1 / RATE)))
        return res.p_I[k], res.u[k], np.gradient(res.p_I[k], 1 / RATE, axis=0)

    p1, u1, v1 = flight(one)
    p2, u2, v2 = flight(two)
    add(np.repeat(ground[None], 500, 0), np.zeros(4))                  # ground 5 s
    add(_bridge(ground, p1[0], np.zeros(3), v1[0], 4.0), w / 4)        # take-off 4 s
    add(p1, u1)                                                         # flight one 30 s
    add(_bridge(p1[-1], p2[0], v1[-1], v2[0], 3.0), w / 4)             # transition 3 s
    add(p2, u2)                                                         # flight two 12 s
    add(_bridge(p2[-1], ground, v2[-1], np.zeros(3), 4.0), w / 4)      # landing 4 s
    add(np.repeat(ground[None], 500, 0), np.zeros(4))                  # ground 5 s
    p = np.concatenate(parts)
    T = np.concatenate(thrust)
    t = np.arange(p.shape[0]) / RATE + 1000.0
    starts = np.cumsum([0] + [q.shape[0] for q in parts]) / RATE + 1000.0
    return t, p, T, starts


def test_the_day_is_cut_into_its_circles_and_manoeuvres(day, paper_config):
    """Five flights kept: the three circles of flight one (6, 10 and 5 m/s at 20 deg,
    heading 30 deg) with the speed-up and the braking between them, and the level circle
    of flight two at 8 m/s; speeds within 0.15 m/s, planes within 1 deg; the ground,
    the take-off, the transition and the landing dropped, each saying why."""
    t, p, T, starts = day
    r = paper_config.tether.length + paper_config.tether.attachment_offset
    cut = cut_day(t, p, T, radius=r, weight=paper_config.vehicle.mass * paper_config.g)
    kept = cut.kept
    assert [q.kind for q in kept] == ["circle", "manoeuvre", "circle", "manoeuvre", "circle",
                                      "circle"], cut.lines()
    for q, (v0, v1, tilt) in zip(kept, [(6, 6, 20), (6, 10, 20), (10, 10, 20), (10, 5, 20),
                                         (5, 5, 20), (8, 8, 0)], strict=True):
        assert q.speed == pytest.approx(v0, abs=0.15), cut.lines()
        assert q.speed_end == pytest.approx(v1, abs=0.15), cut.lines()
        assert q.tilt_deg == pytest.approx(tilt, abs=1.0), cut.lines()
    assert kept[0].heading_deg == pytest.approx(30.0, abs=1.0)
    # the flights lie where they were flown: one in [starts[2], starts[3]), two after
    assert starts[2] <= kept[0].t0 and kept[4].t1 <= starts[3] + 0.01
    assert starts[4] <= kept[5].t0 and kept[5].t1 <= starts[5] + 0.01
    assert kept[5].t1 - kept[5].t0 > 10.0  # most of flight two
    dropped = [q for q in cut.pieces if not q.kept]
    assert dropped[0].kind == "ground" and dropped[-1].kind == "ground"
    assert all(q.why for q in dropped)
    assert not any(q.kept for q in cut.pieces if q.t1 < starts[2] or q.t0 > starts[5])
    assert cut.lines()[0] == "the day: 6 flights kept of " + str(len(cut.pieces)) + " pieces"
