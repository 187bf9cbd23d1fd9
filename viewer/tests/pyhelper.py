"""Python side of the viewer's browser tests (run with KESBRDF_PYTHON, PYTHONPATH=../src).

    python pyhelper.py fixtures OUTDIR
        writes OUTDIR/good.csv (paper protocol, anisotropic Ward, RGB),
        OUTDIR/bad.csv (text in a numeric field), OUTDIR/big.csv (over the upload
        limit given by --limit) and OUTDIR/model/ward.kes.json fitted from good.csv.
    python pyhelper.py reference MODEL OUT.json
        seeded direction pairs and f_r from kesbrdf.models.brdf.evaluate for every mapping,
        the numbers the GLSL shader must reproduce.
"""

from __future__ import annotations

import base64
import json
import sys
from pathlib import Path

import numpy as np

#: Ward lobe of the test fabric: narrow along the warp, wide along the weft.
WARD = {"reference": "ward", "alpha_x": 0.12, "alpha_y": 0.3, "rho_d": [0.25, 0.08, 0.05], "rho_s": 0.2}
SEED = 20260522
#: Pairs closer than this to the horizon are skipped: 1/sqrt(cos cos) amplifies float32 rounding.
MAX_THETA_DEG = 80.0
#: The paper mapping divides by sin(beta); skip pairs where it is nearly singular.
MIN_SIN_BETA = 0.05
#: Paper mapping folds (phi, gamma<0) to (phi+pi, -gamma); skip pairs this close to the fold.
MIN_PAPER_GAMMA_DEG = 0.5


def ward(wi, wr):
    ax, ay = WARD["alpha_x"], WARD["alpha_y"]
    rho_d = np.asarray(WARD["rho_d"], float)
    h = wi + wr
    e = ((h[..., 0] / ax) ** 2 + (h[..., 1] / ay) ** 2) / h[..., 2] ** 2
    spec = np.exp(-e) / (4 * np.pi * ax * ay * np.sqrt(wi[..., 2] * wr[..., 2]))
    return rho_d / np.pi + WARD["rho_s"] * spec[..., None]


def sph(theta, phi):
    theta, phi = np.broadcast_arrays(np.asarray(theta, float), np.asarray(phi, float))
    return np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1)


def write_fixtures(out: Path, limit: int) -> None:
    out.mkdir(parents=True, exist_ok=True)
    k = np.arange(1, 30)
    rows = []
    for psi in (0, 45, 90, 135):
        ti, tr = 90 - 3 * k, 3 * k
        wi = sph(np.radians(ti), np.radians(psi + 180))
        wr = sph(np.radians(tr), np.radians(psi))
        f = ward(wi, wr)
        for a, b, v in zip(ti, tr, f):
            rows.append(f"{psi},{a},{b},{v[0]:.9g},{v[1]:.9g},{v[2]:.9g}")
    head = [
        "# kesbrdf-measurement: 1",
        "# sample: virtual satin (Ward) for the viewer tests",
        "# instrument: kesbrdf viewer test fixture",
        "# quantity: brdf",
        "# simulated: true",
        f"# generator: {json.dumps(WARD)}",
        "psi_deg,theta_i_deg,theta_r_deg,R,G,B",
    ]
    (out / "good.csv").write_text("\n".join(head + rows) + "\n")
    bad = head + rows[:5] + ["45,87,3,0.1,oops,0.2"] + rows[5:10]
    (out / "bad.csv").write_text("\n".join(bad) + "\n")
    with open(out / "big.csv", "w") as fh:
        fh.write("\n".join(head) + "\n")
        line = rows[0] + "\n"
        fh.write(line * (limit // len(line) + 10))
    model_dir = out / "model"
    model_dir.mkdir(exist_ok=True)
    fit_model(out / "good.csv", model_dir / "ward.kes.json")
    # a lobe without the Ward symmetries (phi -> -phi, phi -> phi + pi), so that a
    # mirrored or transposed lookup in the shader cannot pass the agreement test
    (out / "asym").mkdir(exist_ok=True)
    synthetic_model(out / "asym" / "asym.kes.json")


def fit_model(csv: Path, target: Path) -> None:
    try:
        from kesbrdf.io.measurement_csv import read_measurement
        from kesbrdf.models.kes import fit
    except ImportError:
        return synthetic_model(target)
    fit(read_measurement(csv)).save(target)


def _arr(a) -> dict:
    a = np.ascontiguousarray(np.asarray(a, "<f8"))
    return {"dtype": "<f8", "shape": list(a.shape), "data": base64.b64encode(a.tobytes()).decode()}


def synthetic_model(target: Path) -> None:
    """A model file per docs/formats.md with an asymmetric lobe (no Ward symmetries) and a
    Fresnel-like body (body_law a = 0.9, p = 4), also used for ward.kes.json while
    kesbrdf.models.kes is not installed."""
    n_phi, n_gamma = 72, 29
    phi = np.arange(n_phi) * 2 * np.pi / n_phi
    gamma = np.linspace(0, np.radians(84), n_gamma)
    width = 0.15 + 0.12 * np.cos(phi) ** 2 + 0.05 * np.sin(phi) + 0.03 * np.sin(2 * phi)
    lobe = np.exp(-((gamma[None, :] / width[:, None]) ** 2))
    table = lobe[..., None] * np.array([0.9, 0.7, 0.5]) + 0.01
    nodes = np.radians(np.arange(0, 85, 6.0))
    half = np.arange(8) * np.pi / 4
    w_nodes = 0.15 + 0.12 * np.cos(half) ** 2 + 0.05 * np.sin(half) + 0.03 * np.sin(2 * half)
    q_nodes = np.exp(-((nodes[:, None] / w_nodes[None, :]) ** 2))[..., None] * np.array([0.9, 0.7, 0.5]) + 0.01
    doc = {
        "format": "kesbrdf-model",
        "format_version": 1,
        "kesbrdf_version": "0.1.0",
        "kind": "kes",
        "channels": ["R", "G", "B"],
        "input": {"name": "synthetic", "sha256": "", "sample": "synthetic test lobe", "quantity": "brdf"},
        "parameters": {"orientations": 4, "noise_floor": 1e-6, "fallback": "error", "body": "auto", "gamma_interpolation": "linear"},
        "diagnostics": {"fallback_gamma_deg": [], "floored": [], "residual_135": {}},
        "body_law": {"a": 0.9, "p": 4.0},
        "arrays": {
            "phi_grid": _arr(phi),
            "gamma_grid": _arr(gamma),
            "table": _arr(table),
            "body": _arr([0.08, 0.025, 0.016]),
            "gamma_nodes": _arr(nodes),
            "q_nodes": _arr(q_nodes),
        },
    }
    target.write_text(json.dumps(doc))


# -- reference f_r -------------------------------------------------------------------
def _decode(a) -> np.ndarray:
    return np.frombuffer(base64.b64decode(a["data"]), "<f8").reshape(a["shape"])


def recipe_evaluate(doc: dict, wi, wr, mapping: str) -> np.ndarray:
    """docs/formats.md 'How to evaluate a model', used only when kesbrdf.models.brdf is absent
    (parameters.normalisation / extrapolation as there: absent means sqrtcos / hold)."""
    arrays = doc["arrays"]
    table, body = _decode(arrays["table"]), _decode(arrays["body"])
    gamma_grid = _decode(arrays["gamma_grid"])
    n_phi, n_gamma = table.shape[:2]
    params = doc.get("parameters") or {}
    lam = 0.5 if params.get("normalisation", "sqrtcos") == "bounded" else 0.0
    slope = 1.0 / np.radians(6.0) if params.get("extrapolation", "hold") == "fade" else 0.0
    line_sum = np.radians(float((doc.get("diagnostics") or {}).get("incidence_line_deg", params.get("incidence_line_deg", 90.0))))
    law = doc.get("body_law") or {"a": 0.0, "p": 1.0}  # docs/formats.md step 3: c g(cos θ_i) g(cos θ_r)

    def g(mu):
        return 1 - float(law["a"]) * np.clip(1 - mu, 0, 1) ** float(law["p"])
    scale = np.ones(wi.shape[:-1])
    if mapping == "deviation":
        m = wi * np.array([-1.0, -1.0, 1.0])
        gamma = np.arctan2(np.linalg.norm(np.cross(wr, m), axis=-1), np.sum(wr * m, -1))
        s = (wi + wr)[..., :2]
    elif mapping == "halfvector":
        h = wi + wr
        h = h / np.linalg.norm(h, axis=-1, keepdims=True)
        gamma = 2 * np.arctan2(np.hypot(h[..., 0], h[..., 1]), h[..., 2])
        s = h[..., :2]
    else:
        t_i = np.arctan2(np.hypot(wi[..., 0], wi[..., 1]), wi[..., 2])
        t_r = np.arctan2(np.hypot(wr[..., 0], wr[..., 1]), wr[..., 2])
        p_i = np.arctan2(wi[..., 1], wi[..., 0])
        p_r = np.arctan2(wr[..., 1], wr[..., 0])
        phi = np.pi / 2 - (p_i + p_r)
        gamma = t_r - t_i
        phi = np.where(gamma < 0, phi + np.pi, phi)
        gamma = np.abs(gamma)
        sin_half_beta = np.minimum(0.5 * np.sqrt(np.sin(p_r - p_i - np.pi) ** 2 + np.cos(t_r) ** 2), 1)
        sin_beta = np.maximum(np.sin(2 * np.arcsin(sin_half_beta)), 1e-6)
        ga = np.abs(t_r - t_i)
        body_paper = body * (np.sqrt(np.clip(np.cos(t_r - t_i), 0, None) / 2)
                             * g(np.cos((line_sum - ga) / 2)) * g(np.cos((line_sum + ga) / 2)))[..., None]
        if lam > 0:  # the table holds (f - c)·w; the paper reads (f - c)·√(cos θ_i cos θ_r) on the line
            geo = np.sqrt(np.clip((np.cos(gamma) + np.cos(line_sum)) / 2, 0, None))
            scale = scale * geo / np.maximum(geo, lam * np.cos(np.clip((line_sum - gamma) / 2, 0, np.pi / 2)))
    if mapping != "paper":
        d = (wr - wi)[..., :2]
        small = np.hypot(s[..., 0], s[..., 1]) < 1e-12
        s = np.where(small[..., None], d, s)
        phi = np.arctan2(s[..., 1], s[..., 0])
    u = np.mod(phi, 2 * np.pi) / (2 * np.pi) * n_phi
    v = np.clip(gamma / (gamma_grid[1] - gamma_grid[0]), 0, n_gamma - 1)
    i0 = np.floor(u).astype(int) % n_phi
    fu = (u - np.floor(u))[..., None]
    j0 = np.minimum(np.floor(v).astype(int), n_gamma - 1)
    j1 = np.minimum(j0 + 1, n_gamma - 1)
    fv = (v - j0)[..., None]
    i1 = (i0 + 1) % n_phi
    q = (1 - fu) * ((1 - fv) * table[i0, j0] + fv * table[i0, j1]) + fu * ((1 - fv) * table[i1, j0] + fv * table[i1, j1])
    if mapping == "paper":
        f = (q * scale[..., None] + body_paper) * (1 / (np.sqrt(wi[..., 2] * wr[..., 2]) * sin_beta))[..., None]
    else:
        w = np.maximum(np.sqrt(wi[..., 2] * wr[..., 2]), lam * np.maximum(wi[..., 2], wr[..., 2]))
        fade = np.clip(1 - (gamma - gamma_grid[-1]) * slope, 0, 1)
        f = body * (g(wi[..., 2]) * g(wr[..., 2]))[..., None] + q * (fade / w)[..., None]
    return np.where(((wi[..., 2] > 0) & (wr[..., 2] > 0))[..., None], f, 0.0)


def reference(model_path: Path, out: Path) -> None:
    doc = json.loads(model_path.read_text())
    rng = np.random.default_rng(SEED)
    n = 400
    t_max = np.radians(MAX_THETA_DEG)
    wi = sph(np.arccos(rng.uniform(np.cos(t_max), 1, n)), rng.uniform(-np.pi, np.pi, n))
    wr = sph(np.arccos(rng.uniform(np.cos(t_max), 1, n)), rng.uniform(-np.pi, np.pi, n))
    # the measured in-plane geometries (paper protocol), incl. the exact mirror pairs
    k = np.arange(1, 30)
    psi = np.radians(np.repeat([0.0, 45.0, 90.0, 135.0], k.size))
    ti = np.radians(np.tile(90.0 - 3 * k, 4))
    tr = np.radians(np.tile(3.0 * k, 4))
    keep = (ti <= t_max) & (tr <= t_max)
    wi = np.concatenate([wi, sph(ti, psi + np.pi)[keep], sph(np.radians(45.0), psi[:4] + np.pi)])
    wr = np.concatenate([wr, sph(tr, psi)[keep], sph(np.radians(45.0), psi[:4])])
    # exact mirror pairs: wr.xy = -wi.xy bit for bit
    wr[-4:] = wi[-4:] * np.array([-1.0, -1.0, 1.0])
    try:
        from kesbrdf.models.brdf import evaluate
        from kesbrdf.io.model_file import load_model as load

        model = load(model_path)
        source = "kesbrdf.models.brdf.evaluate"
        def f(mapping):
            return np.asarray(evaluate(model, wi, wr, mapping=mapping), float)
    except ImportError:
        source = "recipe helper (kesbrdf.models.brdf not installed)"
        def f(mapping):
            return recipe_evaluate(doc, wi, wr, mapping)
    result = {"source": source, "channels": doc["channels"], "pairs": [], "values": {}}
    t_i = np.arccos(np.clip(wi[..., 2], -1, 1))
    t_r = np.arccos(np.clip(wr[..., 2], -1, 1))
    p_i = np.arctan2(wi[..., 1], wi[..., 0])
    p_r = np.arctan2(wr[..., 1], wr[..., 0])
    sin_half = 0.5 * np.sqrt(np.sin(p_r - p_i - np.pi) ** 2 + np.cos(t_r) ** 2)
    paper_ok = (np.sin(2 * np.arcsin(np.minimum(sin_half, 1))) > MIN_SIN_BETA) & (
        np.abs(t_r - t_i) > np.radians(MIN_PAPER_GAMMA_DEG)
    )
    result["pairs"] = [[a.tolist(), b.tolist()] for a, b in zip(wi, wr)]
    result["paper_ok"] = paper_ok.tolist()
    for mapping in ("deviation", "halfvector", "paper"):
        v = f(mapping)
        c = v.shape[-1]
        rgb = v if c == 3 else np.repeat(v.mean(-1, keepdims=True), 3, -1)
        result["values"][mapping] = rgb.tolist()
    out.write_text(json.dumps(result))


if __name__ == "__main__":
    if sys.argv[1] == "fixtures":
        limit = int(sys.argv[3]) if len(sys.argv) > 3 else 5 * 1024 * 1024
        write_fixtures(Path(sys.argv[2]), limit)
    elif sys.argv[1] == "reference":
        reference(Path(sys.argv[2]), Path(sys.argv[3]))
    else:
        sys.exit(f"usage: {sys.argv[0]} fixtures OUTDIR [LIMIT] | reference MODEL OUT.json")
