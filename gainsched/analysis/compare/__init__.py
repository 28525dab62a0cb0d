"""Model versus measurement: the residual of the model on flight logs.

The workflow and the statistics are described in docs/model-vs-measurement.md.

Pipeline, per gap-free log segment (:class:`~gainsched.analysis.logs.FlightLog`):

1. **Reduced coordinates from the pose.** The attachment point
   ``p_t = p_q + R_CB p_e`` in the circle frame gives the tether distance
   ``d = |p_t|`` and the spherical angles ``(delta, xi)``; ``R_CB`` gives the
   Z-Y-X Euler angles ``(phi, theta, psi)``, ``chi = psi - xi`` (docs/conventions.md,
   the conversion of :func:`gainsched.model.maximal.reduced_from_maximal`).
   These six channels vary slowly even at 15 m/s (xi and psi grow linearly),
   which is why they, and not the Cartesian pose, are differentiated.
2. **Differentiation.** Savitzky-Golay (:func:`scipy.signal.savgol_filter`,
   window and order from ``[analysis]``) gives each channel and its first two
   derivatives; the COG velocity and acceleration and the body rates and
   their derivatives follow from exact kinematics
   (``p_q'' = p_t'' - R (omega' x p_e + omega x (omega x p_e))``, paper eq. 9
   corrected; Euler rates to body rates). Half a window at each segment end,
   where the filter extrapolates, is dropped from every statistic.
3. **Prediction.** The model's forces for the measured state and the logged
   commands (centred on the sample time: a logged command is held over the
   interval before its sample): thrust along z_B after the thrust modifiers,
   gravity, effect forces and torques (paper eqs. 3, 6, 8, 10), the tether
   tension from the load cell when logged, otherwise solved from the radial
   equation. Stateful effects (motor lag) are run along the log. The
   predicted accelerations are smoothed with the same filter as the
   measurement, so the residual compares like with like.
4. **Residual** ``measured - predicted`` on the axes of :data:`AXES`:
   tangential (along the direction of travel), normal (to the circle plane),
   radial (outward along the tether; only with a load cell, since the
   radial equation is otherwise used up by the tension), the body angular
   accelerations (roll, pitch, yaw), and the tether stretch
   ``d - rho - predicted stretch`` (m; zero for a rigid tether).

Statistics per axis (:func:`axis_stats`): RMS, bias, NRMSE fit %, the noise
floor (the motion-capture noise pushed through the same pipeline), whiteness
(autocorrelation beyond the filter's own support, against a Bartlett band)
and the cross-correlation with the inputs and their rates at +-lags.
:func:`where_it_fails` bins the residual against airspeed, tilt, azimuth,
tension, thrust and time in flight and names the worst regime.

The package's modules, one concept each (private: this namespace is the API), top to
bottom of their imports (a module imports only from those below it):

- ``_compare``: the entry point, :func:`compare`;
- ``_comparison``: its result, :class:`Comparison`; ``_tracking``: along-track tracking,
  :func:`tracking_summary`;
- ``_noise``: the noise floor, :func:`noise_floor`; ``_stats``: the statistics per axis,
  :class:`AxisStats`, :func:`axis_stats`; ``_binning``: :func:`where_it_fails`;
  ``_motor_order``: :func:`check_motor_order`, :func:`motor_order_fits`;
- ``_residual``: step 4, :class:`Residual`, :func:`residuals`, :func:`residual_axes`;
- ``_predict``: step 3, :func:`predict`;
- ``_inputs``: the commands and the effects' states along the log
  (:func:`centred_commands`);
- ``_load``: reading the logs, :func:`load_segments`;
- ``_measured``: steps 1-2, :class:`Measured`, :func:`measure`, :func:`window_samples`;
- ``_axes``: :data:`AXES`, :data:`UNITS`, :data:`AT_NOISE_FLOOR`.
"""

from ...constants import BIN_VARIABLES
from ._axes import AT_NOISE_FLOOR, AXES, UNITS
from ._binning import where_it_fails
from ._compare import compare
from ._comparison import Comparison
from ._inputs import centred_commands
from ._inputs import has_channel as has_channel  # not in __all__: analysis.diagnose uses it
from ._load import load_segments
from ._measured import Measured, attachment_from_cog_config, measure, window_samples
from ._motor_order import MOTOR_ORDER_FACTOR, check_motor_order, motor_order_fits
from ._noise import noise_floor
from ._predict import predict
from ._residual import Residual, residual_axes, residuals
from ._stats import AxisStats, axis_stats
from ._tracking import tracking_summary

__all__ = [
    "centred_commands",
    "AXES",
    "UNITS",
    "BIN_VARIABLES",
    "Measured",
    "Residual",
    "AxisStats",
    "Comparison",
    "load_segments",
    "measure",
    "predict",
    "residuals",
    "residual_axes",
    "axis_stats",
    "where_it_fails",
    "compare",
    "tracking_summary",
    "window_samples",
    "attachment_from_cog_config",
    "noise_floor",
    "AT_NOISE_FLOOR",
    "MOTOR_ORDER_FACTOR",
    "motor_order_fits",
    "check_motor_order",
]
