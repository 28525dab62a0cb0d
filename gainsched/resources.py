"""The files the package ships: the reference configs.

In a checkout they are ``configs/*.toml``; the package reaches them as
``gainsched/configs`` (a link to that folder), and a wheel carries them there as
package data, so ``load_config("paper")`` and ``gainsched paper`` work from any folder
with nothing but the installed package (README, Set-up). The simulator's scenarios
ship the same way, in ``gainsched/sim/scenarios`` (:func:`gainsched.load_scenario`).
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

__all__ = ["reference_configs", "reference_config", "config_path"]


def _folder() -> Path:
    return Path(str(resources.files("gainsched") / "configs"))


def reference_configs() -> tuple[str, ...]:
    """The names of the configs the package ships, which ``load_config`` takes bare.

    The checkout's ``configs/*.toml``, carried by an installed package as package data:
    ``gs.load_config(name)`` loads one from any folder (a file of that name in the
    current folder comes first).

    Returns
    -------
    tuple of str
        The names, sorted, without the ``.toml``.

    Examples
    --------
    >>> gs.reference_configs()
    ('heavy_auto', 'paper', 'paper_hold', 'recommended')
    >>> gs.load_config("recommended").name
    'recommended'
    """
    return tuple(sorted(p.stem for p in _folder().glob("*.toml")))


def reference_config(name: str) -> Path | None:
    """The shipped config called ``name`` (``"paper"``), or None when there is none."""
    path = _folder() / f"{name}.toml"
    return path if name in reference_configs() else None


def config_path(path) -> Path:
    """The config file ``path`` names: the path itself when it is a file or has a folder or
    a suffix, else (a bare name such as ``"paper"``) the shipped config of that name when
    there is one.

    Example
    -------
    >>> config_path("paper").name, config_path("paper").parent.name
    ('paper.toml', 'configs')
    >>> str(config_path("my/own.toml"))
    'my/own.toml'
    """
    p = Path(path)
    if p.exists() or len(p.parts) != 1 or p.suffix:
        return p
    return reference_config(p.name) or p
