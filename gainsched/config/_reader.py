"""Reading a config: TOML text in, one validated :class:`Config` out.

:func:`load_config` (a file) and :func:`config_from_text` (text) are the ways in; both
run one validation pass (:func:`_config`): the size and the TOML, every section by its
reader (:mod:`gainsched.config._sections`), then the checks across sections (lengths,
hover, control rate, commands, margins), the build budget
(:func:`gainsched.config.check_budget`) and a flyable circle
(:func:`gainsched.config._plausible.check_circles`). :class:`Config`, the tree of section
dataclasses the pass makes, lives here with it: :meth:`Config.with_values` reads its
edited text again.
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import InputError
from ..resources import config_path, reference_configs
from ..textinput import parse_toml, read_text
from ._budget import check_budget
from ._checks import Section, check_name, check_rate
from ._plausible import G_RANGE, check_circles, check_hover, check_lengths
from ._schema import (
    Analysis,
    Control,
    EffectSpec,
    Feasibility,
    Firmware,
    Grid,
    Limits,
    Sensors,
    Tether,
    Vehicle,
)
from ._sections import (
    read_analysis,
    read_control,
    read_effects,
    read_feasibility,
    read_firmware,
    read_grid,
    read_limits,
    read_sensors,
    read_tether,
    read_vehicle,
)

#: largest config text, characters: a hand-written config is a few KiB, and the largest
#: grid the default [limits] allow is far below this (parsing 20 MB of TOML takes seconds)
MAX_CONFIG_CHARS = 2**20
_KEY_LINE = re.compile(r"^[ \t]*([A-Za-z0-9_\-]+)[ \t]*=|^[ \t]*\[+[ \t]*([^\]\n]+?)[ \t]*\]",
                       re.M)


@dataclass(frozen=True)
class Config:
    """A validated config: every parameter of a build, in SI units, from one TOML file.

    Made by :func:`load_config` or :func:`config_from_text`, never by hand: those check
    every key. Frozen; :meth:`with_values` makes a validated variant. Each section of the
    file is a frozen dataclass of its own (:class:`Vehicle`, :class:`Tether`, ...); keys
    ending in ``_deg`` are held in rad under the name without the suffix.

    Attributes
    ----------
    name : str
        The ``name`` key (default: the config file's stem): the stem of the output files
        (``NAME.h5``, ``NAME_gains.h``) and the prefix of the C symbols
        (:func:`check_name`).
    vehicle : Vehicle
        ``[vehicle]``: mass (kg), inertia (3, 3) kg m^2, motor layout (``"x"``), arm
        length (m), reaction torque per newton of thrust ``kappa`` (m, paper eq. 8), and
        the thrust range of each motor ``thrust_min``, ``thrust_max`` (N).
    tether : Tether
        ``[tether]``: length ``rho`` (m), attachment offset ``L_e`` (m, behind the COG),
        and the link model with its stiffness (N/m), damping (N s/m), mass (kg) and
        segments; the schedule treats the tether as rigid, the elastic links are used by
        the maximal-coordinate simulator only.
    effects : tuple of EffectSpec
        The ``[effects.NAME]`` tables, sorted by name: each model effect (e.g. ``drag``,
        paper eq. 10) and its parameters in SI; empty when the file has none.
    g : float
        ``[environment] g``: gravitational acceleration, m/s^2.
    control : Control
        ``[control]``: control rate ``rate_hz`` (Hz; period ``dt``, s), the LQR weights
        ``Q`` (n, n) over the LQR state (n = 10 + integral states, 11 for
        configs/paper.toml; paper eq. 24) and ``R`` (4, 4) over the motor thrusts, the
        integral states (``integrator``: delta, paper Sec. IV.B; ``azimuth_integral``:
        xi), the terminal cost (``"periodic"`` or ``"single-period"``) and the firmware's
        bounds on the integral states (``int_limit``, rad s; default: sized from the
        table's gains) and whether the build computes every circle's stability margins
        (``margins``, default true; docs/margins.md).
    grid : Grid
        ``[grid]``: the schedule's axes: tangential COG speeds ``speeds`` (n_v,) m/s,
        circle tilts ``tilts`` (n_a,) rad (``tilts_deg`` in the file, starting at 0), and
        ``azimuth_samples`` (n_xi, even) per circle.
    feasibility : Feasibility
        ``[feasibility]`` (defaults when absent): the tension margin and thrust margin
        (N) every nominal keeps, and whether it may use pitch and yaw offsets.
    source : str
        Where the config came from: the file path, or the ``source`` given to
        :func:`config_from_text` (``"<string>"`` by default); errors about it name it.
    text : str
        The TOML text as read (newlines normalised to ``\\n``): :attr:`sha256` hashes it
        and every table built from it embeds it (``config_text``).
    analysis : Analysis
        ``[analysis]`` (defaults when absent): how flight logs are differentiated and
        aligned for model versus measurement (:func:`gainsched.compare`).
    limits : Limits
        ``[limits]`` (defaults when absent): the memory (GiB) and CPU time (s) a build
        may need (:func:`gainsched.config.check_budget`).
    firmware : Firmware
        ``[firmware]`` (defaults when absent): the table format the C header carries and
        the flash budget.
    sensors : Sensors
        ``[sensors]`` (defaults when absent): the gyro's calibration (scale and bias per
        body axis), which the log reader and the firmware controller undo.
    radius : float
        Property: nominal COG circle radius ``r = rho + L_e``, m.
    sha256 : str
        Property: SHA-256 of :attr:`text` (hex), stored in the tables and C headers.

    See Also
    --------
    load_config : Load and validate a config file.
    config_from_text : Parse and validate config text.

    Examples
    --------
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> cfg.vehicle.mass, cfg.tether.length, cfg.radius            # kg, m, m
    (0.5, 1.5, 1.6)
    >>> cfg.control.Q.shape, cfg.control.integrators, cfg.control.dt  # dt in s
    ((11, 11), ('int_delta',), 0.001)
    >>> [e.name for e in cfg.effects]
    ['drag']
    >>> cfg.grid.speeds.size, np.rad2deg(cfg.grid.tilts).round(1).tolist()
    (19, [0.0, 10.0, 20.0, 28.0, 34.0, 37.0, 40.0])

    A heavier vehicle, validated again (the text and hash follow the change):

    >>> heavy = cfg.with_values({"vehicle.mass": 0.55})
    >>> heavy.vehicle.mass, heavy.sha256 == cfg.sha256
    (0.55, False)
    """

    name: str
    vehicle: Vehicle
    tether: Tether
    effects: tuple[EffectSpec, ...]
    g: float
    control: Control
    grid: Grid
    feasibility: Feasibility
    source: str = "<string>"
    text: str = field(default="", repr=False)
    analysis: Analysis = field(default_factory=Analysis)
    limits: Limits = field(default_factory=Limits)
    firmware: Firmware = field(default_factory=Firmware)
    sensors: Sensors = field(default_factory=Sensors)

    def __repr__(self) -> str:
        """One line: the name, the source, the vehicle and tether at a glance, the effects,
        the grid and the text's hash (the full values: the attributes, or ``text``)."""
        g = self.grid
        grid = ("axes chosen by the build" if g.auto else
                f"{g.speeds.size} speeds x {g.tilts.size} tilts x {g.azimuth_samples} azimuths")
        effects = ", ".join(e.name for e in self.effects) or "none"
        return (f"Config({self.name!r}, source={self.source!r}, mass {self.vehicle.mass:g} kg, "
                f"tether {self.tether.length:g} m {self.tether.link}, effects {effects}, "
                f"{grid}, sha256 {self.sha256[:12]})")

    @property
    def sha256(self) -> str:
        """SHA-256 of the config text (hex)."""
        return hashlib.sha256(self.text.encode()).hexdigest()

    @property
    def radius(self) -> float:
        """Nominal COG radius r = rho + L_e, m."""
        return self.tether.length + self.tether.attachment_offset

    def with_values(self, values: dict, source: str | None = None) -> Config:
        """A variant with some keys changed: the config text edited as a TOML document
        (comments kept, floats in full precision; :func:`gainsched.config.set_values`)
        and validated again, so ``text`` and ``sha256`` describe the variant.

        Parameters
        ----------
        values : dict
            Dotted key -> value, e.g. ``{"vehicle.mass": 0.55, "grid.azimuth_samples": 72}``.
        source : str, optional
            Where errors point (default: this config's source).

        Example
        -------
        >>> cfg = load_config("configs/paper.toml")              # doctest: +SKIP
        >>> cfg.with_values({"vehicle.mass": 0.55}).vehicle.mass  # doctest: +SKIP
        0.55
        """
        from ._edit import set_values

        return config_from_text(set_values(self.text, values),
                                self.source if source is None else source)


def _check_commands(source, firmware: Firmware, vehicle: Vehicle) -> None:
    """Normalised outputs must cover the motors' range (``vehicle.thrust_min >= 0``
    already): ``vehicle.thrust_max <= firmware.thrust_max_N``, the thrust at full command."""
    if firmware.command != "normalized":
        return
    if firmware.thrust_full is not None and firmware.thrust_full < vehicle.thrust_max:
        raise InputError(source, "firmware.thrust_max_N",
                         f"{firmware.thrust_full:g} N at full command is below "
                         f"vehicle.thrust_max = {vehicle.thrust_max:g} N: the controller's "
                         "range would need commands above 1")


SCHEMA = "gainsched-config/1"


def config_from_text(text: str, source: str = "<string>") -> Config:
    """Parse and validate config TOML text held in a string, as load_config does a file.

    The same checks as :func:`load_config`, for text that is not (yet) a file: a
    config generated in a script, a variant, or the ``config_text`` a table embeds.

    Parameters
    ----------
    text : str
        Config TOML text (schema ``gainsched-config/1``; configs/paper.toml shows every
        section), at most 1 MiB.
    source : str or path-like, optional
        Where the text came from (default ``"<string>"``): every error names it, and
        without a ``name`` key the config's name is its stem. For a config file name
        (``*.toml``) that default must pass :func:`check_name` too; other sources
        (``"<string>"``, a table's embedded text) keep their stem unchecked: nothing is
        written under such a name unless the config comes through :func:`load_config`.

    Returns
    -------
    Config
        The validated config, in SI units; ``text`` is ``text`` and ``source`` is
        ``str(source)``.

    Raises
    ------
    InputError
        The text is not TOML, a key is unknown or missing, a value has the wrong type
        or an impossible value, or the build would exceed ``[limits]``; the message
        names ``source`` and the dotted key (e.g. ``vehicle.mass``).

    See Also
    --------
    load_config : The same for a file.
    Config.with_values : A variant of a loaded config with some keys changed.

    Examples
    --------
    >>> from pathlib import Path
    >>> text = Path("configs/paper.toml").read_text()
    >>> cfg = gs.config_from_text(text, "variant.toml")
    >>> cfg.name, cfg.source, cfg.vehicle.thrust_max                # thrust in N
    ('paper', 'variant.toml', 3.5)

    A bad value is refused, naming the source and the key:

    >>> gs.config_from_text(text.replace("mass = 0.5 ", "mass = -0.5 "), "variant.toml")
    Traceback (most recent call last):
        ...
    gainsched.errors.InputError: variant.toml: vehicle.mass: must be > 0, got -0.5
    """
    return _config(text, str(source), Path(str(source)).suffix.lower() == ".toml")


def _largest_key(text: str) -> tuple[str, int]:
    """The dotted key whose value takes the most characters of ``text`` (a TOML file) and
    that number: a cheap scan of the ``key =`` and ``[table]`` lines, no parsing."""
    best, size, table, key, start = "", -1, "", "", 0
    for m in _KEY_LINE.finditer(text):
        if key and m.start() - start > size:
            best, size = key, m.start() - start
        if m.group(2) is not None:
            table, key = m.group(2).strip(), ""
        else:
            key, start = (f"{table}.{m.group(1)}" if table else m.group(1)), m.start()
    if key and len(text) - start > size:
        best, size = key, len(text) - start
    return best, max(size, 0)


def _check_size(source: str, text: str) -> None:
    if len(text) > MAX_CONFIG_CHARS:
        key, size = _largest_key(text)
        raise InputError(
            source,
            key,
            f"the config is {len(text) / 2**20:.3g} MiB ({size / 2**20:.3g} MiB in this key); "
            f"a config may have at most {MAX_CONFIG_CHARS // 2**20} MiB (a grid this large "
            "could not be built anyway)",
        )


def _config(text: str, source: str, check_default_name: bool) -> Config:
    _check_size(source, text)
    data = parse_toml(text, source)
    top = Section(source, "", data)
    schema = top.string("schema", SCHEMA)
    if schema != SCHEMA:
        raise top.error("schema", f"must be {SCHEMA!r}, got {schema!r}")
    if "name" in data:
        name = check_name(source, top.string("name"))
    else:
        name = top.string("name", Path(source).stem)
        if check_default_name:
            check_name(source, name, from_file=True)
    vehicle = read_vehicle(top.sub("vehicle"))
    tether = read_tether(top.sub("tether"))
    check_lengths(source, vehicle.arm_length, tether.length)
    effects = read_effects(top.sub("effects", {}))
    env = top.sub("environment")
    g = env.bounded("g", lo=G_RANGE[0], hi=G_RANGE[1], unit="m/s^2")
    env.done()
    check_hover(source, vehicle.mass, vehicle.thrust_max, g)
    control = read_control(top.sub("control"))
    radius = tether.length + tether.attachment_offset
    grid = read_grid(top.sub("grid"), radius)
    check_rate(source, control, grid, radius)
    feas = read_feasibility(top.sub("feasibility", {}))
    analysis = read_analysis(top.sub("analysis", {}))
    limits = read_limits(top.sub("limits", {}))
    firmware = read_firmware(top.sub("firmware", {}))
    sensors = read_sensors(top.sub("sensors", {}))
    _check_commands(source, firmware, vehicle)
    if feas.thrust_margin * 2 >= vehicle.thrust_max - vehicle.thrust_min:
        raise InputError(source, "feasibility.thrust_margin", "leaves no usable thrust range")
    top.done()
    cfg = Config(name, vehicle, tether, effects, g, control, grid, feas, source, text,
                 analysis=analysis, limits=limits, firmware=firmware, sensors=sensors)
    check_budget(cfg, source)
    check_circles(cfg, source)  # after the budget: the grid is of a size a build takes
    return cfg


def load_config(path) -> Config:
    """Load and validate a config file (TOML, UTF-8): every key checked, SI units out.

    Every key is checked here (unknown, missing, wrong type, impossible value), and
    whatever would only fail late in a build (a control rate that undersamples the
    fastest circle, a grid that collapses in float32, a build above ``[limits]``); see
    the module docstring. Degrees exist only in the file (keys ending in ``_deg``).

    Parameters
    ----------
    path : str or path-like
        The config file, e.g. ``"configs/paper.toml"``, or the bare name of a config the
        package ships (``"paper"``: :func:`gainsched.resources.reference_configs`; a file
        of that name in the current folder comes first). It must be UTF-8 (a leading
        UTF-8 byte-order mark is accepted; UTF-16, UTF-32 and other encodings are
        refused naming the file), at most 1 MiB. Without a ``name`` key the config's
        name is the file's stem, which must pass :func:`check_name`.

    Returns
    -------
    Config
        The validated config, in SI units, with ``source`` the path and ``text`` the
        file's text (newlines normalised).

    Raises
    ------
    InputError
        The file cannot be read or is not UTF-8 TOML, a key is unknown or missing, a
        value has the wrong type or an impossible value, or the build would exceed
        ``[limits]``; the message names the file and the dotted key.

    See Also
    --------
    config_from_text : The same for text in memory.

    Examples
    --------
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> cfg.name, cfg.vehicle.mass, cfg.control.rate_hz              # kg, Hz
    ('paper', 0.5, 1000.0)
    >>> cfg.grid.speeds[[0, -1]].tolist(), round(float(cfg.grid.tilts[-1]), 3)  # m/s, rad
    ([1.3, 15.0], 0.698)
    >>> gs.load_config("paper").text == cfg.text                     # the shipped copy
    True
    >>> gs.load_config("configs/missing.toml")
    Traceback (most recent call last):
        ...
    gainsched.errors.InputError: configs/missing.toml: cannot read (No such file or directory)
    """
    p = config_path(path)
    hint = ""
    if len(p.parts) == 1 and not p.suffix:  # a bare name: perhaps a shipped config
        hint = f"; the shipped configs are {', '.join(reference_configs())}"
    # up to 64 MiB is read so that _check_size can name the key that makes a config too
    # long (a list of a million speeds is 20 MiB); a longer file is refused unread
    text = read_text(p, what="config", limit=64 * MAX_CONFIG_CHARS,
                     allowed=f"{MAX_CONFIG_CHARS // 2**20} MiB", hint=hint)
    return _config(text, str(p), True)
