"""Matplotlib figures without pyplot: every plot of the package (report/,
uncertainty histograms, history trends) draws on these. matplotlib itself is
imported when a figure is made, not with fivecal."""
from __future__ import annotations


def _pyplot():
    """The part of pyplot the plots use, on private ``Figure`` objects with
    an Agg canvas: no pyplot global state, and the caller's matplotlib
    backend (a notebook's, a GUI's) is left alone."""
    return _Figures


class _Figures:
    @staticmethod
    def figure(**kw):
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        fig = Figure(**kw)
        FigureCanvasAgg(fig)
        return fig

    @staticmethod
    def subplots(nrows: int = 1, ncols: int = 1, squeeze: bool = True, subplot_kw=None, sharex=False,
                 sharey=False, **kw):
        fig = _Figures.figure(**kw)
        return fig, fig.subplots(nrows, ncols, squeeze=squeeze, subplot_kw=subplot_kw, sharex=sharex,
                                 sharey=sharey)

    @staticmethod
    def get_cmap(name: str):
        import matplotlib

        return matplotlib.colormaps[name]

    @staticmethod
    def close(fig) -> None:
        """Nothing to release: the figure is not registered with pyplot."""
