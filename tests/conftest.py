"""Shared fixtures, factories and markers of the whole suite (one place; docs in README,
"Tests").

- the paper config (configs/paper.toml), its reduced model and its committed table
  (tables/paper.h5), loaded once per test process;
- ``small_config(**keys)``: configs/paper.toml on a 2 x 2 x 8 grid with keys set on top
  (:mod:`support`), the one way a test makes a variant config;
- the markers ``needs_cc`` (a host C compiler), ``needs_arm`` (the Cortex-M4F cross
  compiler and QEMU), ``needs_cppcheck`` (cppcheck with its MISRA addon) and
  ``needs_dask`` (the dask extra, for a wheel installed without it), turned into
  skips with the reason in one hook (:func:`pytest_runtest_setup`);
- the reference circle of the link-model tests;
- ``fly(hidden)`` and ``diagnosed(hidden)``: the default campaign of
  :mod:`gainsched.sim.campaign` flown on a plant with a hidden effect (once per test
  run: :func:`support.once`), and its diagnosis (once per test module).

Parallel runs (``make test`` runs pytest-xdist): every fixture here is per worker
process and writes nothing outside pytest's own temporary folders, except the flown
campaigns, which the workers of one run share (``shared_dir``: the first to need one
flies it, the others wait for it and read it); compiled kernels go to the build's
content-keyed cache, which concurrent builders share safely
(gainsched/native/__init__.py).
"""

from __future__ import annotations

import importlib.util
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from scipy.interpolate import CubicSpline
from threadpoolctl import threadpool_limits

from gainsched.config import load_config
from gainsched.model.reduced import Model
from gainsched.schedule.nominal import nominal_from_path
from gainsched.schedule.path import circle_path, period
from gainsched.schedule.tables import load_table

import support
from support import ARM_TOOLS, CC, CIRCLE_SPEED, CIRCLE_TILT, PAPER_H5, PAPER_TOML

# One BLAS thread per test process when pytest-xdist runs one process per core: OpenBLAS'
# threads spin while they wait, and two processes' spinning threads on two cores made the
# solve-heavy tests up to 10x slower (measured: a 2 s grid fixture took 20 s). The
# results do not depend on it: builds pin one BLAS thread themselves
# (gainsched/native/reproducible.py).
if os.environ.get("PYTEST_XDIST_WORKER"):
    threadpool_limits(limits=1, user_api="blas")

# Every test converts the foreign logs it reads (the cache of converted logs would keep
# a conversion across runs and hide a change of the converter a test patches); the
# cache's own tests turn it on in a folder of their own (tests/analysis/test_logcache.py).
os.environ["GAINSCHED_LOG_CACHE"] = "0"

#: marker -> the reason a test with it is skipped, or None when the tools are here
_TOOL_SKIPS = {
    "needs_cc": None if CC is not None else "no C compiler (set CC, or install gcc)",
    "needs_arm": None if ARM_TOOLS is not None and CC is not None else (
        "processor-in-the-loop tests skipped: arm-none-eabi-gcc or qemu-system-arm not found "
        "(Debian: apt-get install gcc-arm-none-eabi libnewlib-arm-none-eabi qemu-system-arm, "
        "or `bash .ci/install-tools pil` as root)"),
    "needs_cppcheck": None if shutil.which("cppcheck") else (
        "cppcheck not found: the MISRA C:2012 check cannot run (Debian: apt-get install "
        "cppcheck, or `bash .ci/install-tools lint` as root)"),
    "needs_dask": None if importlib.util.find_spec("distributed") else (
        "dask is not installed (pip install 'gainsched[dask]'; make installs it)"),
}


def pytest_configure(config: pytest.Config) -> None:
    """Register ``needs_cppcheck`` beside the markers pyproject.toml lists (a change there
    would rebuild every checkout's venv)."""
    config.addinivalue_line(
        "markers", "needs_cppcheck: needs cppcheck and its MISRA addon (skipped, saying so)")
    config.addinivalue_line(
        "markers", "needs_dask: needs the dask extra (skipped, saying so)")


def pytest_runtest_setup(item: pytest.Item) -> None:
    """Skip a test whose toolchain marker names a tool this machine lacks, saying which."""
    for name, reason in _TOOL_SKIPS.items():
        if reason is not None and item.get_closest_marker(name) is not None:
            pytest.skip(reason)


# --------------------------------------------------------------------------- the paper


@pytest.fixture(scope="session")
def paper_path() -> Path:
    """Absolute path of configs/paper.toml."""
    return PAPER_TOML


@pytest.fixture(scope="session")
def paper_text() -> str:
    """The text of configs/paper.toml."""
    return PAPER_TOML.read_text()


@pytest.fixture(scope="session")
def paper_config():
    """The loaded paper config (frozen; safe to share)."""
    return load_config(PAPER_TOML)


@pytest.fixture(scope="session")
def paper_table():
    """The committed paper table, tables/paper.h5 (read once per test process; treat it as
    read-only)."""
    return load_table(PAPER_H5)


@pytest.fixture(scope="session")
def paper_c_scheduler(paper_table):
    """The paper table's gain source through the compiled C runtime
    (:func:`gainsched.sim.loop.c_runtime_scheduler`), compiled once per test process;
    None without a C compiler (a test that needs it is marked ``needs_cc``)."""
    if CC is None:
        return None
    from gainsched.sim.loop import c_runtime_scheduler

    return c_runtime_scheduler(paper_table)


@pytest.fixture(scope="session")
def model(paper_config):
    """Reduced model of the paper vehicle with the config's effects (drag)."""
    return Model(paper_config)


@pytest.fixture(scope="session")
def model_nodrag(paper_config):
    """Reduced model of the paper vehicle without any effect (conservative with zero thrust)."""
    return Model(paper_config, effects=())


@pytest.fixture(scope="session")
def circle(model):
    """Nominal 8 m/s circle at 20 deg: the Nominal and a periodic spline of u_d(t), N."""
    T = period(CIRCLE_SPEED, model.r)
    t = np.linspace(0.0, T, 721)
    nom = nominal_from_path(model, circle_path(CIRCLE_SPEED, model.r, t), CIRCLE_TILT)
    assert np.all(nom.reasons == 0)
    spline = CubicSpline(t, nom.u, bc_type="periodic")
    return nom, (lambda s: spline(s % T))


# --------------------------------------------------------------------------- factories


@pytest.fixture(scope="session")
def small_config():
    """The factory :func:`support.small_config`: ``small_config(grid__speeds=[3, 9])`` is
    the paper config on the small grid (2 x 2 x 8) with the speeds changed, validated."""
    return support.small_config


@pytest.fixture(scope="session")
def small_config_text():
    """The factory :func:`support.small_config_text`: the same as unvalidated TOML text
    (for a test that writes a bad value, or a file for the command line)."""
    return support.small_config_text


# --------------------------------------------------------------------------- campaigns


@pytest.fixture(scope="session")
def shared_dir(tmp_path_factory) -> Path:
    """A folder all test processes of this run share (under pytest-xdist, the parent of
    each worker's temporary base; a single process: its own), for :func:`support.once`."""
    base = tmp_path_factory.getbasetemp()
    root = base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base
    folder = root / "shared"
    folder.mkdir(exist_ok=True)
    return folder


@pytest.fixture(scope="module")
def fly(paper_config, paper_table, shared_dir):
    """The factory ``fly(hidden="none", scenarios=None, load_cell=True,
    real_tether=False)``: the flight logs (list of FlightLog) of
    :func:`gainsched.sim.campaign.campaign` on the plant with the hidden effect ``hidden``
    (a name of ``HIDDEN``), the paper table flying, flights of
    :data:`support.CAMPAIGN_DURATION` s: the default flights, or ``scenarios`` (Scenario
    objects, or names of default flights); ``load_cell=False`` drops the tension;
    ``real_tether``: on the elastic tether of a real vehicle (``REAL_TETHER``). Flown
    once per test run, whichever worker needs it first (:func:`support.once`; a
    campaign is deterministic, so who flies it does not matter), then kept per module."""
    from gainsched.sim.campaign import campaign, default_flights
    from gainsched.sim.loop import table_scheduler

    sched = table_scheduler(paper_table)
    cache = {}

    def get(hidden="none", scenarios=None, load_cell=True, real_tether=True):
        if scenarios is not None and all(isinstance(s, str) for s in scenarios):
            scenarios = [s for s in default_flights(support.CAMPAIGN_DURATION)
                         if s.name in scenarios]
        key = (hidden, None if scenarios is None else tuple(s.name for s in scenarios),
               load_cell, real_tether)
        if key not in cache:
            cache[key] = support.once(
                shared_dir, ("campaign", hidden, scenarios, load_cell, real_tether,
                             support.CAMPAIGN_DURATION),
                lambda: campaign(paper_config, sched, hidden,
                                 duration=support.CAMPAIGN_DURATION, scenarios=scenarios,
                                 load_cell=load_cell, real_tether=real_tether))
        return cache[key]

    return get


@pytest.fixture(scope="module")
def diagnosed(paper_config, fly):
    """The factory ``diagnosed(hidden, scenarios=None, real_tether=False)``:
    :func:`gainsched.analysis.diagnose.diagnose` of the paper config on ``fly(hidden,
    scenarios, real_tether=real_tether)``, once per module."""
    from gainsched.analysis.diagnose import diagnose

    cache = {}

    def get(hidden, scenarios=None, real_tether=True):
        key = (hidden, None if scenarios is None else tuple(
            s if isinstance(s, str) else s.name for s in scenarios), real_tether)
        if key not in cache:
            cache[key] = diagnose(paper_config, fly(hidden, scenarios,
                                                    real_tether=real_tether))
        return cache[key]

    return get
