"""The paper's figures and the HTML report (optional extra ``plot``: matplotlib).

* :mod:`kesbrdf.plotting.figures`: ``plot_<what>(ax, ...)`` draw computed arrays;
  ``figure_3a``, ``figure_3b``, ``figure_4``, ``figure_5``, ``figure_6`` and
  ``figure_albedo`` build the paper's Fig. 3–6 (and an albedo map) from a model, a
  measurement and a reference.
* :mod:`kesbrdf.plotting.save`: ``save_figure`` writes PNG/SVG/PDF atomically with the
  package version, the input SHA-256 and the parameters in the file's metadata.
* :mod:`kesbrdf.plotting.report`: ``write_report`` writes one self-contained HTML file.

matplotlib is imported only when a figure is drawn; without it a clear ImportError
names the extra to install (``kesbrdf[plot]``).
"""
