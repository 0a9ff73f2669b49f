"""Calibration history: a store of identifications (SQLite, one file), their
comparison, trend and change detection, and fleet runs on Dask.

    from fivecal import history
    with history.Store("machines.fcdb") as s:
        s.add(result, machine_id="HU40-17", procedure="sphere")
        cals = s.list("HU40-17")
    print(history.compare(cals[-2], cals[-1], machine=s.machine("HU40-17")).report())
    charts = history.detect(cals)               # CUSUM, 0.1 % false alarms per calibration

Command line: ``fivecal history add|list|show|compare|export|trend`` and
``fivecal fleet identify``; docs/history.md. Dask and pyarrow are optional
(``pip install 'fivecal[fleet]'``); importing this package needs neither.
"""
from .store import (AlreadyRecorded, Calibration, MIGRATIONS, SCHEMA_VERSION, Store, calibration_from_result,
                    dataset_digest, read_parquet, utc_time, write_parquet)
from . import fleet, fleetsim  # noqa: E402  (neither imports Dask at import time)
from .trend import (Chart, ChartDesign, Comparison, Grade, PooledStatistics, check_same_machine, compare, cusum,
                    cusum_interval, default_grid, detect, first_alarm, grade, gum_from_history, machine_error_names,
                    plot_trend, pooled_statistics, siegmund_arl, volumetric_change, volumetric_errors)

__all__ = ["AlreadyRecorded", "Calibration", "MIGRATIONS", "SCHEMA_VERSION", "Store", "calibration_from_result",
           "dataset_digest", "read_parquet", "utc_time", "write_parquet", "Chart", "ChartDesign", "Comparison", "Grade",
           "PooledStatistics", "check_same_machine", "compare", "cusum", "cusum_interval", "default_grid", "detect",
           "first_alarm", "grade", "gum_from_history", "machine_error_names", "plot_trend", "pooled_statistics",
           "siegmund_arl", "volumetric_change", "volumetric_errors"]
