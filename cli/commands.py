"""The function that runs each command: ``func(kind, ns)``, `kind` the problem's kind (:mod:`eosp.kinds`)."""

from __future__ import annotations

from eosp.cli.export_schedule import cmd_export_schedule
from eosp.cli.generate import cmd_generate
from eosp.cli.import_export import cmd_export, cmd_import
from eosp.cli.info import cmd_info
from eosp.cli.plot import cmd_plot
from eosp.cli.report import cmd_report
from eosp.cli.scenario import cmd_scenario
from eosp.cli.simulate import cmd_simulate
from eosp.cli.solve import cmd_solve
from eosp.cli.validate import cmd_validate

COMMAND_FUNCTIONS = {"generate": cmd_generate, "import": cmd_import, "export": cmd_export, "info": cmd_info,
                     "validate": cmd_validate, "solve": cmd_solve, "build-shards": None, "plot": cmd_plot,
                     "export-schedule": cmd_export_schedule, "report": cmd_report, "scenario": cmd_scenario,
                     "simulate": cmd_simulate}
