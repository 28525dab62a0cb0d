"""The model loop in one call, as ``gainsched improve`` runs it: compare, diagnose and
apply in rounds; rebuild the tables from the improved config; fly the standard flights
with the old table and the new; write the report (docs/model-vs-measurement.md, "The loop
in one command")."""

from __future__ import annotations

import contextlib
import shutil
from dataclasses import dataclass
from pathlib import Path

from ..analysis.improve import Improvement, write_improve
from ..config import Config, config_from_text
from ..errors import InputError
from ._build import Build, build_into
from ._logs import _as_read
from ._report import SILENT, Reporter, config_of, teller
from ._tables import table_for

__all__ = ["Improved", "StepFailure", "improve"]


@dataclass(frozen=True)
class StepFailure:
    """A step of :func:`improve` that failed (the steps before it are kept).

    Attributes
    ----------
    name : str
        The step: ``"compare and diagnose"``, ``"rebuild the tables"``, ``"fly the old
        and the new tables"`` or ``"check the new tables under the fit's uncertainty"``.
    why : str
        Why, in one line (with the exception's type when it is not a user error).
    undone : bool
        Whether what the step was writing was removed (a half-built ``tables/``).
    """

    name: str
    why: str
    undone: bool


@dataclass(frozen=True, eq=False)
class Improved:
    """What :func:`improve` did.

    Attributes
    ----------
    improvement : Improvement or None
        The rounds (:func:`gainsched.analysis.improve.improve`); None when the first step
        (compare and diagnose) failed.
    out_dir : Path or None
        The output folder (None: nothing written).
    build : Build or None
        The rebuilt tables (:func:`~gainsched.studies.build`), written to
        ``out_dir/tables``; None when none were built.
    flights : OldNewFlights or None
        The standard flights, old table against new
        (:func:`gainsched.sim.oldnew.fly_old_new`); None when not flown.
    not_flown : str or None
        Why the flights were not flown (None: they were).
    refusal : str or None
        Why no table can hold the improved config (an effect the tables' symmetry
        cannot carry), when that is why.
    uncertain : Uncertainty or None
        The rebuilt table's loops on plants over the last applied fit's 95 % box
        (:func:`gainsched.sim.uncertain.uncertain_loops`, as ``gainsched check
        --uncertain``); None when not checked.
    failed : StepFailure or None
        The step that failed; what was done before it is in ``out_dir``.
    said : tuple of str
        :meth:`lines`.
    """

    improvement: Improvement | None
    out_dir: Path | None
    build: Build | None = None
    flights: object = None
    not_flown: str | None = None
    refusal: str | None = None
    failed: StepFailure | None = None
    uncertain: object = None

    @property
    def config(self) -> Config:
        """The improved config (the last round's)."""
        return self.improvement.config

    @property
    def applied(self) -> list[str]:
        """The candidates written into the config, in order."""
        return self.improvement.applied

    @property
    def rounds(self) -> list:
        """The rounds (:class:`~gainsched.analysis.improve.Round`)."""
        return self.improvement.rounds

    said: tuple = ()

    def lines(self) -> list[str]:
        """What ``gainsched improve`` prints, in order: the rounds, the rebuilt tables, the
        flights old against new, and what was written (each told to the reporter as soon
        as it was known)."""
        return list(self.said)


_REBUILD, _FLY = "rebuild the tables", "fly the old and the new tables"
_UNCERTAIN = "check the new tables under the fit's uncertainty"
_UNCHANGED = "nothing was applied: the tables are CONFIG's own"
_NO_BUILD = "--no-build"  # the report says it as the command line does (build=False)


def improve(config, logs, out_dir=None, *, rounds: int = 3, exclude=(), build: bool = True,
            old_table=None, duration: float = 3.0, jobs: int = -1, channel_map=None,
            trust=(), sensors: bool = True, pose=None, pose_map=None, day: bool = False,
            uncertain: bool = True, samples: int | None = None,
            reporter: Reporter = SILENT) -> Improved:
    """The model loop in one call: what ``gainsched improve CONFIG LOGS -o OUT_DIR`` does.

    Compare and diagnose in rounds, applying each accepted fit, until no effect is
    missing (:func:`gainsched.analysis.improve.improve`); with ``out_dir``, write the
    improved config (its name kept: the same C symbols), rebuild the tables from it, fly
    the standard flights on the improved model with the old table and the new one, check
    the new table's loops over the last applied fit's 95 % box (as ``gainsched check
    --uncertain``), and write the report, the whole set published at once. A step that
    fails after the first keeps what was done before it (:attr:`Improved.failed`).

    Parameters
    ----------
    config : Config or path-like
        The model to improve.
    logs : list of path or FlightLog
        Two or more flights (held-out scores need them).
    out_dir : path-like, optional
        The output folder: ``NAME.toml``, ``tables/`` (rebuilt), ``report/``. None: the
        rounds only, nothing written.
    rounds : int, default 3
        The most diagnose rounds (1..10).
    exclude : sequence of str
        Candidates or effect kinds left out (diagnose's ``exclude``).
    build : bool, default True
        Rebuild the tables and fly them (with ``out_dir``); False: the config and the
        report only.
    old_table : Table or path-like, optional
        The table built from ``config`` that the old controller flies; default: as
        :func:`~gainsched.studies.table_for` finds it.
    duration, jobs : float (default 3.0), int (default -1)
        Seconds per standard flight; parallel workers of the rebuild (-1: every core).
    channel_map, trust, sensors
        As :func:`gainsched.diagnose` takes them.
    pose, pose_map, day
        A flight day, or a pose recorded apart, as :func:`~gainsched.studies.compare`
        takes them.
    uncertain, samples : bool (default True), int (default 8)
        Check the rebuilt table over the last applied fit's 95 % box with ``samples``
        random plants besides the estimate and the corners (docs/margins.md).
    reporter : Reporter, optional
        Shows the fits', the build's and the flights' progress; default: nothing.

    Returns
    -------
    Improved
        The rounds, the rebuilt tables, the flights, and :meth:`Improved.lines`, what the
        command prints.

    Raises
    ------
    InputError
        A bad log (naming it), an old table built from another config, before any work.

    Examples
    --------
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> logs = ["examples/flights/v3.csv", "examples/flights/v9.csv",
    ...         "examples/flights/v15.csv"]
    >>> imp = gs.improve(cfg, logs, rounds=1)
    >>> imp.applied, imp.config.name
    (['thrust_momentum + motor_lag'], 'paper')
    >>> imp.rounds[-1].rms < 0.5 * imp.rounds[0].rms
    True
    """
    from ..analysis.improve import improve as improve_rounds
    from ..schedule.tables import load_table

    cfg = config_of(config)
    old_path = None
    if old_table is not None and not hasattr(old_table, "built_from"):
        old_path, old_table = Path(old_table), load_table(old_table)
    if old_table is not None and not old_table.built_from(cfg):
        raise InputError(old_path or "old_table", "", f"was built from another config than "
                         f"{cfg.source}: the old table of the flights must be CONFIG's")
    logs = _as_read(cfg, logs, channel_map, trust, pose, pose_map, day)
    said, say = teller(reporter)

    with _fits(reporter) as fitted, _step("compare and diagnose", user_errors=False) as step:
        imp = improve_rounds(cfg, logs, rounds=rounds, exclude=exclude,
                             channel_map=channel_map, trust=trust, progress=fitted,
                             sensors=sensors)
    if step.failure is not None:  # nothing done before it: nothing to keep
        return Improved(None, None, failed=step.failure)
    say(f"round {k}: normalised RMS {r.rms:.3g}"
        + ("" if r.diagnosis is None else f": {r.diagnosis.verdict}")
        for k, r in enumerate(imp.rounds))
    if out_dir is None:
        return Improved(imp, None, said=tuple(said))
    out_dir = Path(out_dir)
    done = _publish(cfg, imp, out_dir, build, old_table, old_path, duration, jobs, reporter,
                    say, (samples,) if uncertain else None)
    return Improved(imp, out_dir, done.get("build"), done.get("flights"), done["not_flown"],
                    done.get("refusal"), done.get("failed"), done.get("uncertain"),
                    tuple(said))


def _publish(cfg, imp, out_dir: Path, build, old_table, old_path, duration, jobs, reporter,
             say, check=None) -> dict:
    """The output set of :func:`improve` published at once: the improved config, the
    rebuilt tables, the flights old against new and (``check``: ``(samples,)``) the new
    table under the fit's uncertainty (:func:`_rebuild_and_fly`, unless nothing was
    applied or ``build`` is false), the report; what was done (``build``, ``flights``,
    ``uncertain``, ``refusal``, ``failed``, ``not_flown``) returned, its lines said."""
    from ..publish import staged

    new, done = imp.config, {}
    with staged(out_dir) as stage:
        path = stage / f"{new.name}.toml"
        path.write_text(new.text)
        (stage / "report").mkdir()
        unchanged = not imp.applied  # the tables would be CONFIG's own, old = new
        if build and not unchanged:
            _rebuild_and_fly(cfg, old_table, old_path, config_from_text(
                new.text, str(out_dir / path.name)), stage, out_dir, duration, jobs,
                reporter, done, say)
            if check is not None and "build" in done and "failed" not in done:
                _check_uncertain(imp, stage, new.name, check[0], reporter, done)
        refusal, failed = done.get("refusal"), done.get("failed")
        done["not_flown"] = (
            _NO_BUILD if not build else _UNCHANGED if unchanged else
            refusal and f"the tables were not rebuilt: {refusal}" or
            failed and f"the step '{failed.name}' failed: {failed.why}" or None)
        write_improve(imp, stage / "report", done.get("flights"),
                      not_flown=done["not_flown"], uncertain=done.get("uncertain"))
    if done.get("flights") is not None:
        say(done["flights"].lines())
    if done.get("uncertain") is not None:
        say(done["uncertain"].lines(str(out_dir / "tables" / f"{new.name}.h5")))
    say([f"{out_dir}: {new.name}.toml ({', '.join(imp.applied) or 'nothing'} applied), "
         "report/" + (", tables/" if "build" in done else "")
         + (f"; tables not rebuilt: {refusal}" if refusal else
            "; nothing applied, so no tables rebuilt and no flights flown"
            if build and unchanged else "")])
    return done


def _rebuild_and_fly(cfg, old_table, old_path, new, stage, out_dir, duration, jobs, reporter,
                     done, say) -> None:
    """The rebuild of the tables from the improved config ``new`` into ``stage/tables`` and
    the flights old against new, each a step (:func:`_step`); what each gave (or why it
    did not) into ``done``, the build's lines to ``say``."""
    from ..firmware.outputs import check_outputs
    from ..schedule.tables import load_table
    from ..sim.oldnew import N_FLIGHTS, fly_old_new

    try:
        check_outputs(new)
    except InputError as held:
        done["refusal"] = f"no table can hold {held.where}: {held.message}"
        return
    (stage / "tables").mkdir()
    with _step(_REBUILD, stage / "tables") as step:
        done["build"] = build_into(new, stage / "tables", jobs=jobs, reporter=reporter)
        say(done["build"].lines(shown=out_dir / "tables"))
    if step.failure is not None:
        done.pop("build", None)
        done["failed"] = step.failure
        return
    with _step(_FLY) as step:
        if old_table is None:  # CONFIG's, as paper finds it
            old_table, old_path = table_for(cfg, reporter=reporter)
        new_table = load_table(stage / "tables" / f"{new.name}.h5")
        meta = {"old_table": str(old_path), "old_table_config_sha256": old_table.config_sha256,
                "new_table": str(out_dir / "tables" / f"{new.name}.h5"),
                "new_table_config_sha256": new_table.config_sha256}
        with reporter.bar("fly old and new tables", 2 * N_FLIGHTS, "flight") as bar:
            done["flights"] = fly_old_new(cfg, old_table, new, new_table, duration=duration,
                                          progress=bar.update, meta=meta)
    if step.failure is not None:
        done["failed"] = step.failure


def last_fit(imp: Improvement) -> tuple[int, dict] | None:
    """The round and the diagnosis report (``diagnose.json``'s data) of the last fit an
    improvement applied, or None: the box the rebuilt table is checked over."""
    fits = [(k, r.diagnosis) for k, r in enumerate(imp.rounds)
            if r.diagnosis is not None and r.diagnosis.applied]
    return (fits[-1][0], fits[-1][1].to_json()) if fits else None


def _check_uncertain(imp, stage, name, samples, reporter, done) -> None:
    """The step :data:`_UNCERTAIN`: the rebuilt table's loops over the last applied fit's
    95 % box into ``done["uncertain"]`` (its failure into ``done["failed"]``, the tables
    and flights kept). Its other applied fits stay at their estimates, as the table has
    them."""
    from ..schedule.tables import load_table
    from ..sim.uncertain import SAMPLES, plant_count, uncertain_loops

    samples = SAMPLES if samples is None else samples
    with _step(_UNCERTAIN) as step:
        k, report = last_fit(imp)
        source = f"round {k}'s diagnosis"
        table = load_table(stage / "tables" / f"{name}.h5")
        with reporter.bar(f"check {name} --uncertain", plant_count(report, samples, source),
                          "plant") as bar:
            done["uncertain"] = uncertain_loops(table, report, samples=samples,
                                                source=source, progress=bar.update)
    if step.failure is not None:
        done["failed"] = step.failure


class _Step:
    """One step of :func:`improve` (:func:`_step`): its ``failure`` once it failed."""

    def __init__(self, name: str, undo: Path | None):
        self.name, self.undo, self.failure = name, undo, None


@contextlib.contextmanager
def _step(name: str, undo: Path | None = None, user_errors: bool = True):
    """Run one step of :func:`improve` whose failure must not lose the steps before it: an
    error (a bound of the config not met, or any fault of the step) is caught and kept
    in one line (:class:`StepFailure`, with the exception's type when it is not a user
    error), and ``undo`` (a folder the step was writing) removed; Ctrl-C still stops the
    whole call. ``user_errors=False``: an InputError (a bad log) passes through."""
    step = _Step(name, undo)
    try:
        yield step
    except Exception as exc:  # noqa: BLE001 - every fault of the step becomes its one line
        if isinstance(exc, InputError) and not user_errors:
            raise
        text = " ".join(str(exc).split()) or "no message"
        why = text if isinstance(exc, InputError) else f"{type(exc).__name__}: {text}"
        if undo is not None:
            shutil.rmtree(undo, ignore_errors=True)
        step.failure = StepFailure(name, why, undo is not None)


@contextlib.contextmanager
def _fits(reporter: Reporter):
    """The progress of diagnose's fits: yields the ``progress(name)`` callback that counts
    a fit and names its candidate on a bar of ``reporter``."""
    with reporter.bar("improve", unit="fit") as bar:
        def fitted(name):
            bar.set_postfix_str(name, refresh=False)
            bar.update()

        yield fitted
