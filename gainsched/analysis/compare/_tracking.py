"""Along-track tracking of logged segments that carry the reference azimuth."""

from __future__ import annotations

import numpy as np

from ...config import Config


def tracking_summary(config: Config, measured, segs) -> list[dict]:
    """Along-track tracking of every log segment that carries the reference azimuth
    (``xi_ref``): the measured azimuth of the attachment point (``Measured.z``, already
    reconstructed from the pose) minus the reference, both continuous (the reference put
    on the 2 pi branch of the first sample; a lap behind is -2 pi), and that error times
    the COG radius (m).

    Returns a list of dicts: ``segment`` (the measured segment's name),
    ``rms_along_track_m``, ``max_along_track_m``, ``final_azimuth_error_rad``,
    ``lap_slips``.
    """
    out = []
    for meas, log in zip(measured, segs, strict=True):
        ref = log.optional.get("xi_ref")
        if ref is None or len(log) < 2:
            continue
        xi = meas.z[:, 1]
        ref = np.unwrap(np.asarray(ref, dtype=float))
        ref = ref + 2 * np.pi * np.round((xi[0] - ref[0]) / (2 * np.pi))
        err = xi - ref
        r = config.radius
        out.append({"segment": meas.name,
                    "rms_along_track_m": float(r * np.sqrt(np.mean(err**2))),
                    "max_along_track_m": float(r * np.abs(err).max()),
                    "final_azimuth_error_rad": float(err[-1]),
                    "lap_slips": int(np.abs(err).max() // (2 * np.pi))})
    return out
