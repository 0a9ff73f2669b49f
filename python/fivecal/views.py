"""What a notebook shows of a fivecal object: ``_repr_html_`` (the report's
verdict and tables in short form) and ``plot()`` (matplotlib figures made
without pyplot, so the user's backend is never switched).

The objects live in the core API and in procedures/, while how they look is
the report's business (report/notebook.py, built from the report's own
pieces). The report layer sits above both, so the objects cannot import it:
they inherit :class:`Viewable`, whose methods dispatch on the object's class
to the view report/ registers here (:func:`html`, :func:`figures`). Imports
stay one way and there is one formatter, the report's."""
from __future__ import annotations

import functools


@functools.singledispatch
def html(obj) -> str:
    """The HTML a notebook shows for ``obj`` (registered by report/notebook.py)."""
    # IPython treats NotImplementedError from _repr_html_ as "no HTML" and
    # falls back to the plain repr.
    raise NotImplementedError(f"no HTML view of {type(obj).__name__}")


@functools.singledispatch
def figures(obj) -> list:
    """The matplotlib Figures of ``obj`` (registered by report/notebook.py)."""
    raise TypeError(f"no figures of a {type(obj).__name__}: nothing registered to draw it")


class Viewable:
    """Gives a class ``_repr_html_`` (Jupyter) and ``plot()``."""

    __slots__ = ()

    def _repr_html_(self) -> str:
        return html(self)

    def plot(self) -> list:
        """matplotlib :class:`~matplotlib.figure.Figure` objects of this
        object, made with the object API (no pyplot state, the current
        backend untouched): show one in a notebook by leaving it as a
        cell's value, or save it with ``fig.savefig(path)``."""
        return figures(self)
