"""Where the grid sweep runs: this machine (joblib/loky) or a Dask cluster.

:func:`executor` is a context manager that yields the joblib settings
(:class:`Execution`) for :func:`gainsched.schedule.grid.build_grid`; ``gainsched build``
and ``gainsched sweep`` both use it::

    with executor("dask", "tcp://10.0.0.5:8786", n_jobs=-1) as ex:
        grid = build_grid(config, n_jobs=ex.n_jobs, backend=ex.backend)

(``ex.backend`` is None for dask: the backend is the one the executor
activated with ``joblib.parallel_config``.)

With ``backend="dask"`` it connects a :class:`dask.distributed.Client` to the
scheduler (short connect timeout), waits for a worker, checks that every
worker runs the same code and numerics as this machine (gainsched source
fingerprint, Python, numpy, scipy, joblib, BLAS, compiled-kernel use), and
activates joblib's ``"dask"`` backend on that client. The jobs are the same
one-per-speed jobs as the local build and joblib returns them in submission
order, so the table is byte-identical to the local build whatever order the
workers finish in. See ``docs/distributed.md``.

Every setup problem (dask missing, bad address, unreachable scheduler, no
workers, mismatched workers, cluster lost mid-build) raises
:class:`~gainsched.errors.InputError` naming the option.
"""

from __future__ import annotations

import hashlib
import platform
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import urlsplit

from ..errors import InputError
from ..native import reproducible, shm

__all__ = [
    "BACKENDS",
    "LOCAL_BACKENDS",
    "DEFAULT_CONNECT_TIMEOUT",
    "Execution",
    "executor",
    "check_options",
    "parse_scheduler",
    "environment",
]

#: joblib backends that run on this machine; ``"local"`` is an alias of ``"loky"``.
LOCAL_BACKENDS = ("local", "loky", "threading", "sequential")
#: every value ``--backend`` accepts.
BACKENDS = (*LOCAL_BACKENDS, "dask")
#: seconds to wait for the scheduler to answer (and for a first worker).
DEFAULT_CONNECT_TIMEOUT = 5.0
_SCHEMES = ("tcp", "tls")
_SRC = "command line"


@dataclass(frozen=True)
class Execution:
    """joblib settings for one build.

    Attributes
    ----------
    backend : str or None
        joblib backend to pass to ``joblib.Parallel``: ``"loky"``, ``"threading"``,
        ``"sequential"``, or None for dask, meaning "the backend the executor
        activated with ``joblib.parallel_config(backend="dask", client=...)"``
        (``Parallel(backend="dask")`` by name is broken in joblib 1.6: it passes
        ``nesting_level`` on to ``Client.submit`` and every task fails).
    n_jobs : int
        joblib ``n_jobs`` (-1: every core, or with dask every worker thread).
    description : str
        One line for the user, e.g. ``"dask tcp://127.0.0.1:8786 (2 workers, 4 threads)"``.
    """

    backend: str | None
    n_jobs: int
    description: str


def check_options(backend: str, scheduler: str | None) -> None:
    """Check the ``--backend`` / ``--scheduler`` combination (InputError naming the option)."""
    if backend not in BACKENDS:
        raise InputError(
            _SRC, "--backend", f"must be one of {', '.join(BACKENDS)}; got {backend!r}"
        )
    if scheduler is not None and backend != "dask":
        raise InputError(_SRC, "--scheduler", "is only used with --backend dask")
    if backend == "dask" and scheduler is None:
        raise InputError(_SRC, "--backend dask", "needs --scheduler tcp://HOST:PORT")


def parse_scheduler(address: str) -> str:
    """Normalise a scheduler address to ``SCHEME://HOST:PORT``.

    Accepts ``tcp://HOST:PORT``, ``tls://HOST:PORT``, ``HOST:PORT`` (tcp) and
    bracketed IPv6 hosts (``tcp://[::1]:8786``). Anything else raises InputError.
    """
    text = address.strip()
    bad = f"bad address {address!r}; expected tcp://HOST:PORT"
    if not text or any(c.isspace() for c in text):
        raise InputError(_SRC, "--scheduler", bad)
    if "://" not in text:
        text = "tcp://" + text
    try:
        parts = urlsplit(text)
        port = parts.port
    except ValueError:
        raise InputError(_SRC, "--scheduler", bad) from None
    if parts.scheme not in _SCHEMES:
        raise InputError(
            _SRC, "--scheduler", f"{bad} (scheme must be one of {', '.join(_SCHEMES)})"
        )
    if not parts.hostname or port is None or port == 0 or parts.path or parts.query or \
            parts.fragment or parts.username or parts.password:
        raise InputError(_SRC, "--scheduler", bad)
    host = f"[{parts.hostname}]" if ":" in parts.hostname else parts.hostname
    return f"{parts.scheme}://{host}:{port}"


def _code_fingerprint() -> str:
    """SHA-256 over the package's Python and C sources (relative path + content)."""
    root = Path(__file__).resolve().parents[1]  # the gainsched package
    h = hashlib.sha256()
    for p in sorted(root.rglob("*")):
        if p.suffix in (".py", ".c", ".h") and "__pycache__" not in p.parts and p.is_file():
            h.update(p.relative_to(root).as_posix().encode() + b"\0")
            h.update(p.read_bytes() + b"\0")
    return h.hexdigest()


def _blas() -> str:
    import numpy as np

    try:
        cfg = np.show_config(mode="dicts")["Build Dependencies"]["blas"]
        return f"{cfg.get('name', '?')} {cfg.get('version', '?')}"
    except Exception:  # the layout of show_config is not a stable API
        return "unknown"


def _native() -> str:
    """Whether the compiled Riccati kernel is used (it and the numpy fallback differ in bits)."""
    try:
        from .. import native

        return "compiled" if native.available("riccati") else "numpy fallback"
    except Exception:
        return "unknown"


def environment() -> dict[str, str]:
    """What decides the bits of a build on this process: code, versions, BLAS, kernels.

    Runs on the client and, through ``Client.run``, on every worker; the build
    is byte-identical to a local one only where all entries agree and every
    worker runs the pinned numerics (``"pinned"``, :mod:`gainsched.native.reproducible`).
    """
    import joblib
    import numpy
    import scipy

    from .. import __version__
    from ..native import reproducible

    return {
        "pinned": "yes" if reproducible.process_pinned() else "no",
        "numerics": reproducible.fingerprint(),
        "gainsched": __version__,
        "gainsched source": _code_fingerprint()[:16],
        "python": ".".join(platform.python_version_tuple()[:2]),
        "numpy": numpy.__version__,
        "scipy": scipy.__version__,
        "joblib": joblib.__version__,
        "BLAS": _blas(),
        "riccati kernel": _native(),
        "machine": platform.machine(),
    }


def _check_workers(client, where: str, timeout: float) -> str:
    """Wait for a worker, compare every worker's :func:`environment` with ours.

    Returns a short description of the cluster.
    """
    try:
        client.wait_for_workers(1, timeout=timeout)
    except Exception:
        raise InputError(_SRC, "--scheduler", f"{where}: no worker connected within {timeout:g} s "
                         f"(start one with: dask worker {where})") from None
    try:
        theirs = client.run(environment)
    except Exception as exc:
        raise InputError(_SRC, "--scheduler", f"{where}: a worker cannot run gainsched "
                         f"({type(exc).__name__}: {exc}); install it there: "
                         "pip install 'gainsched[dask]'") from None
    ours = environment()
    pin = reproducible.pin_available()
    for worker in sorted(theirs):
        env = theirs[worker]
        if pin and env.get("pinned") != "yes":
            start = " ".join(f"{k}='{v}'" for k, v in reproducible.PINNED_ENV.items())
            msg = (f"worker {worker} does not run the pinned numerics ({env.get('numerics')}); "
                   f"start workers with: env {start} dask worker {where}  (docs/distributed.md)")
            raise InputError(_SRC, "--scheduler", msg)
        for key in ours:
            if key == "pinned" or (pin and key == "numerics"):
                continue  # the pin above decides; this process need not be pinned itself
            if env.get(key) != ours[key]:
                msg = (
                    f"worker {worker} has {key} {env.get(key)}, this machine {ours[key]}; "
                    "every worker needs the same install for a byte-identical build "
                    "(docs/distributed.md)"
                )
                raise InputError(_SRC, "--scheduler", msg)
    threads = sum(client.ncores().values())
    return f"{len(theirs)} workers, {threads} threads"


@contextmanager
def _dask(scheduler: str, n_jobs: int, timeout: float) -> Iterator[Execution]:
    address = parse_scheduler(scheduler)  # a malformed address is wrong with or without dask
    try:
        from dask.distributed import Client, KilledWorker
        from distributed.comm.core import CommClosedError
        from joblib import parallel_config
    except ImportError:
        raise InputError(_SRC, "--backend dask", "dask is not installed; install the extra: "
                         "pip install 'gainsched[dask]'") from None
    try:
        client = Client(address, timeout=timeout)
    except OSError as exc:  # refused, unresolvable, silent: dask retries until the timeout
        msg = f"cannot reach the Dask scheduler at {address} within {timeout:g} s ({exc})"
        raise InputError(_SRC, "--scheduler", msg) from None
    except Exception as exc:  # something answered, but not in dask's protocol
        msg = f"{address} does not answer like a Dask scheduler ({type(exc).__name__}: {exc})"
        raise InputError(_SRC, "--scheduler", msg) from None
    try:
        info = _check_workers(client, address, timeout)
        with parallel_config(backend="dask", client=client, wait_for_workers_timeout=timeout):
            try:
                yield Execution(None, n_jobs, f"dask {address} ({info})")
            except (KilledWorker, CommClosedError) as exc:
                msg = f"lost the Dask cluster at {address} ({type(exc).__name__}: {exc})"
                raise InputError(_SRC, "--scheduler", msg) from None
    finally:
        client.close()


@contextmanager
def executor(backend: str = "local", scheduler: str | None = None, n_jobs: int = -1, *,
             connect_timeout: float = DEFAULT_CONNECT_TIMEOUT) -> Iterator[Execution]:
    """Run a build locally or on a Dask cluster; yields the :class:`Execution` to use.

    Parameters
    ----------
    backend : str
        ``"local"`` (= ``"loky"``, processes on this machine), ``"loky"``,
        ``"threading"``, ``"sequential"`` or ``"dask"``.
    scheduler : str, optional
        Dask scheduler address ``tcp://HOST:PORT`` (only, and required, with ``"dask"``).
    n_jobs : int
        joblib workers (-1: every core; with dask, every worker thread).
    connect_timeout : float, s
        How long to wait for the scheduler to answer and for a first worker.

    Raises
    ------
    InputError
        Bad option combination or address, dask not installed, scheduler
        unreachable, no or mismatched workers, cluster lost during the build.
    """
    check_options(backend, scheduler)
    if n_jobs == 0:
        raise InputError(_SRC, "--jobs", "must be -1 (all cores) or a non-zero worker count")
    if not connect_timeout > 0:
        raise InputError(_SRC, "--connect-timeout", f"must be > 0 s, got {connect_timeout:g}")
    shm.sweep()  # what killed builds left in /dev/shm (gainsched.native.shm)
    if backend != "dask":
        name = "loky" if backend == "local" else backend
        jobs = 1 if name == "sequential" else n_jobs
        if name == "loky":
            from .jobs import start_workers

            start_workers(jobs, "gainsched.schedule.grid")  # a build's circles
        yield Execution(name, jobs, f"local ({name}, n_jobs={jobs})")
        return
    with _dask(scheduler, n_jobs, connect_timeout) as ex:
        yield ex
