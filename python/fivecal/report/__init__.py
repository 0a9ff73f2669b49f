"""fivecal.report: what a user reads and looks at. :mod:`.document` writes the
HTML and text report, :mod:`.plots` the figures of every observation kind,
:mod:`.polar` the ball bar polar charts."""
from .document import table_html, write_report

__all__ = ["table_html", "write_report"]
