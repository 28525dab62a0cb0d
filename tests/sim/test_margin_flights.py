"""The table's stability margins flown, not only computed (issue 56, docs/margins.md).

On three circles of the paper vehicle (a slow level one, the fast 40 deg one, and the
level circle a speed-up ends on) the nonlinear simulation flies the circle's own gains
(solved at 144 azimuths, interpolated in the azimuth) with ideal sensing:

- the feedback scaled by the gain margin's factor moved 10 % of the way back towards 1
  stays up, and scaled 10 % beyond it (0.9 times the factor) diverges;
- the commands delayed by 0.9 times the delay margin (``simulate(command_delay=...)``)
  stay up, and by 1.1 times it diverge.

"Stays up": no slack tether, the error envelope (the largest deviation of delta, xi,
phi, theta, chi from the nominal over a period) not growing over the second half of the
flight, and the motors saturated in less than a fifth of the last period. "Diverges":
the envelope at least doubling over the second half, or the motors saturated over half
the last period (a loop past its delay margin grows until the thrust limits hold it in a
limit cycle), or a slack tether. Each flight lasts at least 12 periods, and long enough
for the outside case's growth rate (log rho per period, from the margins' own kernel) to
double it twice over.

The paper's per-motor margins (stable with any one motor's feedback off) and its upper
margins (beyond +20 dB) have no crossing in the range searched: there is nothing to fly
just outside them.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import gainsched as gs
from gainsched.schedule import margins as mg
from gainsched.schedule.grid import solve_circle
from gainsched.sim._plant import DelayedCommands
from gainsched.sim._scenario import Sensing

#: (speed m/s, tilt deg): slow level, fast 40 deg, the speed-up scenario's final circle
CIRCLES = [(2.0, 0.0), (15.0, 40.0), (11.3, 0.0)]


@pytest.fixture(scope="module")
def cfg(paper_config):
    return paper_config.with_values({"grid.azimuth_samples": 144})


def _scheduler(sol, factor: float):
    """The circle's own gains (linear in the azimuth), times ``factor``."""
    K = sol.K[0]
    n_xi = K.shape[0]

    def gains(xi, xi_dot, alpha):
        pos = (xi % (2 * np.pi)) / (2 * np.pi) * n_xi
        j, w = int(pos) % n_xi, pos - int(pos)
        return factor * ((1 - w) * K[j] + w * K[(j + 1) % n_xi]), 0

    return gains


def _fly(cfg, sol, speed, tilt_deg, factor, delay, log_rho):
    """(late growth of the error envelope, saturated share of the last period, slack)."""
    T = sol.steps * sol.dt
    periods = int(min(400, max(12, np.ceil(4 * np.log(2) / abs(log_rho)))))
    scn = dataclasses.replace(gs.load_scenario("horizontal"), speed=speed,
                              tilt=np.radians(tilt_deg), duration=periods * T,
                              sensing=Sensing())
    res = gs.simulate(cfg, _scheduler(sol, factor), scn, command_delay=delay)
    err = np.abs(res.z - res.z_d)[:, [0, 1, 4, 5, 6]]
    per = int(round(T / cfg.control.dt))
    n = err.shape[0] // per
    env = err[: n * per].reshape(n, per, -1).max(axis=(1, 2))
    return env[-1] / env[n // 2], res.saturated[-per:].any(-1).mean(), res.slack_time


@pytest.mark.slow
@pytest.mark.parametrize(("speed", "tilt_deg"), CIRCLES, ids=["slow-level", "fast-40deg",
                                                              "speedup-end"])
def test_the_margins_fly_inside_and_diverge_outside(cfg, speed, tilt_deg):
    sol, (Ad, Bd, K) = solve_circle(cfg, speed, np.radians([tilt_deg]), keep_steps=True,
                                    dare_tilt0=False)
    g, tau = sol.gain_margin[0, 0], sol.delay_margin[0]
    assert 0 < g < 1 and 0.005 < tau < 0.05  # a crossing of each to fly past
    zero = np.zeros(1, int)
    rate_g = mg._gain_loops(Ad, Bd, K, zero, np.full((1, 4), 0.9 * g))[0]
    rate_d = mg._delay_loops(Ad, Bd, K, zero, np.array([1.1 * tau / sol.dt]))[0]
    assert rate_g > 0 and rate_d > 0
    for what, factor, delay, rate in (("gain", g + 0.1 * (1 - g), 0.0, rate_g),
                                      ("delay", 1.0, 0.9 * tau, rate_d)):
        growth, sat, slack = _fly(cfg, sol, speed, tilt_deg, factor, delay, rate)
        assert slack is None and growth <= 1.05 and sat < 0.2, (what, "inside", growth, sat)
    for what, factor, delay, rate in (("gain", 0.9 * g, 0.0, rate_g),
                                      ("delay", 1.0, 1.1 * tau, rate_d)):
        growth, sat, slack = _fly(cfg, sol, speed, tilt_deg, factor, delay, rate)
        assert slack is not None or growth >= 2 or sat >= 0.5, (what, "outside", growth, sat)


class _Recorder:
    """A plant that records the thrusts it is given."""

    def __init__(self):
        self.applied = []

    def step(self, x, u, alpha, dt):
        self.applied.append(np.array(u))
        return x, 1.0


def test_a_command_delay_applies_the_mix_of_two_held_commands():
    """``command_delay`` of 2.25 steps: the plant gets ``0.75 u_{k-2} + 0.25 u_{k-3}``, the
    commands before the first one being the first one (the delay of the margins)."""
    rec = _Recorder()
    plant = DelayedCommands(rec, 2.25)
    commands = [np.full(4, float(k + 1)) for k in range(6)]
    for u in commands:
        plant.step(None, u, 0.0, 0.001)
    got = [a[0] for a in rec.applied]
    want = [1.0, 1.0, 1.0, 0.75 * 2 + 0.25 * 1, 0.75 * 3 + 0.25 * 2, 0.75 * 4 + 0.25 * 3]
    assert got == pytest.approx(want, abs=1e-15)


def test_a_negative_command_delay_is_refused(paper_config):
    with pytest.raises(ValueError, match="command_delay must be >= 0 s"):
        gs.simulate(paper_config, lambda *a: (None, 0), gs.load_scenario("horizontal"),
                    command_delay=-0.001)
