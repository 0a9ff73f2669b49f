"""fivecal: geometric error identification for five-axis machine tools.

Units: mm for lengths and linear commands, degrees for rotary commands, rad
for angular error parameters. Conventions: README "Concepts"; file formats: docs/formats.md.
"""
from .dataset import Dataset, ball_dataset, load_dataset, save_dataset
from .io import columnar as _columnar  # noqa: F401  (load_dataset / save_dataset read and write Parquet through it)
from .guards import CorrectionLimitError, FitWarning, UnusableResultError
from .identification import Result, identify, resolve_estimate
from .machine import Machine, RadiansWarning
from .units import UnitsWarning
from .simulation import simulate
from .compensation import compensate_gcode, compensate_poses, write_error_table
from .report import write_report
from .procedures import dbb, probing_stats
from .procedures.dbb import Trace, circular_test, jiang_cripps, read_trace_csv, wang_identify, wang_path
from . import uncertainty
from .uncertainty import gum_input_covariance, monte_carlo
from ._version import __version__

__all__ = ["Machine", "RadiansWarning", "UnitsWarning", "Dataset", "ball_dataset", "load_dataset", "save_dataset", "simulate",
           "identify", "resolve_estimate", "Result", "FitWarning", "UnusableResultError",
           "CorrectionLimitError", "compensate_poses", "compensate_gcode",
           "write_error_table", "write_report", "dbb", "Trace", "jiang_cripps", "wang_path",
           "wang_identify", "circular_test", "read_trace_csv", "uncertainty", "monte_carlo",
           "gum_input_covariance", "probing_stats", "__version__"]
