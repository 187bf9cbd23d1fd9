"""The batch summary: ``summary.csv``, ``summary.parquet`` and the ``index.html`` contact sheet.

One row per fabric (catalogue order).  Columns (docs/batch.md "Summary"):

``id, input, status`` (``ok`` / ``failed``), ``error`` (the one-line message),
``failed_step``, ``kind``, ``n_samples``,
``fit_nrmse`` (round trip to the fitted measurement; ~1e-16 for the KES table, which
interpolates its inputs exactly), ``loo_nrmse`` (worst leave-one-orientation-out
relative RMSE), ``ref_nrmse`` (held-out orientations against the fabric's reference,
when it has one), ``fit_error`` (the contact sheet's default sort key: ``loo_nrmse``
when defined, else ``fit_nrmse``), ``seconds`` (this run), ``seconds_<step>`` (this
run, skip checks included), ``compute_seconds_<step>`` (when the step was computed,
from its manifest), ``steps_done``, ``steps_skipped``, ``model``, ``report``,
``preview``, ``colourways``, ``exports`` (``;``-separated), ``export_formats``,
``export_errors``, and the catalogue's ``notes`` / ``meta_*`` columns.
Paths are relative to ``OUT``.
"""

from __future__ import annotations

import base64
import csv
import html
import io
import json

__all__ = ["summary_rows", "write_summary", "COLUMNS", "OUTPUT_FILES"]

#: Every file a run writes at the top of ``OUT`` (beside the fabric folders), by kind.
#: The catalogue refuses fabric ids equal to these names, ignoring case
#: (:func:`kesbrdf.batch.catalog.check_id`): ``OUT/<id>/`` would take their place.
OUTPUT_FILES = {"csv": "summary.csv", "parquet": "summary.parquet", "index": "index.html", "json": "summary.json"}

COLUMNS = ("id", "input", "status", "error", "failed_step", "kind", "n_samples", "fit_nrmse", "loo_nrmse",
           "ref_nrmse", "fit_error", "seconds", "steps_done", "steps_skipped", "model", "report", "preview",
           "colourways", "exports", "export_formats", "export_errors")
FLOAT_COLUMNS = ("fit_nrmse", "loo_nrmse", "ref_nrmse", "fit_error", "seconds")
#: Inline preview tiles in index.html up to this many bytes in total (else link them).
INLINE_LIMIT = 32 * 1024 * 1024


def _out(rec, step, name):
    s = rec["steps"].get(step, {})
    if s.get("status") in ("done", "skipped") and name in s.get("outputs", {}):
        return f"{rec['id']}/{step}/{name}"
    return None


def summary_rows(records, steps, meta_by_id=None) -> list[dict]:
    rows = []
    for rec in records:
        st = rec.get("steps", {})
        res = {k: (st.get(k, {}).get("result") or {}) for k in steps}
        val = res.get("validate", {})
        ex = res.get("export", {})
        row = {
            "id": rec["id"], "input": rec.get("input"), "status": rec["status"], "error": rec.get("error"),
            "failed_step": rec.get("failed_step"),
            "kind": res.get("fit", {}).get("kind"), "n_samples": res.get("ingest", {}).get("n_samples"),
            "fit_nrmse": val.get("fit_nrmse"), "loo_nrmse": val.get("loo_nrmse"), "ref_nrmse": val.get("ref_nrmse"),
            "seconds": rec.get("seconds"),
            "steps_done": ",".join(s for s in steps if st.get(s, {}).get("status") == "done"),
            "steps_skipped": ",".join(s for s in steps if st.get(s, {}).get("status") == "skipped"),
            "model": _out(rec, "fit", "model.kes.json"), "report": _out(rec, "report", "report.html"),
            "preview": _out(rec, "preview", "preview.png"), "colourways": _out(rec, "preview", "colourways.png"),
            "exports": ";".join(f"{rec['id']}/export/{p}" for p in ex.get("paths", [])) or None,
            "export_formats": ",".join(ex.get("formats", [])) or None,
            "export_errors": "; ".join(f"{k}: {v}" for k, v in (ex.get("failed") or {}).items()) or None,
        }
        row["fit_error"] = row["loo_nrmse"] if row["loo_nrmse"] is not None else row["fit_nrmse"]
        for s in steps:
            row[f"seconds_{s}"] = st.get(s, {}).get("seconds")
            row[f"compute_seconds_{s}"] = st.get(s, {}).get("computed_seconds")
        for k, v in (meta_by_id or {}).get(rec["id"], {}).items():
            row[k] = v
        rows.append(row)
    return rows


def _columns(rows, steps):
    cols = list(COLUMNS) + [f"seconds_{s}" for s in steps] + [f"compute_seconds_{s}" for s in steps]
    for r in rows:
        cols += [k for k in r if k not in cols]
    return cols


def to_csv(rows, cols) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for r in rows:
        w.writerow(["" if r.get(c) is None else (repr(r[c]) if isinstance(r[c], float) else r[c]) for c in cols])
    return buf.getvalue()


def to_parquet(rows, cols) -> bytes:
    import pyarrow as pa
    import pyarrow.parquet as pq

    arrays = {}
    for c in cols:
        vals = [r.get(c) for r in rows]
        if c in FLOAT_COLUMNS or c.startswith(("seconds_", "compute_seconds_")):
            arrays[c] = pa.array([None if v is None else float(v) for v in vals], pa.float64())
        elif c == "n_samples":
            arrays[c] = pa.array([None if v is None else int(v) for v in vals], pa.int64())
        else:
            arrays[c] = pa.array([None if v is None else str(v) for v in vals], pa.string())
    sink = pa.BufferOutputStream()
    pq.write_table(pa.table(arrays), sink)
    return sink.getvalue().to_pybytes()


_JS = """
const g=document.getElementById('grid'),k=document.getElementById('key'),o=document.getElementById('order'),
f=document.getElementById('filter');
function num(t,a){const v=t.dataset[a];return v===''?NaN:(isNaN(+v)?v:+v);}
function sortTiles(){const a=k.value,d=o.value==='desc'?-1:1,ts=[...g.children];
ts.sort((x,y)=>{const p=num(x,a),q=num(y,a);if(typeof p==='string'||typeof q==='string')return d*String(p).localeCompare(String(q));
if(isNaN(p)&&isNaN(q))return 0;if(isNaN(p))return 1;if(isNaN(q))return -1;return d*(p-q);});
ts.forEach(t=>{t.style.display=(f.value==='all'||t.dataset.status===f.value)?'':'none';g.appendChild(t);});}
k.onchange=o.onchange=f.onchange=sortTiles;sortTiles();
"""
_CSS = """
body{font:14px system-ui,sans-serif;margin:1em;background:#111;color:#ddd}a{color:#8cf}
#grid{display:flex;flex-wrap:wrap;gap:8px}.t{width:268px;background:#222;padding:6px;border-radius:4px}
.t img{width:256px;height:192px;object-fit:cover;background:#000;display:block}
.ph{width:256px;height:192px;display:flex;align-items:center;justify-content:center;background:#300;color:#f99;
font-size:12px;overflow:hidden;text-align:center}.failed{outline:2px solid #a33}.id{font-weight:bold;word-break:break-all}
.n{font-size:12px;color:#aaa}.e{font-size:11px;color:#f99;word-break:break-word}
"""


def _fmt(v):
    return "—" if v is None else f"{v:.3g}"


def contact_sheet(rows, read_bytes, title="kesbrdf batch") -> str:
    """Self-contained HTML: preview tiles (inline PNG) sortable by fit error and more."""
    total = 0
    tiles = []
    for r in rows:
        img = None
        if r.get("preview"):
            data = read_bytes(r["preview"])
            if data and total + len(data) <= INLINE_LIMIT:
                total += len(data)
                img = "data:image/png;base64," + base64.b64encode(data).decode()
            elif data:
                img = r["preview"]
        data_attrs = " ".join(
            f'data-{k.replace("_", "")}="{html.escape("" if r.get(k) is None else str(r.get(k)))}"'
            for k in ("id", "status", "fit_error", "fit_nrmse", "loo_nrmse", "ref_nrmse", "seconds")
        )
        pic = (f'<img src="{html.escape(img)}" alt="preview of {html.escape(r["id"])}" loading="lazy">' if img else
               f'<div class="ph">{html.escape(r["status"] if r["status"] == "failed" else "no preview")}</div>')
        links = []
        if r.get("report"):
            links.append(f'<a href="{html.escape(r["report"])}">report</a>')
        if r.get("colourways"):
            links.append(f'<a href="{html.escape(r["colourways"])}">colourways</a>')
        if r.get("model"):
            links.append(f'<a href="{html.escape(r["model"])}">model</a>')
        err = f'<div class="e">{html.escape(r["failed_step"] or "")}: {html.escape(r["error"])}</div>' if r.get("error") else ""
        tiles.append(
            f'<div class="t {html.escape(r["status"])}" {data_attrs}>{pic}<div class="id">{html.escape(r["id"])}</div>'
            f'<div class="n">{html.escape(r.get("kind") or "")} · fit error {_fmt(r.get("fit_error"))} · '
            f'ref {_fmt(r.get("ref_nrmse"))}</div><div class="n">{" · ".join(links)}</div>{err}</div>'
        )
    n_ok = sum(r["status"] == "ok" for r in rows)
    return (
        f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
        f"<style>{_CSS}</style></head><body><h1>{html.escape(title)}</h1>"
        f"<p>{len(rows)} fabrics, {n_ok} ok, {len(rows) - n_ok} failed. Fit error: worst leave-one-orientation-out "
        "relative RMSE (else the round trip); ref: held-out orientations against the fabric's reference. "
        f"Table: <a href='{OUTPUT_FILES['csv']}'>{OUTPUT_FILES['csv']}</a>, "
        f"<a href='{OUTPUT_FILES['parquet']}'>{OUTPUT_FILES['parquet']}</a>.</p>"
        "<p>sort by <select id='key'><option value='fiterror'>fit error</option><option value='refnrmse'>reference "
        "error</option><option value='loonrmse'>leave-one-out error</option><option value='fitnrmse'>round trip"
        "</option><option value='id'>id</option><option value='status'>status</option><option value='seconds'>time"
        "</option></select> <select id='order'><option value='desc'>worst first</option><option value='asc'>"
        "best first</option></select> show <select id='filter'><option value='all'>all</option><option value='ok'>"
        "ok</option><option value='failed'>failed</option></select></p>"
        f"<div id='grid'>{''.join(tiles)}</div><script>{_JS}</script></body></html>\n"
    )


def write_summary(store, records, steps, meta_by_id=None) -> dict:
    """Write the three summary files into the store's root; returns their locations."""
    rows = summary_rows(records, steps, meta_by_id)
    cols = _columns(rows, steps)
    name = OUTPUT_FILES
    paths = {"csv": store.write_bytes(name["csv"], to_csv(rows, cols).encode())}
    try:
        paths["parquet"] = store.write_bytes(name["parquet"], to_parquet(rows, cols))
    except ImportError:  # pragma: no cover - pyarrow is in the batch extra
        paths["parquet"] = None
    sheet = contact_sheet(rows, lambda rel: store.read_bytes(rel))
    paths["index"] = store.write_bytes(name["index"], sheet.encode())
    paths["json"] = store.write_bytes(name["json"], (json.dumps(rows, indent=1, default=str) + "\n").encode())
    return paths
