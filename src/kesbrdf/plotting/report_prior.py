"""Report sections of issue 9: uncertainty map, model comparison, baselines, planning.

:func:`sections_html` returns the HTML that :func:`kesbrdf.plotting.report.build_report`
inserts after the figures:

* **Uncertainty map** (when the model carries a σ, :mod:`kesbrdf.validate.uncertainty`): per
  Fig. 6 light, the model's log10 f_r next to σ of ln f over the viewing hemisphere;
* **Model comparison** — ``model.diagnostics["fit_report"]["comparison"]``: the held-out
  error of every candidate ``kesbrdf.fit(kind="auto")`` tried and the one it kept;
* **Default vs baselines** — :func:`kesbrdf.validate.baselines.compare_models` with its verdicts;
* **Prior-based model** — Fig. 6 and the uncertainty map of a fibre-prior model;
* **Protocol planning** — :func:`kesbrdf.plotting.planning.figure_plan`.
"""

from __future__ import annotations

import base64
import html

import numpy as np

from kesbrdf.plotting.save import figure_bytes

__all__ = ["figure_uncertainty", "sections_html", "comparison_table_html", "baselines_html"]

#: The Fig. 6 lights (θ_i, φ_i) in degrees.
LIGHTS_DEG = ((30.0, 90.0), (30.0, 45.0))


def figure_uncertainty(model, reference=None, lights_deg=LIGHTS_DEG, n: int = 81, channel: int = 0):
    """Fig. 6 with σ: per light the model's log10 f_r, [the truth, log10(model/truth)], σ of ln f.

    Works for any model that carries a σ (:mod:`kesbrdf.validate.uncertainty`; the paper's
    Fig. 6 builder draws only the KES kinds).  σ is
    :func:`kesbrdf.validate.uncertainty.predict_sigma` (prior-based kinds: fit noise ⊕ spread to
    the pure prior and the stored KES table ⊕ distance from the measured data, docs/prior.md §5;
    kes: eq. K1 of :mod:`kesbrdf.models.kes_sigma`; kes-halfdiff: the same, :mod:`kesbrdf.models.halfdiff_sigma`).
    Equal-area disks, x = warp, y = weft; pixels outside are blank.
    """
    from kesbrdf.geometry import spherical_to_cartesian
    from kesbrdf.plotting._mpl import new_figure
    from kesbrdf.plotting.figures import hemisphere_grid
    from kesbrdf.validate.uncertainty import predict_sigma

    grid = hemisphere_grid(n, "equal-area")
    wr = spherical_to_cartesian(grid["theta"], grid["phi"]).reshape(-1, 3)
    inside = grid["inside"].ravel()
    ncol = 4 if reference is not None else 2
    fig = new_figure(figsize=(3.4 * ncol, 3.0 * len(lights_deg)))
    for row, (ti, pi) in enumerate(lights_deg):
        wi = np.broadcast_to(spherical_to_cartesian(np.radians(ti), np.radians(pi)), wr.shape)
        f, _, sl = predict_sigma(model, wi[inside], wr[inside])
        lf = np.log10(np.maximum(f[:, channel], 1e-12))
        cols = [(lf, "model", "log10 f_r (1/sr)", "magma", None)]
        if reference is not None:
            t = np.asarray(reference(wi[inside], wr[inside]), float)
            t = t[:, min(channel, t.shape[-1] - 1)]
            lt = np.log10(np.maximum(t, 1e-12))
            cols.append((lt, "truth", "log10 f_r (1/sr)", "magma", None))
            cols.append((lf - lt, "log10(model / truth)", "decades", "coolwarm", (-1.0, 1.0)))
        cols.append((sl[:, channel], "uncertainty σ of ln f", "σ of ln f", "viridis", None))
        lo = min(np.nanmin(c[0]) for c in cols[: 2 if reference is not None else 1])
        hi = max(np.nanmax(c[0]) for c in cols[: 2 if reference is not None else 1])
        for col, (vals, title, label, cmap, lim) in enumerate(cols):
            img = np.full(inside.size, np.nan)
            img[inside] = vals
            if lim is None and cmap == "magma":
                lim = (max(lo, hi - 4.0), hi)
            ax = fig.add_subplot(len(lights_deg), ncol, ncol * row + col + 1)
            im = ax.imshow(img.reshape(n, n), origin="lower", extent=grid["extent"], cmap=cmap,
                           vmin=None if lim is None else lim[0], vmax=None if lim is None else lim[1])
            ax.set_title(f"{title}\nlight θi={ti:g}°, φi={pi:g}°", fontsize=8)
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
    """The default-vs-baselines table and its verdicts (:mod:`kesbrdf.validate.baselines`), or ""."""
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
    from kesbrdf.validate.uncertainty import has_uncertainty

    parts = []
    comparison = ((getattr(model, "diagnostics", None) or {}).get("fit_report") or {}).get("comparison")
    body = comparison_table_html(comparison) + baselines_html(baselines)
    caption = ("Fig. 6 with uncertainty: the model, the truth, log10(model/truth) and σ of ln f "
               "(prior-based kinds: fit noise ⊕ spread between candidates, docs/prior.md §5; kes, kes-halfdiff: noise ⊕ "
               "interpolation error over orientation ⊕ distance off the measured slice, docs/models.md)")
    if model is not None and has_uncertainty(model):
        body += "<h3>Uncertainty</h3>" + _img(figure_uncertainty(model, reference), "6-uncertainty", caption, dpi)
    elif model is not None:
        body += (f'<p class="note">The model (kind {html.escape(str(model.kind))}) carries no σ: '
                 "its file holds no noise or interpolation-error estimate (a kes or kes-halfdiff file written "
                 "before 2026-12-03, or a baseline)"
                 + ("; the fibre-prior model below shows one." if prior_model is not None else ".") + "</p>")
    if prior_model is not None and prior_model is not model:
        body += ("<h3>Prior-based model (fibre prior × KES residual)</h3>"
                 + _img(figure_uncertainty(prior_model, reference), "6-prior-uncertainty", caption, dpi))
    if plan:
        from kesbrdf.plotting.planning import figure_plan

        body += "<h3>Protocol planning</h3>" + _img(figure_plan(plan), "plan",
                                                    "Expected hemisphere NRMSE of candidate protocols (kesbrdf plan)", dpi)
    if body:
        parts.append("<h2 id=prior>Models, uncertainty and planning</h2>" + body)
    return "".join(parts)
