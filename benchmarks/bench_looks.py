"""Each export's look in its own renderer (issue 18): image error per format on three fabrics.

For the demo's black satin (``sadeghi-black-satin``), a twill (Irawan & Marschner
``cotton_twill``) and a felt (RGL ``rgl-felt-white``, measured): virtual paper-protocol
measurement → KES model → the four exports with a renderer here (``rgl-bsdf``: Mitsuba
``measured``; ``gltf``, ``usd``, ``mtlx``: Blender Cycles; ``gltf-threejs``: three.js in headless
Chromium; kesbrdf.export.looks) →
each rendered in the look scene (sphere + folded cloth under the studio soft boxes,
256x192, 32 spp + OIDN) and compared with the kesbrdf plugin's render of the model:
FLIP and relative RMSE over the fabric pixels, with the noise floor (two plugin seeds).
Analytic fits on the demo's grid (kesbrdf.cli.demo.DEMO_FIT_GRID).  Several minutes.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))

FABRICS = ("sadeghi-black-satin", "irawan-cotton-twill", "rgl-felt-white")
FORMATS = (("rgl-bsdf", ".bsdf"), ("gltf", ".gltf"), ("mtlx", ".mtlx"), ("usd", ".usda"))


def _reference(name: str):
    if name == "irawan-cotton-twill":
        from kesbrdf.references.irawan2012 import Irawan2012

        return Irawan2012("cotton_twill")
    from kesbrdf.references.registry import make_reference

    return make_reference(name)


def run() -> dict:
    import kesbrdf.render  # noqa: F401
    from kesbrdf.cli.demo import DEMO_FIT_GRID
    from kesbrdf.export import export
    from kesbrdf.export.looks import LookOptions, check_looks
    from kesbrdf.measure.gonio import measure
    from kesbrdf.models.kes import fit

    out: dict = {"options": LookOptions().to_json(), "fit_grid": DEMO_FIT_GRID}
    for name in FABRICS:
        try:
            ref = _reference(name)
        except Exception as exc:  # an RGL file may be missing on this machine
            out[name] = {"error": str(exc)}
            continue
        t0 = time.perf_counter()
        with tempfile.TemporaryDirectory(prefix="kesbrdf-bench-looks-") as tmp:
            d = Path(tmp)
            model = fit(measure(ref, protocol="paper"))
            model.save(d / "model.kes.json")
            files, fit_error = {}, {}
            for fmt, ext in FORMATS:
                opts = {} if fmt == "rgl-bsdf" else {"fit_grid": DEMO_FIT_GRID}
                r = export(model, fmt, d / f"fabric{ext}", **opts)
                files[fmt] = r.paths[0]
                fe = r.agreement.get("fit_error")
                if fe is not None:
                    fit_error[fmt] = fe
            t_export = time.perf_counter() - t0
            files["gltf-threejs"] = files["gltf"]  # the same file, in three.js
            looks = check_looks(d / "model.kes.json", files, d / "looks")
        rows = {}
        for row in looks["rows"]:
            rows[row["format"]] = ({"skipped": row["skipped"]} if "skipped" in row else
                                   {k: row[k] for k in ("renderer", "flip", "rel_rmse", "seconds")})
        first = next((r for r in looks["rows"] if "noise_flip" in r), None)
        out[name] = {
            "formats": rows,
            "noise_flip": first["noise_flip"] if first else None,
            "noise_rel_rmse": first["noise_rel_rmse"] if first else None,
            "fit_error": fit_error,
            "export_seconds": round(t_export, 1),
            "seconds": round(time.perf_counter() - t0, 1),
        }
    return out


if __name__ == "__main__":  # pragma: no cover
    import json

    print(json.dumps(run(), indent=1, default=str))
