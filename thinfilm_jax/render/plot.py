"""Figures without pyplot's global state: the few pyplot calls the figures use (`subplots`,
`figure`, `close`, `get_cmap`), made on `matplotlib.figure.Figure` objects drawn by the Agg
canvas. The library never calls ``matplotlib.use``: a notebook's or a program's backend (inline,
Qt, ...) stays as its owner chose, and its own pyplot figures are untouched by ours.

matplotlib is an optional dependency (``pip install 'thinfilm_jax[plots]'``): it is imported
here, when a figure is drawn, and its absence is an `ImportError` saying which extra to install
(`require_matplotlib`); the rest of the library never needs it.

Example:
    >>> import matplotlib
    >>> before = matplotlib.get_backend()
    >>> fig, ax = subplots(figsize=(2, 1))
    >>> _ = ax.plot([0, 1], [1, 0])
    >>> type(fig.canvas).__name__, matplotlib.get_backend() == before
    ('FigureCanvasAgg', True)
"""

from __future__ import annotations

__all__ = ["figure", "subplots", "close", "get_cmap"]

INSTALL_HINT = ("matplotlib is needed to draw figures (figure7, render, fit-map's PNGs): "
                "pip install 'thinfilm_jax[plots]'")


def require_matplotlib():
    """The `matplotlib` module, imported now; an `ImportError` naming the ``[plots]`` extra
    when it is not installed."""
    try:
        import matplotlib
    except ImportError as e:
        raise ImportError(INSTALL_HINT) from e
    return matplotlib


def figure(*, figsize=None, dpi=None, layout=None, constrained_layout=None, **kw):
    """A `Figure` on its own Agg canvas (pyplot's ``figure`` without registering it)."""
    require_matplotlib()
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    if constrained_layout:
        layout = "constrained"
    fig = Figure(figsize=figsize, dpi=dpi, layout=layout, **kw)
    FigureCanvasAgg(fig)
    return fig


def subplots(nrows: int = 1, ncols: int = 1, *, figsize=None, dpi=None, layout=None,
             constrained_layout=None, sharex=False, sharey=False, squeeze=True,
             width_ratios=None, height_ratios=None, subplot_kw=None, gridspec_kw=None):
    """(fig, axes) as pyplot's ``subplots`` gives them, on a `figure` of our own."""
    fig = figure(figsize=figsize, dpi=dpi, layout=layout,
                 constrained_layout=constrained_layout)
    axes = fig.subplots(nrows, ncols, sharex=sharex, sharey=sharey, squeeze=squeeze,
                        width_ratios=width_ratios, height_ratios=height_ratios,
                        subplot_kw=subplot_kw, gridspec_kw=gridspec_kw)
    return fig, axes


def close(fig=None) -> None:
    """Nothing to do: our figures are in no pyplot registry; they go with their last
    reference."""


def get_cmap(name: str):
    """A registered colormap by name (`matplotlib.colormaps`)."""
    return require_matplotlib().colormaps[name]
