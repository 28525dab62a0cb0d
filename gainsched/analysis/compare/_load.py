"""Reading the logs of a comparison and differentiating every segment."""

from __future__ import annotations

import warnings
from pathlib import Path

from ...config import Config
from ...errors import InputError
from ..logs import FlightLog, LogWarning, read_log
from ._measured import Measured, measure


def load_segments(config: Config, logs, channel_map=None, trust=(), progress=None
                  ) -> tuple[list[Measured], list[FlightLog], list[str]]:
    """Read log files (or take :class:`FlightLog` objects) and differentiate every segment.

    ``channel_map``: for PX4 ULogs and ROS 2 bags (:func:`read_log`); their normalised or
    PWM commands reach newtons through the config's ``vehicle.thrust_max`` unless the
    map gives a thrust. The files are checked against the config's vehicle
    (:mod:`gainsched.analysis.logs._consistency`) except for the checks named in ``trust``.
    Returns (measured segments, the log segments, warnings as text: gaps, dropped
    pieces). ``progress(1)`` is called after each log read (a progress bar's increment).
    """
    segs: list[FlightLog] = []
    notes: list[str] = []
    for item in logs:
        if isinstance(item, FlightLog):
            segs.append(item)
            continue
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", LogWarning)
            segs.extend(read_log(item, channel_map=channel_map,
                                 thrust_max=config.vehicle.thrust_max, config=config,
                                 trust=trust))
        notes.extend(str(w.message) for w in caught if issubclass(w.category, LogWarning))
        if progress is not None:
            progress(1)
    if not segs:
        raise InputError("command line", "LOG", "no flight log given")
    names = [s.meta.get("flight_id") or Path(s.source).stem or "log" for s in segs]
    seen: dict[str, int] = {}
    meas = []
    for s, nm in zip(segs, names, strict=True):
        if names.count(nm) > 1 and s.n_segments == 1:
            seen[nm] = seen.get(nm, 0) + 1
            nm = f"{nm}({seen[nm]})"
        meas.append(measure(s, config, name=nm))
    return meas, segs, notes
