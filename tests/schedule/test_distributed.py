"""Builds and sweeps on a Dask cluster (gainsched.schedule.distributed, gainsched.schedule.sweep).

A two-worker ``dask.distributed.LocalCluster`` on loopback (worker processes,
so tasks are pickled and gainsched is imported remotely, as on a real cluster)
runs a reduced paper grid; the tables must equal the local build byte for byte.
Skipped when dask is not installed, except the checks that need no cluster.
"""

from __future__ import annotations

import csv
import hashlib
import json
import socket
import sys

import pytest
from click.testing import CliRunner

from gainsched.cli import cli
from gainsched.config import config_from_text
from gainsched.errors import InputError
from gainsched.native import reproducible
from gainsched.schedule.sweep import make_sweep, parse_sigma, parse_vary

SPEEDS = [3, 6, 9, 12]  # m/s


@pytest.fixture(scope="module")
def small_text(small_config_text) -> str:
    """configs/paper.toml on a reduced grid (4 speeds x 2 tilts x 8 azimuths): ~1 s to build."""
    text = small_config_text(grid__speeds=SPEEDS)
    cfg = config_from_text(text)
    assert list(cfg.grid.speeds) == SPEEDS and cfg.grid.tilts.size == 2
    return text


@pytest.fixture(scope="module")
def small_path(small_text, tmp_path_factory):
    p = tmp_path_factory.mktemp("cfg") / "small.toml"
    p.write_text(small_text)
    return p


@pytest.fixture(scope="module")
def scheduler():
    """Address of a 2-worker, 1-thread-each LocalCluster on 127.0.0.1, workers started with
    the pinned numerics (as docs/distributed.md tells users to start theirs)."""
    distributed = pytest.importorskip("dask.distributed")
    with pytest.MonkeyPatch.context() as mp:  # the worker processes inherit this environment
        for key, value in reproducible.PINNED_ENV.items():
            mp.setenv(key, value)
        with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                      host="127.0.0.1", dashboard_address=":0") as cluster:
            yield cluster.scheduler_address


@pytest.fixture(scope="module")
def local_build(small_path, tmp_path_factory):
    """Folder of the local (loky) build of the small config."""
    out = tmp_path_factory.mktemp("local")
    res = CliRunner().invoke(cli, ["build", str(small_path), "-o", str(out), "-j", "2"])
    assert res.exit_code == 0, res.output
    return out


def _invoke(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def _one_line_error(res, *needles):
    assert res.exit_code == 2, res.output
    err = res.stderr.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("gainsched: error: "), res.stderr
    assert "Traceback" not in res.output
    for n in needles:
        assert n in err[0], err[0]


def _sha(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


# --------------------------------------------------------------------------- build


@pytest.mark.slow
def test_dask_build_equals_local_build_byte_for_byte(scheduler, small_path, local_build, tmp_path):
    res = _invoke("build", small_path, "-o", tmp_path, "--backend", "dask", "--scheduler",
                  scheduler)
    assert res.exit_code == 0, res.output
    assert f"on dask {scheduler} (2 workers, 2 threads)" in res.stderr
    for name in ("small.h5", "small_gains.h"):
        assert (tmp_path / name).read_bytes() == (local_build / name).read_bytes(), name


def test_result_order_does_not_follow_completion_order(scheduler, small_path, local_build,
                                                       tmp_path, monkeypatch):
    """The low speeds are made to finish last on the cluster; the table is unchanged."""
    from gainsched.schedule import jobs

    handed_back = []  # (finish time on the worker, speed), in the order build_grid gets them
    workers = set()

    def timed(func, delay, *args, **kwargs):  # runs on a worker (pickled by value)
        import time

        from distributed import get_worker  # raises outside a Dask worker

        time.sleep(delay)
        return func(*args, **kwargs), time.time(), get_worker().address

    class SlowLowSpeeds(jobs.Parallel):
        def __call__(self, iterable):
            jobs = [(timed, (f, 0.5 * (1 - args[1] / SPEEDS[-1]), *args), kw)
                    for f, args, kw in iterable]  # args = (config, speed, tilts)
            for i, (out, t, worker) in enumerate(super().__call__(jobs)):
                handed_back.append((t, jobs[i][1][3]))
                workers.add(worker)
                yield out

    monkeypatch.setattr(jobs, "Parallel", SlowLowSpeeds)
    res = _invoke("build", small_path, "-o", tmp_path, "--backend", "dask", "--scheduler",
                  scheduler)
    assert res.exit_code == 0, res.output
    assert [v for _, v in handed_back] == SPEEDS  # results come back in submission order...
    assert [v for _, v in sorted(handed_back)] != SPEEDS  # ...though they finished otherwise
    assert workers and all(w.startswith("tcp://127.0.0.1:") for w in workers)  # on the cluster
    assert (tmp_path / "small.h5").read_bytes() == (local_build / "small.h5").read_bytes()


# --------------------------------------------------------------------------- sweep


def test_sweep_on_dask_rows_and_tables_equal_individual_builds(scheduler, small_path, tmp_path):
    out = tmp_path / "sweep"
    res = _invoke("sweep", small_path, "--vary", "vehicle.mass=0.45,0.55", "--vary",
                  "tether.length=1.4", "-o", out, "--backend", "dask", "--scheduler",
                  scheduler)
    assert res.exit_code == 0, res.output
    rows = list(csv.DictReader((out / "sweep.csv").open()))
    assert [r["variant"] for r in rows] == ["small-v000", "small-v001"]
    assert [float(r["vehicle.mass"]) for r in rows] == [0.45, 0.55]
    assert [float(r["tether.length"]) for r in rows] == [1.4, 1.4]
    doc = json.loads((out / "sweep.json").read_text())
    assert doc["vary"] == {"vehicle.mass": [0.45, 0.55], "tether.length": [1.4]}
    assert [v["variant"] for v in doc["variants"]] == ["small-v000", "small-v001"]
    for r in rows:
        assert 0 < float(r["feasible_pct"]) <= 100
        assert 0 < float(r["worst_spectral_radius"]) < 1
        assert float(r["max_abs_K"]) > 0 and float(r["min_tension_margin_N"]) >= 0
        table = out / r["table"]
        assert r["table_sha256"] == _sha(table)
        # the variant's config file rebuilds its table byte for byte, locally
        single = tmp_path / r["variant"]
        built = _invoke("build", out / f"{r['variant']}.toml", "-o", single, "-j", "2")
        assert built.exit_code == 0, built.output
        assert (single / f"{r['variant']}.h5").read_bytes() == table.read_bytes()
    # the two masses give different tables, and each config names its own values
    assert rows[0]["table_sha256"] != rows[1]["table_sha256"]
    text = (out / "small-v001.toml").read_text()
    assert "mass = 0.55" in text and "length = 1.4" in text and 'name = "small-v001"' in text


def test_monte_carlo_is_seeded(small_text):
    base = config_from_text(small_text, "small.toml")

    def plan(seed, n=4):
        return make_sweep(base, [parse_vary("vehicle.mass=0.45,0.55")], monte_carlo=n,
                          seed=seed, sigma=[parse_sigma("vehicle.inertia.zz=0.03"),
                                            parse_sigma("effects.drag.mu1=0.2")])

    a, b, c = plan(1), plan(1), plan(2)
    params = [v.params for v in a.variants]
    assert params == [v.params for v in b.variants]
    assert [v.config.text for v in a.variants] == [v.config.text for v in b.variants]
    assert params != [v.params for v in c.variants]
    assert len(params) == 8 and len({v.name for v in a.variants}) == 8
    # common random numbers: each mass gets the same draws
    assert [p[1:] for p in params[:4]] == [p[1:] for p in params[4:]]
    zz = [dict(p)["vehicle.inertia.zz"] for p in params[:4]]
    assert len(set(zz)) == 4 and all(0.0045 * 0.6 < x < 0.0045 * 1.4 for x in zz)
    assert a.variants[0].config.vehicle.inertia[2, 2] == zz[0]


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (["--vary", "vehicle.mas=1,2"], ["--vary vehicle.mas", "unknown", "vehicle.mass"]),
        (["--vary", "grid.speeds=1"], ["--vary grid.speeds"]),
        (["--vary", "vehicle.inertia=1"], ["--vary vehicle.inertia", "not a real-valued"]),
        (["--vary", "effects.motor_lag.tau=0.1"], ["effects.motor_lag", "no [effects.motor_lag]"]),
        (["--vary", "vehicle.mass=0.5,abc"], ["--vary vehicle.mass", "'abc'"]),
        (["--vary", "vehicle.mass=-1"], ["vehicle.mass", "must be > 0"]),
        (["--vary", "vehicle.mass"], ["--vary", "KEY=VALUE"]),
        (["--vary", "vehicle.mass=1", "--vary", "vehicle.mass=2"], ["more than once"]),
        (["--monte-carlo", "3"], ["--monte-carlo", "--sigma"]),
        (["--vary", "g=9.8", "--sigma", "g=0.1"], ["--sigma", "--monte-carlo"]),
        (["--monte-carlo", "2", "--sigma", "vehicle.kappa=-0.1"], ["--sigma vehicle.kappa"]),
        ([], ["--vary"]),
    ],
)
def test_sweep_bad_keys_give_one_line(small_path, tmp_path, args, needles):
    _one_line_error(_invoke("sweep", small_path, "-o", tmp_path, *args), *needles)
    assert not any(tmp_path.iterdir())  # nothing built


# --------------------------------------------------------------------------- errors


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize("command", ["build", "sweep"])
def test_unreachable_scheduler(small_path, tmp_path, command):
    pytest.importorskip("dask.distributed")
    addr = f"tcp://127.0.0.1:{_closed_port()}"
    extra = ["--vary", "vehicle.mass=0.5"] if command == "sweep" else []
    res = _invoke(command, small_path, "-o", tmp_path, *extra, "--backend", "dask",
                  "--scheduler", addr, "--connect-timeout", "0.5")
    _one_line_error(res, "--scheduler", "cannot reach the Dask scheduler", addr)


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (["--backend", "dask", "--scheduler", "foo://h:1"], ["--scheduler", "bad address"]),
        (["--backend", "dask", "--scheduler", "tcp://h"], ["--scheduler", "bad address"]),
        (["--backend", "dask", "--scheduler", "tcp://h:99999"], ["--scheduler", "bad address"]),
        (["--backend", "dask", "--scheduler", "h 1"], ["--scheduler", "bad address"]),
        (["--scheduler", "tcp://127.0.0.1:8786"], ["--scheduler", "only used with --backend dask"]),
        (["--backend", "dask"], ["--backend dask", "needs --scheduler"]),
        (["--backend", "local", "-j", "0"], ["--jobs"]),
    ],
)
def test_bad_cluster_options(small_path, tmp_path, args, needles):
    _one_line_error(_invoke("build", small_path, "-o", tmp_path, *args), *needles)


def test_dask_not_installed(small_path, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "dask.distributed", None)  # import raises ImportError
    res = _invoke("build", small_path, "-o", tmp_path, "--backend", "dask", "--scheduler",
                  "tcp://127.0.0.1:8786")
    _one_line_error(res, "--backend dask", "dask is not installed", "pip install 'gainsched[dask]'")


def test_mismatched_worker_is_refused(scheduler, monkeypatch):
    """A worker whose numerics differ from this machine's cannot join the build."""
    from gainsched.schedule import distributed as gd

    monkeypatch.setattr(gd, "_blas", lambda: "other-blas 0.0")  # this process only
    with pytest.raises(InputError, match=r"worker tcp://\S+ has BLAS .*, this machine other-blas"):
        with gd.executor("dask", scheduler, 2):
            pass


@pytest.mark.skipif(not reproducible.pin_available(), reason="no pin on this CPU")
def test_unpinned_worker_is_refused(monkeypatch):
    """A worker started without the pinned numerics (here: Sandybridge BLAS kernels) would
    round differently: the check names it and says how to start workers."""
    from gainsched.schedule import distributed as gd

    distributed = pytest.importorskip("dask.distributed")
    monkeypatch.setenv("OPENBLAS_CORETYPE", "Sandybridge")  # runs on any AVX2 CPU
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                                  host="127.0.0.1", dashboard_address=":0") as cluster:
        with pytest.raises(InputError, match=r"does not run the pinned numerics .*Sandybridge.*"
                           r"OPENBLAS_CORETYPE='Haswell'"):
            with gd.executor("dask", cluster.scheduler_address, 1):
                pass
