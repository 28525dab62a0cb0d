"""Configuration: TOML in, one frozen dataclass tree out.

``load_config(path)`` is the only way in. Every key is checked at this
boundary (unknown key, wrong type, missing key, impossible value) and a bad
one raises :class:`~gainsched.errors.InputError` naming the file and the
dotted key. Degrees exist only here (keys ending in ``_deg``); the dataclasses
hold SI units.

Besides types and ranges, the checks refuse what would only fail late in a
build: a name that is not a safe file name (:func:`check_name`), grid axes that
collapse in the tables' float32 (:func:`~gainsched.config._checks.check_float32_axis`), a
weight Q that leaves the azimuth undetectable, a physically absurd vehicle, a control rate
that undersamples the fastest circle (:func:`~gainsched.config._checks.check_rate`), a
build that would need more memory or CPU time than ``[limits]`` allows
(:func:`check_budget`), and a config no build could fly (``_plausible``: gravity,
lengths, hover, a flyable circle).

One concept per private module, every public name re-exported here:

- ``_schema``: the frozen dataclasses, one per section (:class:`Vehicle`, ...);
- ``_checks``: :class:`Section` (a TOML table read key by key, unknown keys refused
  with the likely meant one) and the ``check_*`` helpers several sections share;
- ``_sections``: one reader per section of the file (``read_vehicle``, ...);
- ``_reader``: :class:`Config`, :func:`load_config`, :func:`config_from_text` and the
  validation pass, with the checks across sections;
- ``_budget``: the memory and CPU time a build needs, estimated (:func:`estimate_build`,
  :func:`check_budget`);
- ``_plausible``: the physics a config must have for any build to fly (:func:`balance`,
  :data:`MAX_TETHER_LENGTH`);
- ``_edit``: a config's text edited as a TOML document, comments and layout kept
  (:func:`set_values`, :func:`set_section`, ...: config variants).
"""

from __future__ import annotations

from ..constants import N_INPUT, N_STATE
from ._budget import GIB, BuildConfig, BuildEstimate, check_budget, estimate_build
from ._checks import Section, check_name
from ._edit import get_value, has_section, remove_key, set_section, set_value, set_values
from ._plausible import MAX_TETHER_LENGTH, balance
from ._reader import Config, config_from_text, load_config
from ._schema import (
    TERMINAL_COSTS,
    Analysis,
    AxisRange,
    AzimuthRange,
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
from ._sections import MAX_RATE_HZ, MAX_SPEED

__all__ = [
    "Config",
    "Vehicle",
    "Tether",
    "Control",
    "Grid",
    "AxisRange",
    "AzimuthRange",
    "Feasibility",
    "Analysis",
    "Limits",
    "Sensors",
    "Firmware",
    "EffectSpec",
    "load_config",
    "config_from_text",
    "check_name",
    "N_STATE",
    "N_INPUT",
    "Section",
    "MAX_SPEED",
    "MAX_RATE_HZ",
    "TERMINAL_COSTS",
    "BuildConfig",
    "BuildEstimate",
    "estimate_build",
    "check_budget",
    "GIB",
    "MAX_TETHER_LENGTH",
    "balance",
    "get_value",
    "has_section",
    "set_value",
    "set_values",
    "remove_key",
    "set_section",
]
