"""fivecal.io: files in and out of fivecal's formats, and the world outside.

:mod:`fivecal.io.tables` reads instrument tables (CSV or whitespace text:
probing logs, ball bar traces, R-test triples, tracker / camera / CMM points,
rows in fivecal's own columns) into datasets; docs/import.md describes the
columns. :mod:`fivecal.io.alignment` finds a fixed instrument's nominal pose
by a rigid alignment of its points to the nominal machine's. :mod:`fivecal.io.linuxcnc`
exports to LinuxCNC's kinematics and compensation files and reads its probe
logs (docs/linuxcnc.md)."""
from .tables import KINDS, import_dataset, read_table, write_dataset
