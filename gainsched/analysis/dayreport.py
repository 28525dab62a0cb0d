"""The report of a flight day (``gainsched convert ... --day -o DIR``): each kept flight as
a log of its own, and what was kept and why the rest was not, as a table (Markdown), as
data (JSON) and as a picture of the day coloured by piece.
"""

from __future__ import annotations

import io
import json
import math

import numpy as np

from .logs import Day, log_bytes

__all__ = ["day_files", "day_markdown", "day_png"]


def _file_name(i: int, piece) -> str:
    return f"{i:02d}-{piece.kind}.csv"


def day_markdown(day: Day) -> str:
    """The pieces of the day as a Markdown table: time, duration, what, kept or why not."""
    rows = ["| from, s | to, s | s | piece | speed, m/s | tilt, deg | heading, deg | kept |",
            "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    files = {id(q): _file_name(i, q) for i, q in enumerate(day.cut.kept, 1)}

    def num(x, fmt="{:.1f}"):
        return "" if math.isnan(x) else fmt.format(x)

    for q in day.cut.pieces:
        speed = (num(q.speed) if q.kind != "manoeuvre" else
                 f"{q.speed:.1f} -> {q.speed_end:.1f}")
        rows.append(f"| {q.t0:.2f} | {q.t1:.2f} | {q.t1 - q.t0:.2f} | {q.kind} | {speed} | "
                    f"{num(q.tilt_deg)} | {num(q.heading_deg, '{:.0f}')} | "
                    + (f"`{files[id(q)]}`" if q.kept else f"no: {q.why}") + " |")
    head = (f"# The day: {len(day.cut.kept)} flights kept of {len(day.cut.pieces)} pieces\n\n"
            "Kept: the steady circles on the tether's sphere and the manoeuvres between two "
            "circles of one plane (docs/flight-log.md, \"A flight day\").\n\n")
    return head + "\n".join(rows) + "\n"


def day_png(day: Day) -> bytes:
    """A picture of the day: the speed and the distance from the anchor over time, each
    kept flight coloured and labelled, the dropped pieces grey."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = day.columns["t"]
    p = np.stack([day.columns[c] for c in "xyz"], -1)
    speed = np.linalg.norm(np.gradient(p, t, axis=0), axis=1)
    fig, ax = plt.subplots(2, 1, figsize=(10, 5), sharex=True)
    ax[0].plot(t, speed, color="0.3", lw=0.6)
    ax[1].plot(t, np.linalg.norm(p, axis=1), color="0.3", lw=0.6)
    colors = plt.get_cmap("tab10").colors
    for i, q in enumerate(day.cut.kept):
        for a in ax:
            a.axvspan(q.t0, q.t1, color=colors[i % 10], alpha=0.25, lw=0)
        ax[0].text(0.5 * (q.t0 + q.t1), 1.02, f"{i + 1:02d}", ha="center", fontsize=7,
                   transform=ax[0].get_xaxis_transform())
    for q in day.cut.pieces:
        if not q.kept:
            for a in ax:
                a.axvspan(q.t0, q.t1, color="0.85", lw=0, zorder=0)
    ax[0].set_ylabel("speed, m/s")
    ax[1].set_ylabel("from the anchor, m")
    ax[1].set_xlabel("time, s (coloured: the flights kept, numbered as their files; grey: "
                     "dropped)")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, metadata={"Software": None})
    plt.close(fig)
    return buf.getvalue()


def day_files(day: Day) -> dict[str, bytes]:
    """The files of ``convert --day``: ``NN-KIND.csv`` per kept flight (its samples, the
    plane it flew), ``day.json``, ``day.md`` and ``day.png``."""
    files = {}
    for i, (q, log) in enumerate(zip(day.cut.kept, _logs_by_piece(day), strict=True), 1):
        cols = {k: v[q.start:q.stop] for k, v in day.columns.items()}
        files[_file_name(i, q)] = log_bytes("csv", cols, log.meta, name=_file_name(i, q))
    data = {"meta": {k: v for k, v in day.meta.items() if k.startswith(("clock_", "pose_"))},
            **day.cut.to_json(),
            "files": [_file_name(i, q) for i, q in enumerate(day.cut.kept, 1)]}
    files["day.json"] = (json.dumps(data, indent=1) + "\n").encode()
    files["day.md"] = day_markdown(day).encode()
    files["day.png"] = day_png(day)
    return files


def _logs_by_piece(day: Day) -> list:
    """The first segment read of each kept piece (its metadata: the piece's plane)."""
    first = {}
    for log in day.logs:  # each piece its own flight_id
        first.setdefault(log.meta["flight_id"], log)
    return list(first.values())
