"""The whole comparison in one call, :func:`compare` (``gainsched compare``)."""

from __future__ import annotations

from ...config import Config
from ...model.reduced import Model
from ..structure import findings
from ._axes import AXES, UNITS
from ._binning import where_it_fails
from ._comparison import Comparison
from ._inputs import check_logged_channels
from ._load import load_segments
from ._motor_order import check_motor_order
from ._noise import noise_floor
from ._residual import residuals
from ._stats import axis_stats
from ._tracking import tracking_summary


def compare(config: Config, logs, *, effects=None, measured=None, segs=None,
            notes=None, channel_map=None, trust=(), progress=None) -> Comparison:
    """Compare the model with flight logs: the residual per axis against its noise floor.

    The whole of ``gainsched compare`` (docs/model-vs-measurement.md): per gap-free log
    segment, the pose in reduced coordinates, differentiated by Savitzky-Golay; the
    model's accelerations for the measured state and the logged commands; the residual
    ``measured - predicted`` on the axes tangential, normal, radial (m/s^2; radial only
    with a load cell), roll, pitch, yaw (rad/s^2) and tether stretch (m); then per axis
    the statistics pooled over the segments, the noise floor (the measurement noise
    pushed through the same pipeline), where the residual concentrates, and the binned
    structure averaged over revolutions.

    Parameters
    ----------
    config : Config
        The model under test: its vehicle, tether, effects and ``[analysis]`` settings
        (Savitzky-Golay window, s, and order; the pose's latency, s; whether to use the
        gyro and the accelerometer columns).
    logs : iterable of str, path-like or FlightLog
        Flight log files (:func:`~gainsched.analysis.logs.read_log`: each split at its
        gaps) or segments already read. Not read when ``measured`` is given.
    effects : tuple of Effect, optional
        Model effects (:mod:`gainsched.model.effects` objects) to predict with instead of
        the config's: a model variant. Default: the config's.
    measured : list of Measured, optional
        The differentiated segments of a previous :func:`load_segments` call with the
        same attachment offset and analysis settings, to skip reading and
        differentiating; give its ``segs`` and ``notes`` too.
    segs : list of FlightLog, optional
        The log segments of ``measured``, in the same order.
    notes : list of str, optional
        The reading notes of ``measured`` (gaps, dropped segments).
    channel_map : ChannelMap, str or path-like, optional
        How PX4 ULogs and ROS 2 bags among ``logs`` hold the channels
        (:func:`~gainsched.analysis.logs.read_log`; default for a ULog: the shipped
        ``px4`` map).
    trust : iterable of str, optional
        Consistency checks of the log files to skip (:func:`~gainsched.analysis.logs.
        read_log`, docs/flight-log.md): ``plane``, ``quaternion``, ``gyro``, ``thrust``,
        ``tension``, ``xi_ref``.
    progress : callable or None, default None
        Called with 1 after each log read (none when ``measured`` is given) and once
        more when the statistics are done (e.g. a progress bar's ``update``).

    Returns
    -------
    Comparison
        Residuals per segment, statistics and noise floor per axis, where it fails, the
        binned structure, tracking, notes.

    Raises
    ------
    InputError
        No log given, a log breaks the format's rules (:func:`read_log`; the file,
        column and row named), a segment is shorter than twice the differentiation
        window, or its commanded thrust is zero on every sample.

    Examples
    --------
    The paper model on the seven example flights (a plant with effects it lacks):

    >>> import glob
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> cmp = gs.compare(cfg, sorted(glob.glob("examples/flights/*.csv")))
    >>> for axis, s in cmp.stats.items():
    ...     print(f"{axis:10s} RMS {s.rms:8.3g} {s.unit:7s} {s.rms_over_noise:5.1f}x noise")
    tangential RMS     1.27 m/s^2     4.8x noise
    normal     RMS     1.73 m/s^2     7.1x noise
    radial     RMS    0.302 m/s^2     1.1x noise
    roll       RMS     3.16 rad/s^2  16.3x noise
    pitch      RMS     2.98 rad/s^2   2.2x noise
    yaw        RMS     1.09 rad/s^2   1.2x noise
    stretch    RMS 0.000161 m         1.0x noise
    >>> round(cmp.normalized_rms(), 1)  # 1: nothing but measurement noise
    7.0
    >>> cmp.where["sentence"]
    'roll residual concentrates at tension 26-34.1 N (RMS 5.74 rad/s^2, ...)'
    """
    if measured is None:
        measured, segs, notes = load_segments(config, logs, channel_map, trust, progress)
    model = Model(config, effects)
    check_logged_channels(model, measured, segs)
    check_motor_order(model, measured, segs)
    res = residuals(config, measured, effects=effects, model=model)
    noise, pose_noise = noise_floor(config, measured, segs, effects=effects)
    axes = [a for a in AXES if all(a in r.residual for r in res)]
    stats = {a: axis_stats(res, a, noise[a]) for a in axes}
    where = where_it_fails(res, noise)
    found, tables = findings(res, noise, units=UNITS)
    if progress is not None:
        progress(1)
    return Comparison(config, measured, res, stats, noise, where, list(notes or []), list(segs),
                      tracking_summary(config, measured, segs or []), found, tables, pose_noise)
