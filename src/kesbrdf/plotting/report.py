"""One self-contained HTML report: figures, metrics, diagnostics, provenance.

The report is a single file: figures are embedded as base64 PNG (``data:`` URIs), the
style sheet is inline, and nothing refers to an external URL, so it can be mailed or
archived as it is.  Metrics and diagnostics are plain dicts of numbers, strings and
lists (what :mod:`kesbrdf.validate.compare` and :mod:`kesbrdf.validate.diagnostics` return, or JSON
read back); the report renders whatever they hold:

* a dict whose values are all dicts of scalars becomes one table (rows = outer keys,
  columns = inner keys), e.g. per-channel metrics;
* a dict of scalars becomes a two-column table; other nested dicts become sections;
* a list of dicts becomes a table; long numeric lists are summarised (n, min, max)
  with the full list in a collapsed ``<details>``;
* numbers under a key containing ``albedo`` that exceed 1 are flagged (white-furnace
  check).
"""

from __future__ import annotations

import base64
import html
import json
import math
import platform
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from kesbrdf._atomic import write_text
from kesbrdf._version import __version__
from kesbrdf.errors import KesbrdfError, ModelError
from kesbrdf.plotting.save import jsonable, describe, figure_bytes, provenance, save_figure

__all__ = ["REPORT_FIGURES", "ReportInputs", "build_report", "write_report", "collect"]

#: Figures a report shows, in order, with their captions.
REPORT_FIGURES = {
    "3a": "Fig. 3a: q = f_r·√(cos θ_i cos θ_r) against signed γ = θ_r − θ_i for each measured "
    "orientation ψ (points) and the model evaluated at the same in-plane geometry (curves).",
    "3b": "Fig. 3b: the same data in 3-D over (ψ, γ); the surface is the model.",
    "4": "Fig. 4: q over the orientation at fixed γ; KES curve (solid) against the measured "
    "samples (dashed). For γ < 0 the deviation azimuth is φ = ψ + 180°.",
    "5": "Fig. 5: the spherical model (x = warp, y = weft, z = mirror direction; radius = "
    "tabulated lobe q in 1/sr) in its three projections.",
    "6": "Fig. 6: f_r over the viewing hemisphere for the paper's lights (θ_i = 30°, "
    "φ_i = 90° and 45°), model against reference, and log10(model / reference).",
    "albedo": "Directional albedo over incident directions; crosses mark values above 1 "
    "(energy is not conserved there).",
}

#: Numeric lists longer than this are summarised, with the full list collapsed.
LIST_INLINE_MAX = 12
#: Tables with more rows than this are collapsed in a <details> element.
TABLE_ROWS_OPEN_MAX = 40

_CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;margin:2em auto;
max-width:1100px;padding:0 1em;color:#222;line-height:1.4}
h1{border-bottom:2px solid #444}h2{border-bottom:1px solid #bbb;margin-top:2em}
table{border-collapse:collapse;margin:.5em 0 1em 0;font-size:.9em}
th,td{border:1px solid #ccc;padding:.2em .6em;text-align:right;vertical-align:top}
th{background:#f0f0f0}td.key,th.key,td.txt{text-align:left}
td.flag{background:#fdd;color:#900;font-weight:bold}
figure{margin:1em 0}figure img{max-width:100%;border:1px solid #ddd}
figcaption{font-size:.9em;color:#444}
.note{color:#a60}code,pre{background:#f6f6f6;font-size:.85em}pre{padding:.5em;overflow-x:auto}
"""


# --------------------------------------------------------------------------------------
# rendering of plain data
# --------------------------------------------------------------------------------------
def _is_scalar(v) -> bool:
    return v is None or isinstance(v, (str, bool, int, float, np.generic))


def _is_number(v) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)


def _numeric_list(v) -> bool:
    return isinstance(v, (list, tuple)) and all(_is_number(x) for x in v)


def _cell_like(v) -> bool:
    """Scalars and short numeric lists fit in one table cell."""
    return _is_scalar(v) or (_numeric_list(v) and len(v) <= 4)


def _fmt(v) -> str:
    if v is None:
        return "—"
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if _is_number(v):
        x = float(v)
        if math.isnan(x):
            return "NaN"
        if math.isinf(x):
            return "∞" if x > 0 else "−∞"
        if float(x).is_integer() and abs(x) < 1e15 and isinstance(v, (int, np.integer)):
            return str(int(x))
        return f"{x:.4g}"
    if isinstance(v, (list, tuple)):
        return ", ".join(_fmt(x) for x in v)
    return html.escape(str(v))


def _flagged(path: tuple, v) -> bool:
    """White-furnace flag: a number > 1 under an ``albedo`` key (not an angle)."""
    if not any("albedo" in str(k).lower() for k in path):
        return False
    if path and any(s in str(path[-1]).lower() for s in ("theta", "phi", "deg")):
        return False
    values = v if isinstance(v, (list, tuple)) else [v]
    return any(_is_number(x) and float(x) > 1.0 for x in values)


def _td(path: tuple, v) -> str:
    cls = "flag" if _flagged(path, v) else ("" if _is_number(v) or _numeric_list(v) else "txt")
    return f'<td class="{cls}">{_fmt(v)}</td>' if cls else f"<td>{_fmt(v)}</td>"


def _wrap_rows(rows: list[str], header: str, n: int) -> str:
    table = f"<table>{header}{''.join(rows)}</table>"
    if n > TABLE_ROWS_OPEN_MAX:
        return f"<details><summary>{n} rows</summary>{table}</details>"
    return table


def _matrix_table(d: dict, path: tuple) -> str:
    cols: list = []
    for row in d.values():
        for k in row:
            if k not in cols:
                cols.append(k)
    header = "<tr><th class=key></th>" + "".join(f"<th>{html.escape(str(c))}</th>" for c in cols) + "</tr>"
    rows = [
        f"<tr><td class=key>{html.escape(str(r))}</td>"
        + "".join(_td(path + (r, c), row[c]) if c in row else "<td></td>" for c in cols)
        + "</tr>"
        for r, row in d.items()
    ]
    return _wrap_rows(rows, header, len(rows))


def _records_table(items: list, path: tuple) -> str:
    cols: list = []
    for row in items:
        for k in row:
            if k not in cols:
                cols.append(k)
    header = "<tr>" + "".join(f"<th>{html.escape(str(c))}</th>" for c in cols) + "</tr>"
    rows = [
        "<tr>" + "".join(_td(path + (c,), row[c]) if c in row else "<td></td>" for c in cols) + "</tr>"
        for row in items
    ]
    return _wrap_rows(rows, header, len(rows))


def _array_html(v, path: tuple) -> str:
    """Nested numeric lists: a table for 2-D (cells may hold channel tuples), else a summary."""
    try:
        a = np.asarray(v, float)
    except (TypeError, ValueError):
        return f"<pre>{html.escape(json.dumps(jsonable(v)))}</pre>"
    flag = ' class="flag"' if _flagged(path, a.ravel().tolist()) else ""
    finite = a[np.isfinite(a)]
    summary = (
        f"<span{flag}>array {'×'.join(map(str, a.shape))}"
        + (f", min {_fmt(finite.min())}, max {_fmt(finite.max())}" if finite.size else "")
        + "</span>"
    )
    if a.ndim in (2, 3) and a.shape[0] <= TABLE_ROWS_OPEN_MAX and a.shape[1] <= 16:
        rows = []
        for i in range(a.shape[0]):
            cells = []
            for j in range(a.shape[1]):
                cell = a[i, j].tolist()
                cells.append(_td(path, cell))
            rows.append(f"<tr><th>{i}</th>{''.join(cells)}</tr>")
        header = "<tr><th></th>" + "".join(f"<th>{j}</th>" for j in range(a.shape[1])) + "</tr>"
        return summary + f"<table>{header}{''.join(rows)}</table>"
    return summary + f"<details><summary>values</summary><pre>{html.escape(json.dumps(jsonable(v)))}</pre></details>"


def _value_html(v, path: tuple) -> str:
    if _cell_like(v):
        return _fmt(v) if not _flagged(path, v) else f'<span class="flag">{_fmt(v)}</span>'
    if _numeric_list(v):
        a = np.asarray(v, float)
        finite = a[np.isfinite(a)]
        flag = ' class="flag"' if _flagged(path, v) else ""
        if len(v) <= LIST_INLINE_MAX:
            return f"<span{flag}>{_fmt(list(v))}</span>"
        text = f"n = {len(v)}" + (f", min {_fmt(finite.min())}, max {_fmt(finite.max())}" if finite.size else "")
        return f"<details><summary{flag}>{text}</summary>{_fmt(list(v))}</details>"
    if isinstance(v, (list, tuple)) and all(_is_scalar(x) for x in v):
        return _fmt(list(v))
    return _render(v, path, 0)


def _render(v, path: tuple = (), depth: int = 0) -> str:
    """HTML for any plain data value."""
    v = jsonable(v)
    if isinstance(v, dict):
        if not v:
            return "<p>—</p>"
        if all(isinstance(x, dict) and x and all(_cell_like(y) for y in x.values()) for x in v.values()):
            return _matrix_table(v, path)
        simple = {k: x for k, x in v.items() if _cell_like(x) or _numeric_list(x)}
        out = []
        if simple:
            rows = "".join(
                f"<tr><td class=key>{html.escape(str(k))}</td>"
                f"<td{'' if _is_number(x) or _numeric_list(x) else ' class=txt'}>{_value_html(x, path + (k,))}</td></tr>"
                for k, x in simple.items()
            )
            out.append(f"<table>{rows}</table>")
        level = min(3 + depth, 6)
        for k, x in v.items():
            if k in simple:
                continue
            out.append(
                f"<section><h{level}>{html.escape(str(k))}</h{level}>{_render(x, path + (k,), depth + 1)}</section>"
            )
        return "".join(out)
    if isinstance(v, list):
        if not v:
            return "<p>—</p>"
        if all(isinstance(x, dict) and all(_cell_like(y) for y in x.values()) for x in v):
            return _records_table(v, path)
        if all(isinstance(x, list) for x in v):
            return _array_html(v, path)
        if all(_is_scalar(x) for x in v):
            return f"<p>{_value_html(v, path)}</p>"
        return "<ul>" + "".join(f"<li>{_render(x, path, depth + 1)}</li>" for x in v) + "</ul>"
    return f"<p>{_value_html(v, path)}</p>"


# --------------------------------------------------------------------------------------
# the report
# --------------------------------------------------------------------------------------
def _model_summary(model) -> dict:
    if model is None:
        return {}
    try:
        table = model.table_view()  # the (φ, γ) table, or the tabulated view of a kind without one
    except ModelError as exc:  # a kind that cannot be tabulated: say so, the rest still runs
        table, no_table = None, str(exc)
    out = {
        "kind": model.kind,
        "model": model.describe(),
        "channels": ", ".join(model.channels),
        "orientations": model.parameters.get("orientations"),
        "(φ, γ) table shape": (" × ".join(str(n) for n in np.shape(table.table))
                               + ("" if model.has_table else " (tabulated through evaluate)"))
        if table is not None else f"none: {no_table}",
    }
    if table is None:
        return {**out, "input": (model.input_info or {}).get("name"), "sample": (model.input_info or {}).get("sample")}
    if model.has_table:
        out["table (n_phi × n_gamma)"] = f"{len(table.phi_grid)} × {len(table.gamma_grid)}"
        out["γ_max (°)"] = round(math.degrees(float(np.max(table.gamma_grid))), 6)
    return {
        **out,
        "body c of the (φ, γ) table (1/sr)": np.asarray(table.body, float).tolist(),
        **({"body shape g(μ) = 1 − a(1 − μ)^p (eq. B3)": {"a": table.body_law.a, "p": table.body_law.p}}
           if getattr(table, "body_law", None) is not None else {}),
        "input": (model.input_info or {}).get("name"),
        "sample": (model.input_info or {}).get("sample"),
    }


def _measurement_summary(measurement) -> dict:
    if measurement is None:
        return {}
    orient = np.degrees(measurement.orientations()).round(6).tolist()
    return {
        "source": None if measurement.source is None else str(measurement.source),
        "samples": len(measurement),
        "in-plane samples": int(np.count_nonzero(measurement.is_in_plane)),
        "orientations ψ (°)": orient,
        "channels": ", ".join(measurement.channels),
        "sample": measurement.metadata.get("sample"),
        "instrument": measurement.metadata.get("instrument"),
        "simulated": measurement.metadata.get("simulated"),
        "notes": "; ".join(map(str, measurement.notes)) or None,
    }


def _get(d, *keys):
    """``d[k0][k1]...`` or None when any level is missing."""
    for k in keys:
        if not isinstance(d, dict) or k not in d:
            return None
        d = d[k]
    return d


def _loo_label(held: str, res: dict) -> str:
    """What a leave-one-orientation-out number scores: the orientation and, when the entry
    says so, the incidence-line rows it was taken on and the rows it left out."""
    label = f"KES interpolation (eq. 1–2), ψ = {held}° left out"
    if "rows" in res and "line_deg" in res:
        label += f", its {res['rows']} rows on θ_i + θ_r = {res['line_deg']:g}°"
        off = int(res.get("rows_off_line") or 0)
        if off:
            label += f" ({off} other row(s) at ψ = {held}° not scored)"
    return label + ": nrmse"


def _highlights(metrics, diagnostics) -> dict:
    """Key numbers found in the usual places of the validation/diagnostics dicts."""
    out: dict = {}
    rt = _get(metrics, "round_trip", "metrics", "all", "rmse")
    if rt is not None:
        out["round trip RMSE, all channels (1/sr)"] = rt
    loo = _get(metrics, "leave_one_orientation_out")
    if isinstance(loo, dict):
        for held, res in loo.items():
            value = _get(res, "metrics", "all", "nrmse")
            if value is not None:
                out[_loo_label(held, res)] = value
    ratios = _get(metrics, "reference", "ratio_kes_to")
    if isinstance(ratios, dict):
        for base, cases in ratios.items():
            if isinstance(cases, dict):
                for case, value in cases.items():
                    out[f"RMSE ratio KES / {base}: {case}"] = value
    for label, keys in (
        ("reciprocity error (max relative)", ("reciprocity_error",)),
        ("directional albedo, max per channel", ("albedo", "max")),
        ("KES log fallback at γ (°)", ("kes", "fallback_gamma_deg")),
        ("floored half-samples", ("kes", "floored")),
    ):
        value = _get(diagnostics, *keys)
        if value is not None:
            out[label] = value
    above = _get(diagnostics, "albedo", "above_one")
    if isinstance(above, list):
        out["incident directions with albedo > 1"] = len(above)
    return out


def _figure_html(name: str, data: bytes) -> str:
    b64 = base64.b64encode(data).decode("ascii")
    caption = html.escape(REPORT_FIGURES.get(name, name))
    return (
        f'<figure id="fig-{html.escape(name)}"><img alt="figure {html.escape(name)}" '
        f'src="data:image/png;base64,{b64}"><figcaption>{caption}</figcaption></figure>'
    )


def _comparisons_html(comparisons) -> str:
    """Section embedding reference-vs-model render panels (:mod:`kesbrdf.render.compare`).

    ``comparisons``: sequence of dicts with ``panel`` (a PNG path) and the numbers
    ``reference``, ``protocol``, ``flip``, ``rel_rmse`` (``noise_flip``/``noise_rel_rmse``
    optional); entries whose panel file is missing are skipped.
    """
    items = []
    for c in comparisons or ():
        panel = Path(str(c.get("panel", "")))
        if not panel.is_file():
            continue
        b64 = base64.b64encode(panel.read_bytes()).decode("ascii")
        cap = (f"{c.get('reference')} ({c.get('protocol')} protocol, {c.get('scene', 'sphere')}): "
               f"FLIP {float(c['flip']):.3f}, relative RMSE {float(c['rel_rmse']):.3f}")
        if "noise_flip" in c:
            cap += f"; noise floor FLIP {float(c['noise_flip']):.3f}, relative RMSE {float(c['noise_rel_rmse']):.3f}"
        items.append(
            f'<figure class="compare"><img alt="reference vs model {html.escape(str(c.get("reference")))}" '
            f'src="data:image/png;base64,{b64}"><figcaption>{html.escape(cap)}</figcaption></figure>'
        )
    if not items:
        return ""
    intro = ("<p>The same scene rendered with the reference BRDF itself (left) and with the KES model "
             "fitted from its virtual measurements (middle); right, the FLIP error map (0 black, 1 "
             "yellow). FLIP and relative RMSE are over the cloth pixels; the noise floor is the same "
             "comparison between two seeds of the reference.</p>")
    return "<h2 id=renders>Reference vs model renders</h2>" + intro + "".join(items)


def _looks_html(looks) -> str:
    """Section "Exports in their renderers" (:mod:`kesbrdf.export.looks`).

    ``looks``: :func:`kesbrdf.export.looks.check_looks` output; each row's
    ``images.side_by_side`` PNG (plugin | export | FLIP) is embedded with its line;
    skipped formats get their reason, rows whose image file is missing are left out.
    """
    rows = (looks or {}).get("rows") or []
    items, lines = [], []
    for r in rows:
        if "skipped" in r:
            lines.append(f"<li>{html.escape(r['format'])}: not rendered ({html.escape(str(r['skipped']))})</li>")
            continue
        line = (f"{r['format']} in {r['renderer']}: FLIP {float(r['flip']):.3f}, relative RMSE "
                f"{float(r['rel_rmse']):.3f} against the measured model (noise floor FLIP "
                f"{float(r['noise_flip']):.3f}, relative RMSE {float(r['noise_rel_rmse']):.3f})")
        lines.append(f"<li>{html.escape(line)}</li>")
        side = Path(str(r.get("images", {}).get("side_by_side", "")))
        if side.is_file():
            b64 = base64.b64encode(side.read_bytes()).decode("ascii")
            items.append(f'<figure class="compare"><img alt="{html.escape(r["format"])} in its renderer" '
                         f'src="data:image/png;base64,{b64}"><figcaption>{html.escape(line)}</figcaption></figure>')
    if not lines:
        return ""
    intro = ("<p>Each export rendered by the tool that reads it (right) next to the kesbrdf Mitsuba plugin's "
             "render of the model (left), same scene, camera and studio lights; FLIP error map on the right. "
             "FLIP (displayed images) and relative RMSE (linear) are over the fabric pixels; the noise floor "
             "is the same comparison between two seeds of the plugin.</p>")
    return "<h2 id=exports>Exports in their renderers</h2>" + intro + "<ul>" + "".join(lines) + "</ul>" + "".join(items)


@dataclass
class ReportInputs:
    """Everything one report shows (:func:`build_report`, :func:`write_report`).

    Attributes
    ----------
    model : ReflectanceModel, optional
        The model the report is about; named at the top with ``model_sha256`` and
        ``selection``.
    measurement : Measurement, optional
    reference : callable f(wi, wr) -> (..., C), optional
        Dense reference for Fig. 6.
    metrics : dict, optional
        Any nested dict of numbers/strings/lists, e.g. ``{"round_trip": validate(...),
        "leave_one_orientation_out": ..., "reference": compare_reference(...)}``.
    diagnostics : dict, optional
        e.g. :func:`kesbrdf.validate.diagnostics.diagnose` output; its albedo grid gives a figure.
    title : str
    figures : sequence of str
        Figure names (:data:`REPORT_FIGURES`); a figure whose inputs are missing is
        replaced by a one-line note.
    figure_dir : str or PathLike, optional
        Also save each figure there as ``fig<name>.<figure_format>`` (with provenance).
    figure_format : str
    dpi : int
        Resolution of the embedded PNGs.
    figure_options : dict, optional
        Figure name -> keyword arguments for its ``figure_*`` builder.
    comparisons : sequence of dict, optional
        Reference-vs-model render panels to embed (``panel`` path + numbers, as returned
        by :func:`kesbrdf.render.compare.compare_render`); missing panels are skipped.
    plan : dict, optional
        :meth:`kesbrdf.measure.planning.PlanResult.to_dict`: drawn as the protocol-planning plot.
    baselines : dict, optional
        :func:`kesbrdf.validate.baselines.compare_models` (+ ``verdicts``): the default-vs-baselines table.
    prior_model : FibrePriorModel, optional
        A fibre-prior model shown beside ``model``: its Fig. 6 and uncertainty map.
        The model comparison table (``model.diagnostics["fit_report"]["comparison"]``)
        and, for a model carrying σ, its uncertainty map are added automatically
        (:mod:`kesbrdf.plotting.report_prior`).
    looks : dict, optional
        :func:`kesbrdf.export.looks.check_looks` output: the section "Exports in their
        renderers" (each export in its renderer beside the plugin render, with FLIP).
    model_sha256 : str, optional
        The model's content hash (:func:`kesbrdf.pipeline.model_sha256`), shown at the top.
    selection : dict, optional
        The fit's selection report (:meth:`kesbrdf.fitting.FitReport.to_dict`): why this
        model; default ``model.diagnostics["fit_report"]`` when the model carries one.
    notes : sequence of str
        One-line notes shown under the model (e.g. a view that could not be drawn).
    """

    model: object = None
    measurement: object = None
    reference: object = None
    metrics: dict | None = None
    diagnostics: dict | None = None
    title: str = "kesbrdf report"
    figures: tuple = tuple(REPORT_FIGURES)
    figure_dir: object = None
    figure_format: str = "png"
    dpi: int = 90
    figure_options: dict | None = None
    comparisons: list | None = None
    plan: dict | None = None
    baselines: dict | None = None
    prior_model: object = None
    looks: dict | None = None
    model_sha256: str | None = None
    selection: dict | None = None
    notes: list = field(default_factory=list)


def _selection_of(inputs: ReportInputs) -> dict | None:
    if inputs.selection is not None:
        return inputs.selection
    d = getattr(inputs.model, "diagnostics", None)
    sel = d.get("fit_report") if isinstance(d, dict) else None
    return sel if isinstance(sel, dict) else None


def _model_header_html(inputs: ReportInputs) -> str:
    """The first lines of the report: which model (kind, content hash) and why it was chosen."""
    model = inputs.model
    if model is None:
        return ""
    digest = inputs.model_sha256
    if digest is None:
        from kesbrdf.pipeline import model_sha256

        digest = model_sha256(model)
    sel = _selection_of(inputs) or {}
    rows = [("model kind", model.kind), ("content sha256", digest or "—")]
    if sel.get("reason"):
        rows.append(("why this model", sel["reason"]))
    if sel.get("rows_total"):
        rows.append(("rows used", f"{sel.get('rows_used')} of {sel.get('rows_total')}"))
    comparison = sel.get("comparison") or {}
    if comparison.get("kept"):
        rows.append(("kept by comparison", comparison["kept"]))
    body = "".join(f"<tr><td class=key>{html.escape(k)}</td><td class=txt>{html.escape(str(v))}</td></tr>"
                   for k, v in rows)
    notes = "".join(f'<p class="note">{html.escape(str(n))}</p>' for n in inputs.notes)
    return (f"<section id=model-chosen><p><b>This report is about one model</b>: every figure, metric, "
            f"render and export below uses it.</p><table>{body}</table>{notes}</section>")


def build_report(inputs: ReportInputs | None = None) -> str:
    """The report as one HTML string (:class:`ReportInputs` says what it shows)."""
    inputs = inputs or ReportInputs()
    model, measurement, reference = inputs.model, inputs.measurement, inputs.reference
    metrics, diagnostics, title, figures = inputs.metrics, inputs.diagnostics, inputs.title, inputs.figures
    figure_dir, figure_format, dpi = inputs.figure_dir, inputs.figure_format, inputs.dpi
    figure_options, comparisons, plan, baselines = inputs.figure_options, inputs.comparisons, inputs.plan, inputs.baselines
    prior_model, looks = inputs.prior_model, inputs.looks
    from kesbrdf.plotting.figures import make_figure

    record = provenance(model, measurement, reference, report=True, figures=list(figures))
    record["environment"] = {
        "python": platform.python_version(),
        "numpy": np.__version__,
        "matplotlib": _matplotlib_version(),
    }
    parts = [
        "<!DOCTYPE html><html lang=en><head><meta charset=utf-8>",
        f"<title>{html.escape(title)}</title><style>{_CSS}</style></head><body>",
        f"<h1>{html.escape(title)}</h1>",
        f"<p>kesbrdf {html.escape(__version__)} · extended-KES anisotropic BRDF (Takeda et al.)</p>",
        _model_header_html(inputs),
    ]
    # -- key numbers
    highlights = _highlights(metrics, diagnostics)
    if highlights:
        parts.append("<h2 id=summary>Summary</h2>" + _render(highlights, ("summary",), 1))
    # -- inputs
    parts.append("<h2 id=inputs>Inputs</h2>")
    if model is not None:
        parts.append("<h3>Model</h3>" + _render(_model_summary(model), ("model",), 1))
    if measurement is not None:
        parts.append("<h3>Measurement</h3>" + _render(_measurement_summary(measurement), ("measurement",), 1))
    if reference is not None:
        parts.append(f"<h3>Reference</h3><p><code>{html.escape(describe(reference))}</code></p>")

    # -- figures
    parts.append("<h2 id=figures>Figures</h2>")
    options = figure_options or {}
    for name in figures:
        kwargs = dict(options.get(name, {}))
        if name == "albedo":
            if diagnostics is None:
                continue
            kwargs.setdefault("diagnostics", diagnostics)
        try:
            fig = make_figure(name, model=model, measurement=measurement, reference=reference, **kwargs)
        except KesbrdfError as exc:
            parts.append(f'<p class="note">Figure {html.escape(name)} not drawn: {html.escape(str(exc))}</p>')
            continue
        parts.append(_figure_html(name, figure_bytes(fig, "png", dpi=dpi)))
        if figure_dir is not None:
            save_figure(fig, Path(figure_dir) / f"fig{name}.{figure_format}")

    from kesbrdf.plotting.report_prior import sections_html

    parts.append(sections_html(model, measurement, reference, plan, baselines, prior_model, dpi))
    parts.append(_comparisons_html(comparisons))
    parts.append(_looks_html(looks))

    # -- metrics and diagnostics
    if metrics is not None:
        shown = metrics
        if isinstance(metrics, dict) and diagnostics is not None:
            shown = {k: v for k, v in metrics.items() if v is not diagnostics}
        parts.append("<h2 id=metrics>Metrics</h2>")
        parts.append(
            "<p>Per channel: rmse and max_abs in 1/sr; nrmse = rmse / mean|truth|; "
            "log_rmse = RMS of ln((pred + ε)/(truth + ε)).</p>"
        )
        parts.append(_render(shown, ("metrics",), 0))
    if diagnostics is not None:
        parts.append("<h2 id=diagnostics>Diagnostics</h2>")
        parts.append(
            "<p>Reciprocity error (max relative |f(i,r) − f(r,i)|), directional albedo "
            "(flagged in red where above 1), behaviour at γ → 0, KES fallbacks, floored "
            "samples and the 135° residual of the 3-orientation form.</p>"
        )
        parts.append(_render(diagnostics, ("diagnostics",), 0))

    # -- provenance
    parts.append("<h2 id=provenance>Provenance</h2>")
    parts.append(
        _render(
            {
                "kesbrdf_version": record["kesbrdf_version"],
                "input_sha256": record["input_sha256"],
                **record["environment"],
            },
            ("provenance",),
            1,
        )
    )
    parts.append(f"<pre>{html.escape(json.dumps(record, indent=1, sort_keys=True))}</pre>")
    parts.append("</body></html>\n")
    return "".join(parts)


def write_report(path, inputs: ReportInputs | None = None) -> Path:
    """Write one self-contained HTML report (:class:`ReportInputs`) to ``path`` atomically."""
    return write_text(path, build_report(inputs))


def _matplotlib_version() -> str | None:
    try:
        import matplotlib
    except ImportError:  # pragma: no cover
        return None
    return matplotlib.__version__


def collect(model, measurement=None, reference=None, mapping: str | None = None) -> tuple[dict, dict]:
    """Compute the report's metrics and diagnostics with :mod:`kesbrdf.validate.compare` and
    :mod:`kesbrdf.validate.diagnostics`.

    Returns
    -------
    (metrics, diagnostics) : tuple of dict
        ``metrics`` holds ``round_trip`` (model against every sample of the
        measurement), ``leave_one_orientation_out`` and ``reference`` (KES and the
        baselines against the reference), each present when its inputs are; a step
        that fails on these inputs records its one-line error instead.
    """
    from kesbrdf.validate import diagnostics as diag
    from kesbrdf.validate import compare as validation

    fit_kwargs = {"fallback": model.parameters.get("fallback", "log")} if model is not None else {}
    if model is not None:
        mapping = model.check_mapping(mapping)
    kes_mapping = mapping if mapping in ("deviation", "halfvector", "paper") else None  # None: each fit's own
    metrics: dict = {}

    def attempt(key, fn, *args, **kwargs):
        try:
            metrics[key] = fn(*args, **kwargs)
        except KesbrdfError as exc:
            metrics[key] = {"error": str(exc)}

    if measurement is not None:
        attempt("round_trip", validation.validate, model, measurement, mapping=mapping)
        # these two fit kes models (and baselines) from the measurement
        attempt("leave_one_orientation_out", validation.leave_one_orientation_out, measurement,
                mapping=kes_mapping, **fit_kwargs)
        if reference is not None:
            attempt("reference", validation.compare_reference, measurement, reference,
                    mapping=kes_mapping, **fit_kwargs)
    diagnostics = diag.diagnose(model, mapping=mapping)
    return metrics, diagnostics
