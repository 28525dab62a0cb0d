"""The prediction: the model's accelerations for the measured state and the logged
commands, put through the filter the measurement went through (:func:`predict`).

Step 3 of the pipeline that :mod:`gainsched.analysis.compare` describes (the thrust,
gravity, effects and tether of paper eqs. 3, 6, 8, 10; the tension from the load cell
or the radial equation; stateful effects run along the log).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import convolve1d
from scipy.signal import lfilter, savgol_filter

from ...config import Config
from ...model.effects import Kinematics, tether_stretch_of
from ...model.reduced import Model
from ._inputs import _load_cell, centred_commands, effect_states, logged_channel
from ._measured import Measured, _delayed, _savgol_kernel


@dataclass(frozen=True, eq=False)
class Prediction:
    """Predicted quantities for one segment (whole segment, before the core cut).

    ``acc`` (N, 3): predicted COG acceleration projected on the path axes (t, n, r),
    smoothed; ``omega_dot`` (N, 3) rad/s^2 smoothed; ``stretch`` (N,) m; ``tension``
    (N,) N used (load cell or radial equation); ``T`` (N, 4) N actual thrust after effects;
    ``inputs`` (N, 4) commanded (T_C, tau_x, tau_y, tau_z) at the sample times;
    ``latency`` s: how far the on-board signals were delayed onto the pose's clock;
    ``omega_dot_pose`` (N, 3) rad/s^2: the prediction smoothed for the pose's angular
    acceleration (``omega_dot`` is filtered like the gyro's when the segment has one).
    """

    acc: np.ndarray
    omega_dot: np.ndarray
    stretch: np.ndarray
    tension: np.ndarray
    T: np.ndarray
    inputs: np.ndarray
    tension_source: str
    latency: float = 0.0
    omega_dot_pose: np.ndarray | None = None


def _kelvin_voigt(f, k, c, dt):
    """Elongation of ``c s' + k s = f`` driven by the tension samples f (exact for f held)."""
    s = f / k
    if c == 0:
        return s
    a = math.exp(-dt * k / c)
    return lfilter([1 - a], [1, -a], s, zi=[a * s[0]])[0]


def _tether_stretch(config: Config, f_t, dt, effects=()):
    """Predicted stretch (m) of the tether for the tension f_t (N), per ``tether.link``
    (:mod:`gainsched.model.links`): 0 for the rigid link; Kelvin-Voigt ``c s' + k s = f`` for
    the spring-damper; ``f / k_s`` plus Kelvin-Voigt ``(k_p, c)`` for the standard linear
    solid; the lumped-mass chain quasi-statically as its whole-chain spring-damper (node
    dynamics and sag neglected). Plus the stretch that ``effects`` add at that tension
    (:func:`~gainsched.model.effects.tether_stretch_of`: an empirical stretch law)."""
    extra = tether_stretch_of(effects, f_t)
    s = np.zeros_like(f_t) if extra is None else extra
    teth = config.tether
    if teth.link == "rigid":
        return s
    f = np.maximum(f_t, 0.0)
    s = s + _kelvin_voigt(f, teth.stiffness, teth.damping, dt)
    if teth.link == "sls":
        s = s + f / teth.series_stiffness
    return s


@dataclass(frozen=True)
class _Kin(Kinematics):
    """Kinematics with the body-frame (ground) velocity computed once per segment (still
    air; :func:`predict` builds a plain one in a model's wind)."""

    vB: np.ndarray | None = None

    @property
    def v_B(self):
        return self.vB


def _kinematics(meas: Measured) -> Kinematics:
    def make():
        vB = np.einsum("nji,nj->ni", meas.R, meas.v)
        return _Kin(meas.R, meas.v, meas.z[:, 7:10], meas.p, meas.alpha, meas.gamma, vB=vB)

    return meas.derived("kin", make)


def _savgol(x, meas: Measured, deriv: int, edges: bool) -> np.ndarray:
    """``savgol_filter(x, meas.window, meas.order, deriv, meas.dt, axis=0, mode="interp")``;
    ``edges=False``: without the end fits, so exact on ``meas.core`` only (the filter's
    interior is this same convolution, bit for bit)."""
    delta = meas.dt if deriv else 1.0
    if edges:
        return savgol_filter(x, meas.window, meas.order, deriv=deriv, delta=delta, axis=0,
                             mode="interp")
    return convolve1d(x, _savgol_kernel(meas.window, meas.order, deriv, delta), axis=0,
                      mode="constant")


def _gyro_operator(x, meas: Measured, edges: bool) -> np.ndarray:
    """A predicted angular acceleration ``x`` (N, k), rad/s^2, through what the gyro's
    went through. The gyro's angular acceleration is the filter's derivative of the
    rate: the prediction gets the same operator (the derivative of its running integral,
    trapezoidal, whose unknown constant the derivative removes exactly), not the
    smoothing; (N, k), rad/s^2 (``edges``: as for :func:`_savgol`)."""
    x_int = np.concatenate([np.zeros((1, x.shape[1])), np.cumsum(
        0.5 * (x[1:] + x[:-1]) * np.diff(meas.t)[:, None], axis=0)])
    return _savgol(x_int, meas, 1, edges)


def predict(model: Model, meas: Measured, *, latency: float | None = None,
            inputs: bool = True, edges: bool = True) -> Prediction:
    """The model's accelerations for the measured state and the logged commands (step 3).

    ``latency`` (s, default: the config's ``analysis.latency_s``) delays the commands and
    the load cell (both logged on board) relative to the pose (the pose lags them by it).
    ``edges=False`` is the fast path of the fits: the filtered outputs are exact on
    ``meas.core`` only (no polynomial fits at the ends), and the pose-smoothed angular
    acceleration is left out when a gyro supplies it.
    """
    cfg = model.config
    lat = cfg.analysis.latency_s if latency is None else latency
    T_raw = _delayed(meas.t, meas.T_cmd, lat)
    u = centred_commands(T_raw)
    z = meas.z
    if model.wind_I is None:
        kin = _kinematics(meas)
    else:  # the flight's heading turns the model's wind into its circle frame
        kin = Kinematics(meas.R, meas.v, meas.z[:, 7:10], meas.p, meas.alpha, meas.gamma,
                         model.wind_I)
    if model.n_extra:
        parts = [z]

        def kin_at(k):
            return Kinematics(meas.R[k], meas.v[k], z[k, 7:10], meas.p[k], meas.alpha,
                              meas.gamma, model.wind_I)

        for eff in model.effects:
            if eff.n_states and eff.log_channel:  # the log holds the states (vbat)
                parts.append(eff.states_from_log(logged_channel(meas, eff, lat)))
            elif eff.n_states:
                parts.append(effect_states(eff, meas.t, T_raw, kin_at))
        z = np.concatenate(parts, -1)
    T = model.thrust(z, u, kin)
    F0, tau0 = model.body_wrench(T, kin, meas.alpha)
    m = model.m
    if meas.tension is not None:
        f_t, source = _load_cell(meas, lat), "load cell"
    else:
        f_t, source = np.sum(meas.e * (F0 - m * meas.a), -1), "radial equation"
    a_pred = (F0 - f_t[:, None] * meas.e) / m
    e_B = meas.derived("e_B", lambda: np.einsum("nji,nj->ni", meas.R, meas.e))
    tau = tau0 - f_t[:, None] * model.tether_lever(e_B)
    wd = tau @ np.linalg.inv(model.J).T  # a product of (N, 3) by (3, 3): 6x einsum's speed
    acc = np.einsum("nij,nj->ni", meas.axes, a_pred)
    if meas.gyro_dot is None or edges:
        sm = _savgol(np.concatenate([acc, wd], -1), meas, 0, edges)
        acc, wd_pose = sm[:, :3], sm[:, 3:]
    else:
        acc, wd_pose = _savgol(acc, meas, 0, edges), None
    wd_gyro = wd_pose
    if meas.gyro_dot is not None:
        wd_gyro = _gyro_operator(wd, meas, edges)
    stretch = _tether_stretch(cfg, f_t, meas.dt, model.effects)
    inp = np.einsum("nk,jk->nj", u, model.alloc) if inputs else None
    return Prediction(acc, wd_gyro, stretch, f_t, T, inp, source, lat, wd_pose)
