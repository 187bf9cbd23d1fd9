"""kesbrdf.plotting._mpl: pyplot-free figures; a missing matplotlib names the extra."""

import sys

import pytest

from kesbrdf.plotting import _mpl


def test_new_figure_is_pyplot_free():
    fig = _mpl.new_figure((3, 2), dpi=50)
    assert tuple(fig.get_size_inches()) == (3, 2)
    # not registered with pyplot: no GUI canvas, no figure manager to leak
    assert type(fig.canvas).__name__ == "FigureCanvasBase"


def test_missing_matplotlib_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # import matplotlib -> ImportError
    with pytest.raises(ImportError, match=r"install kesbrdf\[plot\]"):
        _mpl.require_matplotlib()
