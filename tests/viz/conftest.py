"""Fixtures of the figure tests. The scenes they draw come from ``synthetic.plot_arrays``."""

import pytest


@pytest.fixture
def drawn(monkeypatch):
    """The figures the plot functions make, kept when they are saved."""
    import trajpref.viz.plot as plot

    figs = []
    original = plot._save

    def keep(fig, out, *args, **kwargs):
        figs.append(fig)
        return original(fig, out, *args, **kwargs)

    monkeypatch.setattr(plot, "_save", keep)
    return figs
