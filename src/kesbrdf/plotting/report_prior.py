"""Report sections of issue 9: uncertainty map, model comparison, baselines, planning.

:func:`sections_html` returns the HTML that :func:`kesbrdf.plotting.report.build_report`
inserts after the figures:

* **Uncertainty map** (when the model carries a σ, :mod:`kesbrdf.uncertainty`): per
  Fig. 6 light, the model's log10 f_r next to σ of ln f over the viewing hemisphere;
* **Model comparison** — ``model.diagnostics["fit_report"]["comparison"]``: the held-out
  error of every candidate ``kesbrdf.fit(kind="auto")`` tried and the one it kept;
* **Default vs baselines** — :func:`kesbrdf.baselines.compare_models` with its verdicts;
* **Prior-based model** — Fig. 6 and the uncertainty map of a fibre-prior model;
* **Protocol planning** — :func:`kesbrdf.plotting.planning.figure_plan`.
"""

from __future__ import annotations

import base64
import html

import numpy as np

from kesbrdf.errors import KesbrdfError
from kesbrdf.plotting.save import figure_bytes

__all__ = ["figure_uncertainty", "sections_html", "comparison_table_html", "baselines_html"]

#: The Fig. 6 lights (θ_i, φ_i) in degrees.
LIGHTS_DEG = ((30.0, 90.0), (30.0, 45.0))


def figure_uncertainty(model, lights_deg=LIGHTS_DEG, n: int = 81, channel: int = 0):
    """Fig. 6 with σ: per light the model's log10 f_r and σ of ln f (equal-area disks).

    σ is :func:`kesbrdf.uncertainty.predict_sigma` (fit noise ⊕ candidate spread,
    docs/prior.md §5); pixels outside the disk are blank.
    """
    from kesbrdf.geometry import spherical_to_cartesian
    from kesbrdf.plotting._mpl import new_figure
    from kesbrdf.plotting.figures import hemisphere_grid
    from kesbrdf.uncertainty import predict_sigma

    grid = hemisphere_grid(n, "equal-area")
    wr = spherical_to_cartesian(grid["theta"], grid["phi"]).reshape(-1, 3)
    inside = grid["inside"].ravel()
    fig = new_figure(figsize=(7.0, 3.2 * len(lights_deg)))
    for row, (ti, pi) in enumerate(lights_deg):
        wi = np.broadcast_to(spherical_to_cartesian(np.radians(ti), np.radians(pi)), wr.shape)
        f, _, sl = predict_sigma(model, wi[inside], wr[inside])
        maps = []
        for vals in (np.log10(np.maximum(f[:, channel], 1e-12)), sl[:, channel]):
            img = np.full(inside.size, np.nan)
            img[inside] = vals
            maps.append(img.reshape(n, n))
        for col, (img, label, cmap) in enumerate(zip(maps, ("log10 f_r (1/sr)", "σ of ln f"), ("magma", "viridis"))):
            ax = fig.add_subplot(len(lights_deg), 2, 2 * row + col + 1)
            im = ax.imshow(img, origin="lower", extent=grid["extent"], cmap=cmap)
            ax.set_title(f"{'model' if col == 0 else 'uncertainty'}, light θi={ti:g}°, φi={pi:g}°", fontsize=9)
            ax.set_axis_off()
            fig.colorbar(im, ax=ax, shrink=0.8, label=label)
    return fig


def _img(fig, alt: str, caption: str, dpi: int) -> str:
    b64 = base64.b64encode(figure_bytes(fig, "png", dpi=dpi)).decode("ascii")
    return (f'<figure id="fig-{html.escape(alt)}"><img alt="{html.escape(alt)}" src="data:image/png;base64,{b64}">'
            f"<figcaption>{html.escape(caption)}</figcaption></figure>")


def _table(header, rows) -> str:
    head = "".join(f"<th>{html.escape(str(h))}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>" for r in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def _num(v) -> str:
    return f"{v:.4g}" if isinstance(v, (int, float)) else "—"


def comparison_table_html(comparison) -> str:
    """The ``kind="auto"`` comparison (``FitReport.comparison``) as a table, or ""."""
    if not comparison:
        return ""
    kept = comparison.get("kept")
    if "folds" in comparison:
        med = comparison.get("median") or {}
        what = f"{comparison['folds']}-fold held-out log RMSE (median over folds)"
        rows = [(c, _num(v), "kept" if c == kept else "") for c, v in sorted(med.items(), key=lambda kv: kv[1])]
        return f"<h3>Model comparison</h3><p>{html.escape(what)}; kept <b>{html.escape(str(kept))}</b>.</p>" + _table(
            ("candidate", "held-out error", ""), rows)
    orient = comparison.get("orientations") or {}
    cands = sorted({c for r in orient.values() for c in r})
    rows = [(f"ψ = {k}°", *(_num(r.get(c)) for c in cands)) for k, r in orient.items()]
    med = comparison.get("median_biases") or {}
    rows.append(("median over the biases", *(_num(med.get(c)) for c in cands)))
    header = ("held-out orientation", *(f"{c} (kept)" if c == kept else c for c in cands))
    return ("<h3>Model comparison</h3><p>Leave-one-orientation-out NRMSE of each candidate "
            f"<code>kesbrdf.fit(kind=\"auto\")</code> tried (each orientation predicted from the others; "
            f"KES can predict only the biases); kept <b>{html.escape(str(kept))}</b>.</p>" + _table(header, rows))


def baselines_html(baselines) -> str:
    """The default-vs-baselines table and its verdicts (:mod:`kesbrdf.baselines`), or ""."""
    if not baselines:
        return ""
    cases = baselines["cases"]
    names = list(next(iter(cases.values())))
    rows = [(case, *(_num(r[nm]["rmse"]) for nm in names)) for case, r in cases.items()]
    verdicts = "".join(f"<li>{html.escape(v)}</li>" for v in baselines.get("verdicts", ()))
    return ("<h3>Default model vs baselines</h3><p>RMSE (1/sr) against the reference on held-out "
            "orientations and the Fig. 6 hemispheres; nearest and linear interpolate the measured "
            "orientations over φ.</p>" + _table(("case", *names), rows) + f"<ul class=verdicts>{verdicts}</ul>")


def sections_html(model=None, measurement=None, reference=None, plan=None, baselines=None, prior_model=None,
                  dpi: int = 90) -> str:
    """The issue-9 sections (module docstring); each one only when its input is given."""
    from kesbrdf.uncertainty import has_uncertainty

    parts = []
    comparison = ((getattr(model, "diagnostics", None) or {}).get("fit_report") or {}).get("comparison")
    body = comparison_table_html(comparison) + baselines_html(baselines)
    if model is not None and has_uncertainty(model):
        body += _img(figure_uncertainty(model), "6-uncertainty",
                     "Fig. 6 with uncertainty: the model and σ of ln f (fit noise ⊕ spread between candidates)", dpi)
    if prior_model is not None and prior_model is not model:
        from kesbrdf.plotting.figures import make_figure

        body += "<h3>Prior-based model (fibre prior + KES residual)</h3>"
        try:
            body += _img(make_figure("6", model=prior_model, measurement=measurement, reference=reference),
                         "6-prior", "Fig. 6 of the fibre-prior model (prior × KES residual)", dpi)
        except KesbrdfError as exc:
            body += f'<p class="note">Fig. 6 of the prior model not drawn: {html.escape(str(exc))}</p>'
        body += _img(figure_uncertainty(prior_model), "6-prior-uncertainty",
                     "The fibre-prior model and its σ of ln f over the hemisphere", dpi)
    if plan:
        from kesbrdf.plotting.planning import figure_plan

        body += "<h3>Protocol planning</h3>" + _img(figure_plan(plan), "plan",
                                                    "Expected hemisphere NRMSE of candidate protocols (kesbrdf plan)", dpi)
    if body:
        parts.append("<h2 id=prior>Models, uncertainty and planning</h2>" + body)
    return "".join(parts)
