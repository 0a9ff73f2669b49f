"""fivecal: geometric error identification for five-axis machine tools.

Units: mm for lengths and linear commands, degrees for rotary commands, rad
for angular error parameters. See DESIGN.md for the conventions.
"""
from .machine import Machine, RadiansWarning

__version__ = "0.1.0"

__all__ = ["Machine", "RadiansWarning", "__version__"]
