"""Fixtures several test modules share: the thesis HU40T machine, its
octagonal TANGO table and the Table 4-2 plan (built once per session), and
the example c600u machine (once per module: some tests edit it)."""
import pytest

import fivecal
from fivecal.demo import example_machine_path
from fivecal.procedures import tango


@pytest.fixture(scope="session")
def hu40t():
    return tango.hu40t_machine()


@pytest.fixture(scope="session")
def table():
    return tango.octagonal_table()


@pytest.fixture(scope="session")
def plan(table, hu40t):
    """The Table 4-2 touch plan on the octagonal table."""
    return tango.hu40t_plan(table, hu40t)


@pytest.fixture(scope="module")
def c600u():
    return fivecal.Machine.load(example_machine_path("c600u"))


def pytest_collection_modifyitems(config, items):
    """Under pytest-xdist (scripts/test.sh runs ``-n JOBS --dist loadgroup``)
    the tests of modules that drive LinuxCNC stay on one worker: only one
    LinuxCNC runs on a machine at a time (the harness's file lock), so two
    workers would take turns waiting on each other's simulator."""
    import linuxcnc_harness

    for item in items:
        mod = getattr(item, "module", None)
        if mod is not None and any(v is linuxcnc_harness for v in vars(mod).values()):
            item.add_marker(pytest.mark.xdist_group("linuxcnc"))


def pytest_report_header(config):
    """Which fivecal the run tests: the installed package (scripts/test.sh, CI)
    or a tree's python/ (PYTHONPATH=python after scripts/dev builds)."""
    import fivecal

    return f"fivecal {fivecal.__version__} from {fivecal.__file__}"
