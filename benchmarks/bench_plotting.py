"""Plotting benchmarks: time to build and save each of the paper's figures, and the
HTML report, for the 116-sample satin model (seconds, best of a few runs)."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from _timing import best_of

os.environ.setdefault("MPLBACKEND", "Agg")




def run() -> dict:
    from kesbrdf.measure.gonio import measure
    from kesbrdf.models.kes import fit
    from kesbrdf.plotting.figures import FIGURES, make_figure
    from kesbrdf.plotting.report import ReportInputs, write_report
    from kesbrdf.plotting.save import figure_bytes
    from kesbrdf.references.ward import AnisotropicWard

    ref = AnisotropicWard(alpha_x=0.08, alpha_y=0.22, rho_d=0.02, rho_s=0.12)
    m = measure(ref)
    model = fit(m)
    out: dict = {}
    for name in FIGURES:
        def build_and_save(name=name):
            fig = make_figure(name, model=model, measurement=m, reference=ref)
            figure_bytes(fig, "png", dpi=100)

        out[f"figure_{name}_png_s"] = best_of(build_and_save)
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "report.html"
        out["report_s"] = best_of(lambda: write_report(path, ReportInputs(model, m, ref)), repeats=1)
        out["report_bytes"] = path.stat().st_size
    return out


if __name__ == "__main__":  # pragma: no cover
    import json

    print(json.dumps(run(), indent=1))
