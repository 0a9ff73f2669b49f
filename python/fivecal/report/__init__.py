"""fivecal.report: what a user reads and looks at. :mod:`.document` writes the
HTML and text report, :mod:`.plots` the figures of every observation kind,
:mod:`.polar` the ball bar polar charts, :mod:`.history` the report's
calibration-history sections, :mod:`.markup` the HTML pieces they share,
:mod:`.notebook` the notebook views (``_repr_html_``, ``plot()``)."""
from .document import write_report
from . import notebook  # noqa: F401  (registers the notebook views of fivecal.views)
from .markup import table_html

__all__ = ["table_html", "write_report"]
