"""A config checked and summarised (``gainsched validate``), and the nominal flight of one
circle over the azimuth (``gainsched nominal``)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..config import Config
from ..errors import InputError
from ._report import config_of

__all__ = ["Validation", "validate", "NominalCircle", "nominal"]


@dataclass(frozen=True, eq=False)
class Validation:
    """What :func:`validate` found: a valid config and its summary.

    Attributes
    ----------
    config : Config
        The validated config.
    source : str
        The config as given (its file, or a shipped config's name): what the first line
        names.
    taut_speeds : ndarray, shape (n_tilts,)
        The slowest speed at which the tether stays taut per tilt of the grid, m/s.
    """

    config: Config
    source: str
    taut_speeds: np.ndarray

    def lines(self) -> list[str]:
        """What ``gainsched validate`` prints: the config's hash, the vehicle, the tether,
        the effects, the grid and the slowest taut speed per tilt."""
        cfg = self.config
        v, t, gr = cfg.vehicle, cfg.tether, cfg.grid
        effects = ", ".join(
            f"{e.name}({', '.join(f'{k}={x:g}' for k, x in e.params)})" for e in cfg.effects)

        def axis(values, rng, what, unit):
            if rng is None:
                return f"{values.size} {what} {values[0]:g}..{values[-1]:g} {unit}"
            return f"{what} {rng.lo:g}..{rng.hi:g} {unit} (at most {rng.max_count}, chosen)"

        az = gr.azimuth_auto
        out = [f"{self.source}: ok (sha256 {cfg.sha256[:12]})",
               f"  vehicle  m={v.mass:g} kg  "
               f"J=diag({', '.join(f'{x:g}' for x in np.diag(v.inertia))}) kg m^2",
               f"           arm {v.arm_length:g} m  kappa {v.kappa:g} m  "
               f"thrust {v.thrust_min:g}..{v.thrust_max:g} N",
               f"  tether   rho={t.length:g} m  L_e={t.attachment_offset:g} m  link={t.link}",
               f"  effects  {effects or 'none'}",
               f"  grid     {axis(gr.speeds, gr.speeds_auto, 'speeds', 'm/s')}, "
               f"{axis(np.rad2deg(gr.tilts), gr.tilts_auto, 'tilts', 'deg')}, "
               + (f"{gr.azimuth_samples} azimuth samples" if az is None
                  else f"{az.lo}..{az.hi} azimuth samples (chosen)")]
        if gr.auto:
            out.append(f"           chosen by the build for "
                       f"{100 * gr.max_interpolation_error:g} % at the cell midpoints "
                       "(docs/grid.md)")
        out += [f"  taut above {s:.2f} m/s at tilt {np.rad2deg(a):g} deg"
                for a, s in zip(gr.tilts, self.taut_speeds, strict=True)]
        return out


def validate(config) -> Validation:
    """Check a config and summarise its vehicle and grid: what ``gainsched validate
    CONFIG`` does (docs/config.md).

    Parameters
    ----------
    config : Config or path-like
        The config, or its TOML file (or a shipped config's name, ``"paper"``).

    Returns
    -------
    Validation
        The validated config, the slowest taut speed per tilt and
        :meth:`Validation.lines`, what the command prints.

    Raises
    ------
    InputError
        The config is not valid (one line naming the file and the key).

    Examples
    --------
    >>> v = gs.studies.validate("configs/paper.toml")
    >>> v.lines()[0], v.taut_speeds.shape
    ('configs/paper.toml: ok (sha256 2714f29fd9de)', (7,))
    """
    from ..schedule.nominal import min_taut_speed

    cfg = config_of(config)
    source = cfg.source if isinstance(config, Config) else str(config)
    taut = np.array([min_taut_speed(cfg, a) for a in cfg.grid.tilts])
    return Validation(cfg, source, taut)


#: the columns of :func:`nominal`'s table and CSV
_HEAD = ("xi_deg", "roll_deg", "T_C_N", "T1_N", "T2_N", "T3_N", "T4_N", "tension_N", "g_load",
         "feasibility")


@dataclass(frozen=True, eq=False)
class NominalCircle:
    """What :func:`nominal` found: the nominal flight of one constant-speed circle.

    Attributes
    ----------
    config : Config
        The config flown.
    speed : float
        Tangential COG speed, m/s (negative: reversed).
    tilt : float
        Circle tilt alpha_C, deg.
    rate : float
        The azimuth rate xi_dot, rad/s.
    period : float
        One turn, s.
    taut_speed : float
        The slowest speed at which the tether stays taut at this tilt, m/s.
    xi : ndarray, shape (n,)
        The azimuth samples, deg in [0, 360).
    roll : ndarray, shape (n,)
        Nominal roll phi, deg.
    collective : ndarray, shape (n,)
        Collective thrust T_C, N.
    thrusts : ndarray, shape (n, 4)
        Motor thrusts T1..T4, N.
    tension : ndarray, shape (n,)
        Tether tension, N.
    g_load : float
        Centripetal acceleration over g.
    reasons : ndarray of int, shape (n,)
        The infeasibility bits per sample (0: feasible;
        :data:`gainsched.schedule.nominal.REASONS`).
    feasibility : tuple of str, shape (n,)
        The reasons per sample as text (``"ok"``: feasible).
    csv : Path or None
        The CSV file written (None: none asked for).
    """

    config: Config
    speed: float
    tilt: float
    rate: float
    period: float
    taut_speed: float
    xi: np.ndarray
    roll: np.ndarray
    collective: np.ndarray
    thrusts: np.ndarray
    tension: np.ndarray
    g_load: float
    reasons: np.ndarray
    feasibility: tuple
    csv: Path | None = None

    def rows(self) -> list[tuple]:
        """The table's rows: xi, roll (deg), T_C, T1..T4, tension (N), g-load and the
        feasibility text per azimuth sample."""
        return [(self.xi[k], self.roll[k], self.collective[k], *self.thrusts[k],
                 self.tension[k], self.g_load, self.feasibility[k])
                for k in range(self.xi.size)]

    def csv_text(self) -> str:
        """The table as CSV (SI units, xi and roll in deg): what ``--csv`` writes."""
        lines = [",".join(_HEAD)] + [
            ",".join(f"{x:.9g}" for x in row[:-1]) + f",{row[-1]}" for row in self.rows()]
        return "\n".join(lines) + "\n"

    def lines(self) -> list[str]:
        """What ``gainsched nominal`` prints: the circle's rate, period and taut speed, the
        table, the feasible count and the CSV written."""
        n, n_bad = self.xi.size, int(np.count_nonzero(self.reasons))
        out = [f"speed {self.speed:g} m/s (xi_dot {self.rate:.4g} rad/s), tilt {self.tilt:g} "
               f"deg, period {self.period:.3f} s, taut above {self.taut_speed:.2f} m/s",
               " ".join(f"{h:>9s}" for h in _HEAD[:-1]) + "  feasibility"]
        out += [" ".join(f"{x:9.3f}" for x in row[:-1]) + "  " + row[-1]
                for row in self.rows()]
        out.append(f"{n - n_bad}/{n} azimuth samples feasible")
        if self.csv is not None:
            out.append(f"wrote {self.csv}")
        return out


def nominal(config, speed: float, tilt: float = 0.0, samples: int = 12, *,
            csv=None) -> NominalCircle:
    """The nominal flight of a constant-speed circle over the azimuth: roll, collective and
    motor thrusts, tether tension, centripetal g-load and feasibility; what ``gainsched
    nominal CONFIG --speed V --tilt A --samples N [--csv FILE]`` does.

    Parameters
    ----------
    config : Config or path-like
        The config, or its TOML file (or a shipped config's name, ``"paper"``).
    speed : float
        Tangential COG speed, m/s: finite, non-zero (negative: reversed).
    tilt : float, default 0
        Circle tilt alpha_C, deg in (-90, 90).
    samples : int, default 12
        Azimuth samples over one period, 4..3600.
    csv : path-like, optional
        Also write the table there as CSV (SI units, xi and roll in deg), atomically.

    Returns
    -------
    NominalCircle
        The samples as arrays and :meth:`NominalCircle.lines`, what the command prints.

    Raises
    ------
    InputError
        A bad config, speed, tilt, number of samples or CSV file, before anything is
        computed.

    Examples
    --------
    >>> c = gs.studies.nominal("configs/paper.toml", 10.0, 20.0, 8)
    >>> c.thrusts.shape, c.feasibility[0], round(c.period, 3)
    ((8, 4), 'ok', 1.005)
    >>> c.lines()[-1]
    '8/8 azimuth samples feasible'
    """
    from ..model.reduced import Model
    from ..publish import check_out_file, write_atomic
    from ..schedule.nominal import REASONS, circle_nominal, min_taut_speed

    cfg = config_of(config)
    if speed == 0 or not np.isfinite(speed):
        raise InputError("command line", "--speed", "must be a finite non-zero speed in m/s")
    if not -90 < tilt < 90:
        raise InputError("command line", "--tilt", "must be in (-90, 90) deg")
    if not (isinstance(samples, (int, np.integer)) and 4 <= samples <= 3600):
        raise InputError("command line", "--samples", f"{samples!r}: must be an integer in "
                         "[4, 3600]")
    if csv is not None:
        csv = Path(csv)
        check_out_file(csv, "--csv")  # a bad --csv fails before anything is computed
    model = Model(cfg)
    nom = circle_nominal(model, speed, np.deg2rad(tilt), samples)
    why = tuple("; ".join(txt for bit, txt in REASONS.items() if r & bit) or "ok"
                for r in nom.reasons)
    done = NominalCircle(
        cfg, speed, tilt, speed / model.r, 2 * np.pi * model.r / abs(speed),
        min_taut_speed(cfg, np.deg2rad(tilt)), np.rad2deg(nom.z[:, 1]) % 360,
        np.rad2deg(nom.phi), np.asarray(nom.collective), np.asarray(nom.u),
        np.asarray(nom.tension), speed**2 / model.r / cfg.g, np.asarray(nom.reasons), why,
        csv)
    if csv is not None:
        write_atomic(csv, done.csv_text().encode(), where="--csv")
    return done
