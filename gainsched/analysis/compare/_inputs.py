"""What the model takes from a log besides the pose: the commands at the sample times,
the load cell, and the states of its stateful effects (run along the log, or logged, like
``vbat``).
"""

from __future__ import annotations

import numpy as np

from ...errors import InputError
from ...model.effects import Effect
from ...model.reduced import Model
from ._measured import Measured, _delayed


def centred_commands(T):
    """Command at the sample time from interval-held commands (mean of the adjacent two)."""
    out = T.copy()
    out[:-1] = 0.5 * (T[:-1] + T[1:])
    return out


def _load_cell(meas: Measured, latency: float) -> np.ndarray:
    """The logged tension (N), delayed by ``latency`` s: on board, like the commands."""
    return _delayed(meas.t, meas.tension[:, None], latency)[:, 0]


def effect_states(eff: Effect, t, T_cmd, kin_fn=None) -> np.ndarray:
    """States of a stateful effect along the log, shape (N, n_states).

    Motor lag is discretised exactly for commands held over each interval
    (``x_k = a x_{k-1} + (1 - a) T_k``, ``a = exp(-dt/tau)``), started in its steady
    state; other stateful effects are integrated with explicit Euler sub-steps.
    """
    exact = eff.states_from_held_commands(t, T_cmd)
    if exact is not None:
        return exact
    x = np.zeros((len(t), eff.n_states))
    sub = 10
    for k in range(1, len(t)):
        xk = x[k - 1]
        h = (t[k] - t[k - 1]) / sub
        kin = kin_fn(k - 1)
        for _ in range(sub):
            xk = xk + h * eff.state_derivative(xk, T_cmd[k], kin)
        x[k] = xk
    return x


def has_channel(meas: Measured, channel: str) -> bool:
    """Whether the segment logged ``channel`` (an effect's ``log_channel``, e.g.
    ``"vbat"``) on every sample: what an effect that takes its states from it needs."""
    x = getattr(meas, channel, None)
    return x is not None and bool(np.all(np.isfinite(x)))


def logged_channel(meas: Measured, eff: Effect, latency: float) -> np.ndarray:
    """The samples of ``eff.log_channel`` (on board, like the commands: delayed by
    ``latency`` s onto the pose's clock), shape (N, ...). Raises InputError naming the
    log and the column when the segment lacks it or misses a sample
    (:func:`check_logged_channels` says so before any prediction)."""
    ch = eff.log_channel
    x = getattr(meas, ch, None)
    if not has_channel(meas, ch):
        what = ("has no such column" if x is None else
                f"misses sample {int(np.flatnonzero(~np.isfinite(x))[0]) + 1} of {x.size}")
        raise InputError(meas.source, f"column {ch}", f"the model's {eff.kind} takes its "
                         f"state from the logged {ch}, and segment {meas.name} {what}")
    x = np.asarray(x, float)
    return _delayed(meas.t, x.reshape(x.shape[0], -1), latency).reshape(x.shape)


def check_logged_channels(model: Model, measured, segs=None) -> None:
    """Every segment has the log columns the model's effects take their states from
    (``Effect.log_channel``: ``vbat`` for ``thrust_voltage``), on every sample; else
    InputError naming the file, the column and the first missing row."""
    for eff in model.effects:
        ch = eff.log_channel
        if not ch:
            continue
        for i, meas in enumerate(measured):
            if has_channel(meas, ch):
                continue
            x = getattr(meas, ch, None)
            seg = segs[i] if segs is not None and i < len(segs) else None
            if x is None:
                raise InputError(meas.source, f"column {ch}", f"missing: the model's "
                                 f"[effects.{eff.kind}] takes its state from the logged "
                                 f"{ch} (docs/flight-log.md)")
            k = int(np.flatnonzero(~np.isfinite(x))[0])
            row = f", {seg.where(k)}" if seg is not None else f", sample {k + 1}"
            raise InputError(meas.source, f"column {ch}{row}", f"missing sample: the model's "
                             f"[effects.{eff.kind}] takes its state from the logged {ch} "
                             "on every sample")
