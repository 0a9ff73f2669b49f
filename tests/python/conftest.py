"""Fixtures several test modules share: the thesis HU40T machine, its
octagonal TANGO table and the Table 4-2 plan (built once per session)."""
import pytest

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
