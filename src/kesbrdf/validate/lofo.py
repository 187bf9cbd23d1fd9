"""Leave-one-family-out evaluation of fitters on the reference families (issue 20).

A *family* is one physical model of reflectance the project implements in
:mod:`kesbrdf.references` (Irawan–Marschner woven cloth, Sadeghi microcylinders, the
anisotropic Ward and Ashikhmin–Shirley microfacet controls, the RGL measured felt).
Each family is sampled with several parameter draws (:func:`family_library`, seeded).
For every fabric and protocol (the paper's 116 samples, ``gonio.measure(protocol="paper")``,
and the dense in-plane grid of 900, ``protocol="dense"``) each *fitter* (a callable
``measurement -> model``) is fitted to the simulated measurement (2 % multiplicative
noise, seeded) and scored against the noise-free reference with the project's
existing scoring (:func:`kesbrdf.validate.compare.metrics`, ``all`` channels):

* ``orientations``: NRMSE at the held-out orientations
  :data:`kesbrdf.validate.compare.HELD_OUT_DEG`, on the paper's incidence line;
* ``hemispheres``: mean NRMSE over the two Fig. 6 hemispheres
  (:data:`kesbrdf.validate.compare.HEMISPHERE_LIGHTS_DEG`, viewer on the 2.5° grid of
  :func:`kesbrdf.validate.compare.hemisphere_directions`);

and the fit time (CPU seconds of this process).

Anything tuned (a rule's threshold, a hyper-parameter of a kind) is chosen leave one
family out (:func:`choose_lofo`): for the held-out family F, the value is the grid
point with the lowest summed score on every *other* family, and it is then applied to
F.  Nothing here knows any fitter: the benchmark (benchmarks/bench_lofo.py) passes
them in, so this module sits in the validation layer below ``kesbrdf.fit``.

The fabrics may also come from the built synthetic fabric library of 2,000+ fabrics
over five families (:mod:`kesbrdf.validate.library`, ``kesbrdf simulate
--fabric-library``): :func:`family_library_from` draws a stratified subsample of it in
the structure :func:`family_library` returns, and :func:`library_inputs` hands
:func:`run_lofo` the library's stored measurements and truths, so nothing is simulated
again.  A fit costs 10-30 s, so a sweep uses a few fabrics per family, not all 2,000.

Microflake / SGGX volumetric cloth (SpongeCake and relatives) is never a family here:
it is kept for an independent held-out check.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from kesbrdf.measure.gonio import measure
from kesbrdf.validate.compare import metrics
from kesbrdf.validate.library import NOISE as LIBRARY_NOISE, truth_sets
from kesbrdf.validate.library import geometry as library_geometry

__all__ = ["FAMILIES", "NOISE", "PROTOCOLS", "family_library", "family_library_from", "library_inputs", "score", "scoring_truths",
           "fit_and_score", "run_lofo", "choose_lofo", "family_table", "FORBIDDEN_FAMILIES"]

#: Multiplicative noise of the simulated measurements (σ = 2 % of the value), as in
#: benchmarks/bench_selection.py; one value with the fabric library's.
NOISE = LIBRARY_NOISE
#: Protocols compared on the same fabric.
PROTOCOLS = ("paper", "dense")
#: Families of :func:`family_library`, in report order.
FAMILIES = ("irawan2012", "sadeghi2013", "ward", "ashikhmin_shirley", "rgl")
#: Never a training or tuning family (kept for an independent held-out check).
FORBIDDEN_FAMILIES = ("microflake", "sggx", "spongecake")


def _irawan_draws(rng, n):
    from kesbrdf.references.irawan2012 import PRESETS, Irawan2012

    # the presets first (the satin-like charmeuse, a twill, a plain weave), then draws
    # around them: tilt range u_max and specular weight of each family scaled
    names = ("silk_charmeuse", "cotton_twill", "polyester_lining", "cotton_denim", "wool_gabardine", "silk_shantung")
    out = {}
    for k in range(n):
        base = PRESETS[names[k % len(names)]]
        if k < len(names) and k < max(n - 1, 1):
            out[base.name] = Irawan2012(base)
            continue
        s_u, s_k = rng.uniform(0.7, 1.3, 2), rng.uniform(0.5, 1.5, 2)
        yarns = [replace(y, umax_deg=float(min(y.umax_deg * su, 80.0)), ks=tuple(float(min(v * sk, 0.5)) for v in y.ks))
                 for y, su, sk in zip((base.warp, base.weft), s_u, s_k)]
        w = replace(base, name=f"{base.name}_draw{k}", warp=yarns[0], weft=yarns[1])
        out[w.name] = Irawan2012(w)
    return out


def _sadeghi_draws(rng, n):
    from kesbrdf.references.sadeghi2013 import PRESETS, Fabric, Sadeghi2013

    names = ("satin", "linen", "velvet", "silk_crepe", "silk_shot", "satin_back")
    out = {}
    for k in range(n):
        base = PRESETS[names[k % len(names)]]
        if k < len(names) and k < max(n - 1, 1):
            out[base.name] = Sadeghi2013(base)
            continue
        s = rng.uniform(0.6, 1.5, 2)
        fams = [replace(f, gamma_s=f.gamma_s * sj, gamma_v=f.gamma_v * sj) for f, sj in zip(base.families, s)]
        fab = Fabric(f"{base.name}_draw{k}", warp=fams[0], weft=fams[1])
        out[fab.name] = Sadeghi2013(fab)
    return out


def family_library(draws: int = 3, seed: int = 20, families=FAMILIES) -> dict:
    """{family: {fabric name: reference BRDF}} with ``draws`` fabrics per family.

    The woven families take their presets first (a satin first), then seeded draws
    around them; Ward and Ashikhmin–Shirley draw roughness, anisotropy and colour;
    the RGL family is the white felt shipped with the tests (one measured fabric; left
    out when Mitsuba cannot read it).  The same ``seed`` gives the same library.
    """
    bad = [f for f in families if any(x in f.lower() for x in FORBIDDEN_FAMILIES)]
    if bad:
        raise ValueError(f"families: microflake/SGGX cloth is kept for an independent check, got {bad}")
    rng = np.random.default_rng(seed)
    lib = {}
    for fam in families:
        sub = np.random.default_rng([seed, FAMILIES.index(fam) if fam in FAMILIES else 99])
        if fam == "irawan2012":
            lib[fam] = _irawan_draws(sub, draws)
        elif fam == "sadeghi2013":
            lib[fam] = _sadeghi_draws(sub, draws)
        elif fam == "ward":
            from kesbrdf.references.ward import AnisotropicWard

            lib[fam] = {}
            for k in range(draws):
                ax, ay = np.exp(sub.uniform(np.log(0.06), np.log(0.4), 2))
                rd = sub.uniform(0.02, 0.4, 3)
                rs = float(sub.uniform(0.04, 0.2))
                lib[fam][f"ward_{ax:.2f}_{ay:.2f}"] = AnisotropicWard(float(ax), float(ay), rd.tolist(), rs)
        elif fam == "ashikhmin_shirley":
            from kesbrdf.references.ashikhmin_shirley import AshikhminShirley

            lib[fam] = {}
            for k in range(draws):
                nu, nv = np.exp(sub.uniform(np.log(8), np.log(400), 2))
                rd = sub.uniform(0.05, 0.5, 3)
                lib[fam][f"as_{nu:.0f}_{nv:.0f}"] = AshikhminShirley(float(nu), float(nv), R_s=float(sub.uniform(0.03, 0.12)),
                                                                     R_d=rd.tolist())
        elif fam == "rgl":
            try:
                from pathlib import Path

                from kesbrdf.references.registry import RGL_DIRS, RGL_FILES
                from kesbrdf.references.rgl import RGLMeasured

                paths = [d / RGL_FILES["rgl-felt-white"] for d in RGL_DIRS]
                path = next(p for p in paths if Path(p).is_file())
                lib[fam] = {"felt_white": RGLMeasured(path)}
            except Exception:  # noqa: BLE001  (Mitsuba or the file missing: the family is empty, and says so)
                lib[fam] = {}
        else:
            raise ValueError(f"families: expected names from {FAMILIES}, got {fam!r}")
    del rng
    return lib


def family_library_from(library, per_family: int = 1, seed: int = 0, families=None) -> dict:
    """{family: {fabric name: reference BRDF}} of ``per_family`` fabrics per family drawn
    (seeded, without replacement) from a built fabric library (a folder or a
    :class:`kesbrdf.validate.library.FabricLibrary`); the structure of :func:`family_library`."""
    from kesbrdf.validate.library import FabricLibrary, load_library, stratified

    lib = library if isinstance(library, FabricLibrary) else load_library(library)
    if families is not None:
        bad = [f for f in families if any(x in f.lower() for x in FORBIDDEN_FAMILIES)]
        if bad:
            raise ValueError(f"families: microflake/SGGX cloth is kept for an independent check, got {bad}")
    pick = stratified(lib, per_family, seed, families)
    return {fam: {lib.specs[k]["name"]: lib.reference(k) for k in idx} for fam, idx in pick.items()}


def library_inputs(library, refs: dict, protocols=PROTOCOLS) -> dict:
    """{family: {fabric: {"tests": truths, protocol: Measurement}}} of the fabrics of ``refs``
    (from :func:`family_library_from`), read from the library: :func:`run_lofo`'s ``data``."""
    from kesbrdf.validate.library import FabricLibrary, load_library

    lib = library if isinstance(library, FabricLibrary) else load_library(library)
    index = {s["name"]: s["index"] for s in lib.specs}
    out = {}
    for fam, fabs in refs.items():
        out[fam] = {}
        for name in fabs:
            k = index[name]
            out[fam][name] = {"tests": lib.truths(k), **{p: lib.measurement(k, p) for p in protocols}}
    return out


def scoring_truths(ref) -> dict:
    """The noise-free truths a fabric is scored on (the ``tests`` of :func:`score` and
    :func:`fit_and_score`): the held-out orientations and both Fig. 6 hemispheres, at the
    directions the fabric library stores its truths at (:func:`kesbrdf.validate.library.geometry`).
    Built once per fabric when several fits or protocols are scored against it."""
    g = library_geometry()
    return truth_sets({tag: (g[f"{tag}_wi"], g[f"{tag}_wr"], np.asarray(ref(g[f"{tag}_wi"], g[f"{tag}_wr"]), float))
                       for tag in ("held", "hemi90", "hemi45")})


def score(predict, ref, tests=None) -> dict:
    """``{"orientations", "hemispheres", "hemi90", "hemi45"}`` NRMSE of ``predict(wi, wr)`` against ``ref``."""
    tests = tests or scoring_truths(ref)
    wi, wr, truth = tests["held"]
    out = {"orientations": metrics(predict(wi, wr), truth)["all"]["nrmse"]}
    for (wi, wr, truth), tag in zip(tests["hemis"], ("hemi90", "hemi45")):
        out[tag] = metrics(predict(wi, wr), truth)["all"]["nrmse"]
    out["hemispheres"] = float(np.mean([out["hemi90"], out["hemi45"]]))
    return out


def fit_and_score(ref, fitters: dict, protocol: str = "paper", seed: int = 0, tests=None, measurement=None) -> dict:
    """{fitter: score + ``fit_cpu_s`` + ``kind``} of every fitter on one fabric and protocol.

    ``measurement`` (optional): the simulated measurement to fit (e.g. the fabric
    library's); by default ``measure(ref, protocol, noise=NOISE, rng=seed)``.
    A fitter that raises is recorded as ``{"error": one line}`` (it is a result, not a crash).
    """
    m = measurement if measurement is not None else measure(ref, protocol=protocol, noise=NOISE, rng=seed)
    tests = tests or scoring_truths(ref)
    out = {}
    for name, fitter in fitters.items():
        c0 = time.process_time()
        try:
            model = fitter(m)
        except Exception as exc:  # noqa: BLE001
            out[name] = {"error": f"{type(exc).__name__}: {' '.join(str(exc).split())[:200]}"}
            continue
        cpu = time.process_time() - c0
        predict = model.evaluate if hasattr(model, "evaluate") else model
        row = score(predict, ref, tests)
        row["fit_cpu_s"] = cpu
        row["kind"] = getattr(model, "kind", None)
        chosen = (getattr(model, "diagnostics", None) or {}).get("fit_report", {}) if hasattr(model, "diagnostics") else {}
        if isinstance(chosen, dict) and chosen.get("fitter"):
            row["fitter"] = chosen["fitter"]
            comp = chosen.get("comparison") or {}
            if comp.get("median_all"):
                row["evidence"] = {k: float(v) for k, v in comp["median_all"].items()}
        out[name] = row
    return out


def run_lofo(library: dict, fitters: dict, protocols=PROTOCOLS, progress=None, cache=None, data=None) -> dict:
    """Every fitter on every fabric and protocol: ``{family: {fabric: {protocol: {fitter: row}}}}``.

    ``data`` (optional, :func:`library_inputs`): per fabric, the stored truths and
    measurements to use instead of simulating them.

    ``cache`` (a dict, e.g. loaded from JSON) is filled and reused by
    ``family/fabric/protocol/fitter`` key, so an interrupted sweep resumes.  The rows
    themselves are not tuned: :func:`choose_lofo` applies a tuned rule leave one family out.
    """
    cache = {} if cache is None else cache
    out = {}
    for k, (fam, refs) in enumerate(library.items()):
        out[fam] = {}
        for j, (name, ref) in enumerate(refs.items()):
            out[fam][name] = {}
            given = (data or {}).get(fam, {}).get(name, {})
            tests = given.get("tests")
            for p, protocol in enumerate(protocols):
                todo = {n: f for n, f in fitters.items() if f"{fam}/{name}/{protocol}/{n}" not in cache}
                if todo:
                    tests = tests or scoring_truths(ref)
                    rows = fit_and_score(ref, todo, protocol, seed=1000 * k + 10 * j + p, tests=tests,
                                         measurement=given.get(protocol))
                    for n, row in rows.items():
                        cache[f"{fam}/{name}/{protocol}/{n}"] = row
                    if progress:
                        progress(fam, name, protocol, rows)
                out[fam][name][protocol] = {n: cache[f"{fam}/{name}/{protocol}/{n}"] for n in fitters}
    return out


def _value(row, metric):
    return float(row.get(metric, np.inf)) if "error" not in row else np.inf


def choose_lofo(results: dict, rule, grid, metric="hemispheres", protocols=PROTOCOLS) -> dict:
    """Tune ``rule`` leave one family out.

    ``rule(rows_by_protocol, value) -> fitter name`` picks a candidate for one fabric
    (it may look at any row, as a user's data would let it: ``rows`` hold the scores).
    For each held-out family F the ``value`` from ``grid`` with the lowest summed
    ``metric`` over every other family (both protocols) is chosen, then applied to F.

    Returns ``{family: {"value": chosen, "choices": {fabric: {protocol: name}}}}``.
    """
    fams = [f for f, fabs in results.items() if fabs]

    def total(fam_list, v):
        s = 0.0
        for f in fam_list:
            for fab in results[f].values():
                for p in protocols:
                    s += _value(fab[p][rule(fab[p], v, p)], metric)
        return s

    out = {}
    for fam in fams:
        others = [f for f in fams if f != fam]
        v = min(grid, key=lambda g: (total(others, g), str(g)))
        out[fam] = {"value": v, "choices": {fab: {p: rule(rows[p], v, p) for p in protocols}
                                           for fab, rows in results[fam].items()}}
    return out


def family_table(results: dict, fitters, protocols=PROTOCOLS) -> dict:
    """Per family, protocol and fitter: the median over the family's fabrics of each metric."""
    table = {}
    for fam, fabs in results.items():
        if not fabs:
            table[fam] = {"note": "no fabric (optional reference unavailable)"}
            continue
        table[fam] = {}
        for p in protocols:
            table[fam][p] = {}
            for n in fitters:
                rows = [fab[p][n] for fab in fabs.values() if n in fab[p]]
                ok = [r for r in rows if "error" not in r]
                cell = {k: (float(np.median([r[k] for r in ok])) if ok and all(k in r for r in ok) else None)
                        for k in ("orientations", "hemispheres", "fit_cpu_s")}
                cell["errors"] = len(rows) - len(ok)
                table[fam][p][n] = cell
    return table
