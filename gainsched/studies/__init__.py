"""The workflows of the command line as functions a script calls (docs/architecture.md).

A study does one whole job of a ``gainsched`` command: it takes what the command's
options say, checks its inputs before any work, publishes its output set at once, shows
its progress through a :class:`Reporter` (none by default) and returns a named result
whose ``lines()`` are what the command prints. The command line only parses, calls one
study and prints (gainsched/cli), so a script gets the same results and files.

- :func:`build`: a config's gain table and C files (``gainsched build``);
- :func:`sweep`: a table per vehicle variant and a results table (``gainsched sweep``);
- :func:`fly`: one scenario flown, its log, metrics and plots (``gainsched simulate``);
- :func:`paper`: the paper's experiments flown and their report (``gainsched paper``);
- :func:`campaign`: a synthetic test campaign's logs (``gainsched campaign``);
- :func:`compare`: a model against flight logs and its report (``gainsched compare``);
- :func:`diagnose`: the missing effect, the config with it and the report (``gainsched
  diagnose``);
- :func:`convert`: a PX4 ULog or a ROS 2 bag in the project's log format (``gainsched
  convert``);
- :func:`topics`: what a ULog or a bag holds, for writing its channel map (``gainsched
  convert --list``);
- :func:`plan`: the flights that would settle a diagnosis (``gainsched plan``);
- :func:`improve`: the model loop, the rebuild and the flights old against new
  (``gainsched improve``);
- :func:`plot`: a table's pictures and their summary (``gainsched plot``);
- :func:`export_c`: a table's C files for the firmware (``gainsched export-c``);
- :func:`validate`: a config checked and summarised (``gainsched validate``);
- :func:`nominal`: the nominal flight of one circle over the azimuth (``gainsched
  nominal``);
- :func:`inspect`: a table's summary and its flight envelope (``gainsched inspect``);
- :func:`check`: a table's interpolation checked at the cell midpoints (``gainsched
  check``);
- :func:`check_uncertain`: a table's loops on the plants of a diagnosis's 95 % box
  (``gainsched check --uncertain``);
- :func:`table_for`: the table a config flies when none is given.

The names are imported on first use (PEP 562, as the package root does): a command
starts without the modules of the studies it does not run.
"""

from importlib import import_module

#: name -> its private module: the one list of the studies' public names
_MODULE_OF = {
    "Build": "_build", "build": "_build", "output_names": "_build",
    "Reporter": "_report", "SILENT": "_report",
    "table_for": "_tables", "plot": "_tables", "Plots": "_tables",
    "export_c": "_firmware", "Export": "_firmware",
    "improve": "_improve", "Improved": "_improve", "StepFailure": "_improve",
    "fly": "_flights", "Flight": "_flights", "paper": "_flights", "PaperRun": "_flights",
    "campaign": "_flights", "CampaignRun": "_flights",
    "sweep": "_sweep", "SweepRun": "_sweep",
    "compare": "_logs", "ComparisonReport": "_logs", "diagnose": "_logs",
    "DiagnosisReport": "_logs", "convert": "_logs", "Conversion": "_logs",
    "topics": "_logs",
    "plan": "_plan", "Planned": "_plan",
    "validate": "_circles", "Validation": "_circles", "nominal": "_circles",
    "NominalCircle": "_circles",
    "inspect": "_inspect", "Inspection": "_inspect", "check": "_inspect", "Check": "_inspect",
    "check_uncertain": "_uncertain", "UncertainCheck": "_uncertain",
}

__all__ = list(_MODULE_OF)


def __getattr__(name: str):
    module = _MODULE_OF.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
