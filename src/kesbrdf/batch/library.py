"""A synthetic fabric library (``kesbrdf simulate --library N -o DIR``).

N varied fabrics measured with the virtual gonioreflectometer
(:func:`kesbrdf.measure.gonio.measure`) from the physically based references, with randomised
parameters (one NumPy generator seeded by ``seed``, so a library is reproducible):

* ``sadeghi:<preset>``: the Sadeghi et al. 2013 microcylinder presets (Table II:
  linen, silk crepe, satin, satin back, shot silk, velvet), in turn;
* ``ward``: anisotropic Ward with α_x ∈ [0.06, 0.3], α_y ∈ [0.1, 0.45], ρ_s ∈ [0.03, 0.2]
  and a random body colour ρ_d ∈ [0.02, 0.5]³;
* ``ashikhmin-shirley``: n_u ∈ [10, 200], n_v ∈ [50, 800], R_s ∈ [0.03, 0.2], R_d ∈ [0.02, 0.5]³.

Every fabric gets 1 % relative noise.  Every ``images_every``-th fabric is
photographed instead (camera frames + acquisition manifest through the virtual camera,
:func:`kesbrdf.measure.acquisition.camera.simulate_images`), so the batch's ingest step sees
both kinds of input.  ``broken`` deliberately broken fabrics are appended, cycling
through :data:`BROKEN`: a measurement file with a non-numeric value, one missing the
45°–135° orientations, and a catalogue row naming a file that does not exist.
The catalogue ``catalog.csv`` records each fabric's reference and its parameters, so
the validate step compares against the truth.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from kesbrdf._atomic import write_text
from kesbrdf.batch.catalog import Fabric, write_catalog
from kesbrdf.batch.steps import make_fabric_reference

__all__ = ["simulate_library", "BROKEN", "SADEGHI_PRESETS"]

SADEGHI_PRESETS = ("linen", "silk_crepe", "satin", "satin_back", "silk_shot", "velvet")
#: The kinds of deliberately broken fabric, in the order they are added.
BROKEN = ("bad-value", "missing-orientations", "missing-file")
NOISE = 0.01


def _draw(k: int, rng: np.random.Generator) -> tuple[str, dict | None]:
    family = k % 3
    if family == 0:
        return f"sadeghi:{SADEGHI_PRESETS[(k // 3) % len(SADEGHI_PRESETS)]}", None
    if family == 1:
        return "ward", {"alpha_x": round(float(rng.uniform(0.06, 0.3)), 4),
                        "alpha_y": round(float(rng.uniform(0.1, 0.45)), 4),
                        "rho_d": [round(float(x), 4) for x in rng.uniform(0.02, 0.5, 3)],
                        "rho_s": round(float(rng.uniform(0.03, 0.2)), 4)}
    return "ashikhmin-shirley", {"n_u": round(float(rng.uniform(10, 200)), 2),
                                 "n_v": round(float(rng.uniform(50, 800)), 2),
                                 "R_s": round(float(rng.uniform(0.03, 0.2)), 4),
                                 "R_d": [round(float(x), 4) for x in rng.uniform(0.02, 0.5, 3)]}


def simulate_library(n: int, out, seed: int = 0, broken: int = 2, images_every: int = 4,
                     kind: str | None = None) -> Path:
    """Write ``n`` fabrics plus ``broken`` broken ones and ``catalog.csv`` into ``out``.

    ``kind``: the catalogue's ``kind`` column for every good fabric (None: empty, so
    the batch fits by ``kesbrdf fit``'s rule).  Returns the catalogue's path.
    """
    from kesbrdf.errors import KesbrdfError
    from kesbrdf.measure.gonio import measure
    from kesbrdf.io.measurement_csv import format_measurement, write_measurement

    if n < 0 or broken < 0:
        raise KesbrdfError(f"--library: expected a count >= 0 of fabrics and broken fabrics, got {n} and {broken}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    fabrics: list[Fabric] = []
    width = max(3, len(str(n)))
    for k in range(n):
        fid = f"fabric-{k + 1:0{width}d}"
        name, params = _draw(k, rng)
        ref = make_fabric_reference(name, params)
        sample = f"library {fid}: {name}"
        if images_every and k % images_every == images_every - 1:
            from kesbrdf.measure.acquisition.camera import simulate_images

            manifest = simulate_images(ref, out / fid, seed=seed + k, sample=sample)
            inp = manifest.relative_to(out).as_posix()
        else:
            m = measure(ref, noise=NOISE, rng=seed + k, sample=sample)
            write_measurement(out / f"{fid}.csv", m)
            inp = f"{fid}.csv"
        opts = {"reference": name}
        if kind is not None:
            opts["kind"] = kind
        if params:
            opts["reference_params"] = params
        fabrics.append(Fabric(id=fid, input=inp, options=opts, meta={"notes": f"simulated {name}"}))
    base = measure(make_fabric_reference("ward", None), noise=NOISE, rng=seed)
    for j in range(broken):
        what = BROKEN[j % len(BROKEN)]
        fid = f"broken-{j + 1}-{what}"
        if what == "bad-value":
            lines = format_measurement(base).splitlines()
            row = next(i for i, ln in enumerate(lines) if ln and not ln.startswith("#")) + 3
            cells = lines[row].split(",")
            cells[-1] = "n/a"
            lines[row] = ",".join(cells)
            write_text(out / f"{fid}.csv", "\n".join(lines) + "\n")
            inp = f"{fid}.csv"
        elif what == "missing-orientations":
            keep = np.flatnonzero(np.degrees(base.psi) < 30)
            write_measurement(out / f"{fid}.csv", base.subset(keep))
            inp = f"{fid}.csv"
        else:
            inp = f"{fid}.csv"  # never written
        fabrics.append(Fabric(id=fid, input=inp, options={"reference": "ward"},
                              meta={"notes": f"deliberately broken: {what}"}))
    write_catalog(out / "catalog.csv", fabrics)
    return out / "catalog.csv"
