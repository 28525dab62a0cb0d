"""gainsched: gain-scheduling compiler for a tethered quadcopter on great circles.

The public API, by task (docs/api.md lists every name with its summary)::

    import gainsched as gs

    cfg = gs.load_config("configs/paper.toml")        # a validated config
    sol = gs.solve_circle(cfg, 9.0, [0.0, 0.35])      # one speed, two tilts (rad)
    table = gs.load_table("tables/paper.h5")          # a built schedule
    gains = gs.Interpolator(table)(0.5, 3.0, 0.2)     # K, u_d, phi_d at (xi, xi_dot, alpha)
    res = gs.simulate(cfg, gs.table_scheduler(table), gs.load_scenario("horizontal"))
    cmp = gs.compare(cfg, ["examples/flights/v9.csv"])  # model versus a flight log

The names are imported on first use (PEP 562 ``__getattr__``): ``import gainsched``
stays at 0.1 s where importing every sub-package takes 2 s (scipy, matplotlib), which
the command line would pay on every call.
"""

from importlib import import_module

#: The public API: (task, module, names), in the order of docs/api.md. The one list of
#: it: ``__all__``, ``__getattr__`` and the page are made from it.
API = (
    ("A config", "config", ("load_config", "config_from_text", "Config")),
    ("The shipped configs", "resources", ("reference_configs",)),
    ("A schedule", "schedule.grid", ("solve_circle", "CircleSolution", "build_grid",
                                     "GridResult")),
    ("Choosing the grid", "schedule.refine", ("refine_grid", "GridChoice")),
    ("Publishing a schedule", "firmware.outputs", ("write_outputs",)),
    ("The command line's workflows", "studies", ("build", "Build", "sweep", "SweepRun",
                                                 "fly", "Flight", "paper", "PaperRun",
                                                 "campaign", "CampaignRun", "Reporter")),
    ("A table", "schedule.tables", ("load_table", "Table")),
    ("Looking up gains", "firmware.runtime", ("Interpolator", "Lookup")),
    ("The compact table format", "firmware.compact", ("compact_data", "CompactData",
                                                      "CompactInterpolator")),
    ("Checking a table", "firmware.host.check", ("midpoint_check",)),
    ("Stability margins", "schedule.margins", ("loop_margins", "LoopMargins",
                                               "crossover_frequency")),
    ("The worst margins of a grid", "schedule.margin_report", ("worst_margins",)),
    ("Motor commands", "actuators", ("command_from_thrust", "thrust_from_command")),
    ("Seeing a table", "schedule.viewer", ("schedule_figures", "schedule_plots",
                                           "table_summary")),
    ("A flight in simulation", "sim.loop", ("load_scenario", "Scenario", "simulate",
                                            "SimResult", "Scheduler", "table_scheduler",
                                            "runtime_scheduler", "metrics",
                                            "log_from_result")),
    ("Seeing a flight", "sim.plots", ("plot_result", "tracking_errors")),
    ("Flight logs", "analysis.logs", ("read_log", "FlightLog")),
    ("Model versus measurement", "analysis.compare", ("compare", "Comparison")),
    ("Which effect is missing", "analysis.diagnose", ("diagnose", "Diagnosis",
                                                      "apply_candidate", "apply_diagnosis",
                                                      "sensor_calibration")),
    ("The model loop in one call", "studies", ("improve", "Improved", "StepFailure")),
    ("The model loop's rounds and report", "analysis.improve", ("Improvement",
                                                                "write_improve")),
    ("Reports", "analysis.reports", ("write_compare", "write_diagnose")),
    ("Errors", "errors", ("InputError",)),
)

_MODULE_OF = {name: module for _, module, names in API for name in names}

__all__ = ["__version__", *_MODULE_OF]


def _version() -> str:
    # importlib.metadata takes 40 ms to import: not before the command line's entry point
    # is ready for a Ctrl-C (gainsched/__main__.py)
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("gainsched")
    except PackageNotFoundError:  # running from a source tree without install
        return "0.0.0"


def __getattr__(name: str):
    if name == "__version__":
        value = globals()[name] = _version()
        return value
    if name == "studies":  # the workflow layer's own namespace (gs.studies.compare, ...)
        value = globals()[name] = import_module(f"{__name__}.studies")
        return value
    module = _MODULE_OF.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(f"{__name__}.{module}"), name)
    globals()[name] = value  # next time without this function
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
