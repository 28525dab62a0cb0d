"""Step 4 of the pipeline (:mod:`gainsched.analysis.compare`): the residual
``measured - predicted`` per axis of :data:`~gainsched.analysis.compare.AXES`, with the
binning variables and the inputs on the same samples.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import savgol_filter

from ...config import Config
from ...model.effects import wind_in_circle_frame
from ...model.reduced import Model
from ._axes import _INPUT_NAMES, AXES
from ._inputs import _load_cell
from ._measured import Measured
from ._predict import Prediction, _tether_stretch, predict


@dataclass(frozen=True, eq=False)
class Residual:
    """Measured, predicted and residual per axis for one segment, core samples only.

    ``measured``, ``predicted``, ``residual``: dict axis -> (n,) arrays, axes as in
    :data:`AXES` (``radial`` only with a load cell); ``variables``: dict of the
    :data:`BIN_VARIABLES` (n,) in their units; ``inputs``: dict name -> (n,) commanded
    (T_C N, tau_x/y/z N m) and their rates (``*_rate``).
    """

    name: str
    source: str
    t: np.ndarray
    measured: dict
    predicted: dict
    residual: dict
    variables: dict
    inputs: dict
    tension_source: str
    window: int

    @property
    def axes(self) -> tuple[str, ...]:
        return tuple(a for a in AXES if a in self.residual)

    def __len__(self):
        return int(self.t.size)



def residual_axes(model: Model, meas: Measured, latency: float | None = None,
                  axes: frozenset | None = None) -> dict:
    """Only the residual per axis (core samples) of one segment: the fast path for fits
    (equal to :func:`_residual`'s bit for bit). ``axes``: the caller needs only these
    (it knows the others unchanged); with a load cell ``{"stretch"}`` alone skips the
    prediction (the stretch depends on the link and the logged tension only)."""
    lat = model.config.analysis.latency_s if latency is None else latency
    c = meas.core
    if axes == {"stretch"} and meas.tension is not None:
        f_t = _load_cell(meas, lat)
        return {"stretch": meas.d[c] - model.rho
                - _tether_stretch(model.config, f_t, meas.dt, model.effects)[c]}
    pred = predict(model, meas, latency=lat, inputs=False, edges=False)
    acc_m = meas.acc_measured(lat)[c]
    out = {"tangential": acc_m[:, 0] - pred.acc[c, 0], "normal": acc_m[:, 1] - pred.acc[c, 1]}
    if pred.tension_source == "load cell":
        out["radial"] = acc_m[:, 2] - pred.acc[c, 2]
    wd = meas.omega_dot_measured(pred.latency)
    for j, ax in enumerate(("roll", "pitch", "yaw")):
        out[ax] = wd[c, j] - pred.omega_dot[c, j]
    out["stretch"] = meas.d[c] - model.rho - pred.stretch[c]
    return out


def _residual(model: Model, meas: Measured, pred: Prediction) -> Residual:
    c = meas.core
    acc_m = meas.acc_measured(pred.latency)
    measured = {"tangential": acc_m[c, 0], "normal": acc_m[c, 1]}
    predicted = {"tangential": pred.acc[c, 0], "normal": pred.acc[c, 1]}
    if pred.tension_source == "load cell":
        measured["radial"], predicted["radial"] = acc_m[c, 2], pred.acc[c, 2]
    wd = meas.omega_dot_measured(pred.latency)
    for j, ax in enumerate(("roll", "pitch", "yaw")):
        measured[ax], predicted[ax] = wd[c, j], pred.omega_dot[c, j]
    measured["stretch"] = meas.d[c] - model.rho
    predicted["stretch"] = pred.stretch[c]
    residual = {k: measured[k] - predicted[k] for k in measured}
    v_air = meas.v[c]
    if model.wind_I is not None:  # the model's wind: the speed relative to the air
        v_air = v_air - wind_in_circle_frame(model.wind_I, meas.alpha, meas.gamma)
    speed = np.linalg.norm(v_air, axis=-1)
    variables = {
        "airspeed": speed,
        "tilt": np.full(speed.shape, np.rad2deg(meas.alpha)),
        "azimuth": np.rad2deg(meas.z[c, 1]) % 360.0,
        "tension": pred.tension[c],
        "thrust": np.sum(meas.T_cmd[c], -1),
        "time": meas.t_flight[c],
    }
    inp = {}
    kw = dict(window_length=meas.window, polyorder=meas.order, axis=0, mode="interp")
    rates = savgol_filter(pred.inputs, deriv=1, delta=meas.dt, **kw)
    for j, nm in enumerate(_INPUT_NAMES):
        inp[nm] = pred.inputs[c, j]
        inp[nm + "_rate"] = rates[c, j]
    return Residual(meas.name, meas.source, meas.t[c], measured, predicted, residual, variables,
                    inp, pred.tension_source, meas.window)


def residuals(config: Config, measured, *, effects=None, latency=None,
              model: Model | None = None) -> list[Residual]:
    """Residuals of ``config`` (optionally with other ``effects``) on measured segments."""
    model = model or Model(config, effects)
    return [_residual(model, m, predict(model, m, latency=latency)) for m in measured]
