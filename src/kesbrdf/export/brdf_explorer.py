r"""BRDF Explorer export (format ``brdf-explorer``): the KES model itself as an analytic ``.brdf``.

Disney's BRDF Explorer (github.com/wdas/brdf) reads "analytic" files: a parameter
block and a GLSL function ``vec3 BRDF(vec3 L, vec3 V, vec3 N, vec3 X, vec3 Y)`` that
it pastes into its own shader templates (``#version 410``, one ``uniform`` per
parameter at ``::INSERT_UNIFORMS_HERE::``).  The function written here evaluates the
extended-KES model exactly as :func:`kesbrdf.models.brdf.evaluate` does (docs/formats.md,
"How to evaluate a model"): (φ, γ) by the deviation or half-vector mapping, bilinear
lookup of the table q (periodic in φ, γ clamped), f_r = c + fade(γ)·q/w with the
foreshortening weight w and the fade beyond the last measured γ that the model file's
``parameters.normalisation`` and ``parameters.extrapolation`` name (files without them:
w = √(cos θ_i cos θ_r) and the last column held; :func:`lobe_parameters`); the table, the
body term and those two choices are baked into constants.  So the polar, 3-D, albedo and
lit-sphere views show the model, not a fit.

Parameters exposed in BRDF Explorer: ``bool halfvector`` (mapping; default: the
model's ``deviation``), ``float scale`` (multiplies f_r, default 1), ``color tint``
(multiplies the body term c, default white: a colourway, docs/method.md, "Colour").

Constant-array size.  BRDF Explorer has no texture slot for an analytic BRDF, and
GLSL drivers compile very large constant arrays slowly or not at all, so the table is
resampled in φ (with the model's own bilinear lookup; the γ grid is kept) to at most
:data:`MAX_TABLE_ENTRIES` entries per channel (default 90 φ, i.e. 4°); the error this costs is measured
against the full model at random pairs and returned (and written in the file's
header comment).  ``n_phi`` / ``n_gamma`` override the grid.

The ``paper`` mapping (eq. 3–4 literally) and the ``kes-halfdiff`` kind are not
exported (a :class:`~kesbrdf.errors.KesbrdfError` says so).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from kesbrdf._atomic import atomic_path
from kesbrdf.errors import KesbrdfError
from kesbrdf.export._framework import ExportResult
from kesbrdf.models.mappings import BOUNDED_LAMBDA, EXTRAPOLATIONS, FADE_DEG, NORMALISATIONS

__all__ = ["export", "brdf_explorer_source", "resample_table", "lobe_parameters", "glsl_function", "KES_GLSL", "BRDF_EXPLORER_HEADER", "MAX_TABLE_ENTRIES", "OPEN_WITH"]

#: The model's evaluation in GLSL, the one copy shared with the browser viewer
#: (``src/kesbrdf/shaders/kes_brdf.glsl``): this export puts its constant arrays before it.
KES_GLSL = (Path(__file__).resolve().parents[1] / "shaders" / "kes_brdf.glsl").read_text(encoding="utf-8")

#: Largest baked table: entries per channel.  Each channel is its own ``const float``
#: array: ANGLE (Chromium's WebGL) rejects a private variable over 64 KiB ("Size of
#: declared private variable exceeds implementation-defined limit", measured with one
#: vec3 array of 10200 entries), and SwiftShader returned zeros for 3 × 15300 floats
#: while 3 × 7650 (90 φ × 85 γ) evaluated correctly; 8192 per channel is the bound.
MAX_TABLE_ENTRIES = 8192
#: default φ resolution of the baked table (4°; the model's own is 1°)
DEFAULT_N_PHI = 90
OPEN_WITH = "Disney BRDF Explorer (github.com/wdas/brdf): File > Open BRDF..., then the polar, 3D, albedo and lit-sphere views"

#: What BRDF Explorer puts before the BRDF function in its fragment templates
#: (src/shaderTemplates/brdftemplatesphere.frag: ``#version 410``, its own uniforms, then
#: one uniform per parameter: float → float, bool → bool, color → vec3).
BRDF_EXPLORER_HEADER = """#version 410
uniform vec3 incidentVector;
uniform float incidentTheta;
uniform float incidentPhi;
uniform float brightness;
uniform float gamma;
uniform float exposure;
uniform float useNDotL;
in vec4 worldSpaceVert;
in vec4 eyeSpaceVert;
out vec4 fragColor;
uniform float scale;
uniform bool halfvector;
uniform vec3 tint;
"""

#: A main() like the templates' (evaluates BRDF), so the unit links as a fragment shader.
BRDF_EXPLORER_MAIN = """
void main()
{
    vec3 N = vec3(0.0, 0.0, 1.0);
    vec3 V = normalize(eyeSpaceVert.xyz);
    vec3 b = max(BRDF(incidentVector, V, N, vec3(1.0, 0.0, 0.0), vec3(0.0, 1.0, 0.0)), vec3(0.0));
    fragColor = vec4(b * brightness, 1.0);
}
"""


def resample_table(model, n_phi: int, n_gamma: int):
    """The model's table q resampled on a (n_phi × n_gamma) grid by its own bilinear lookup.

    Returns
    -------
    table : ndarray, shape (n_phi, n_gamma, 3)
    d_gamma : float
    """
    from kesbrdf.models.brdf import lookup

    phi = np.arange(n_phi) * (2 * np.pi / n_phi)
    gamma = np.linspace(0.0, model.gamma_max, n_gamma)
    q = lookup(model, phi[:, None], gamma[None, :])
    if q.shape[-1] == 1:
        q = np.repeat(q, 3, axis=-1)
    elif q.shape[-1] != 3:
        raise KesbrdfError(f"brdf-explorer export: expected 1 or 3 channels, got {q.shape[-1]}")
    return q, float(gamma[1] - gamma[0])


def _default_grid(model):
    """Keep the model's γ grid (the measured curves' resolution: resampling γ misplaces
    their kinks, up to 4× errors measured); reduce φ to fit :data:`MAX_TABLE_ENTRIES`."""
    n_gamma = model.gamma_grid.size
    n_phi = min(DEFAULT_N_PHI, model.phi_grid.size, max(4, MAX_TABLE_ENTRIES // n_gamma))
    return n_phi, n_gamma


def lobe_parameters(model) -> dict:
    """How the model scales its lobe (docs/formats.md, "How to evaluate a model", steps 2–3):
    ``normalisation``, ``extrapolation``, ``gamma_max`` (radians) and ``body_law`` (a, p of the
    body's shape, eq. B3 of :mod:`kesbrdf.models.body`; (0, 1): Lambertian), keyword arguments of
    :func:`glsl_function` and :func:`numpy_port`.  Files without the two parameters are
    read as the model reads them (``sqrtcos``, ``hold``)."""
    normalisation = getattr(model, "normalisation", "sqrtcos")
    extrapolation = getattr(model, "extrapolation", "hold")
    if normalisation not in NORMALISATIONS or extrapolation not in EXTRAPOLATIONS:
        raise KesbrdfError(
            f"brdf-explorer export: expected normalisation in {', '.join(NORMALISATIONS)} and extrapolation in "
            f"{', '.join(EXTRAPOLATIONS)}, got {str(normalisation)[:40]!r} and {str(extrapolation)[:40]!r}"
        )
    law = getattr(model, "body_law", None)
    return {"normalisation": normalisation, "extrapolation": extrapolation, "gamma_max": float(model.gamma_max),
            "body_law": (0.0, 1.0) if law is None else (float(law.a), float(law.p))}


def _lobe_constants(normalisation: str, extrapolation: str):
    """(λ, fade slope) of the baked shader: w = max(√(cos θ_i cos θ_r), λ·max(cos θ_i, cos θ_r))
    with λ = 0 for ``sqrtcos``; fade = clamp(1 − (γ − γ_max)·slope, 0, 1) with slope 0 for
    ``hold`` (exactly 1 everywhere)."""
    if normalisation not in NORMALISATIONS:
        raise KesbrdfError(f"unknown normalisation {normalisation!r}; expected one of {', '.join(NORMALISATIONS)}")
    if extrapolation not in EXTRAPOLATIONS:
        raise KesbrdfError(f"unknown extrapolation {extrapolation!r}; expected one of {', '.join(EXTRAPOLATIONS)}")
    lam = BOUNDED_LAMBDA if normalisation == "bounded" else 0.0
    slope = 1.0 / math.radians(FADE_DEG) if extrapolation == "fade" else 0.0
    return lam, slope


def _body3(model):
    body = np.atleast_1d(np.asarray(model.body, float))
    return np.repeat(body, 3) if body.size == 1 else body[:3]


def _f(x: float) -> str:
    """A GLSL float literal (always with a point and an exponent), float32-exact."""
    return f"{float(x):.8e}"


def glsl_function(table, d_gamma: float, body, *, normalisation: str, extrapolation: str, gamma_max: float,
                  body_law=(0.0, 1.0)) -> str:
    """GLSL (the common subset of #version 410 and ES 3.00) of ``BRDF(L, V, N, X, Y)``.

    ``normalisation``, ``extrapolation``, ``gamma_max`` and ``body_law`` (a, p) are the
    model's (:func:`lobe_parameters`).
    """
    n_phi, n_gamma, _ = table.shape
    lam, slope = _lobe_constants(normalisation, extrapolation)
    n = n_phi * n_gamma

    def array(c: int) -> str:
        flat = [_f(a) for a in table[..., c].reshape(-1)]
        rows = ",\n".join("    " + ", ".join(flat[k : k + 8]) for k in range(0, n, 8))
        return f"const float KES_Q{c}[{n}] = float[{n}](\n{rows}\n);"
    b = [_f(v) for v in body]
    return f"""// kesbrdf extended-KES model (docs/formats.md "How to evaluate a model"), baked
const int kesNPhi = {n_phi};
const int kesNGamma = {n_gamma};
const float kesDGamma = {_f(d_gamma)};
const vec3 KES_BODY = vec3({b[0]}, {b[1]}, {b[2]});
// the body's shape g(mu) = 1 - a (1 - mu)^p, eq. B3 of kesbrdf.models.body (a = 0: Lambertian)
const float kesBodyA = {_f(body_law[0])};
const float kesBodyP = {_f(body_law[1])};
// the parameters: colour tint on the body term, mapping 0 deviation / 1 halfvector
#define kesBody (KES_BODY * tint)
#define kesMapping (halfvector ? 1 : 0)
// foreshortening weight w = max(sqrt(cos_i cos_r), kesLambda * max(cos_i, cos_r)): normalisation "{normalisation}"
const float kesLambda = {_f(lam)};
// lobe factor clamp(1 - (gamma - kesGammaMax) * kesFadeSlope, 0, 1): extrapolation "{extrapolation}"
const float kesGammaMax = {_f(gamma_max)};
const float kesFadeSlope = {_f(slope)};
const float kesLineSum = {_f(math.pi / 2)};  // unused: the paper mapping is not exported
// q(phi_i, gamma_j) of channel c at KES_Qc[i * kesNGamma + j], phi_i = i*2pi/kesNPhi, gamma_j = j*kesDGamma
{array(0)}
{array(1)}
{array(2)}

vec3 kesFetch(int i, int j)
{{
    int k = i * kesNGamma + j;
    return vec3(KES_Q0[k], KES_Q1[k], KES_Q2[k]);
}}

{KES_GLSL}
// L to the light, V to the viewer, N normal, X warp, Y weft (BRDF Explorer's frame)
vec3 BRDF(vec3 L, vec3 V, vec3 N, vec3 X, vec3 Y)
{{
    vec3 wi = vec3(dot(L, X), dot(L, Y), dot(L, N));
    vec3 wr = vec3(dot(V, X), dot(V, Y), dot(V, N));
    return scale * kesBRDF(wi, wr);
}}
"""


def brdf_explorer_source(model, n_phi: int | None = None, n_gamma: int | None = None) -> tuple[str, dict]:
    """Text of the ``.brdf`` file and a description of the baked table (``model.table_view()``:
    the (φ, γ) table, or the tabulated view of a kind without one)."""
    model = model.table_view()
    d_phi, d_gamma_n = _default_grid(model)
    n_phi = int(n_phi or d_phi)
    n_gamma = int(n_gamma or d_gamma_n)
    if n_phi < 4 or n_gamma < 2 or n_phi * n_gamma > MAX_TABLE_ENTRIES:
        raise KesbrdfError(
            f"brdf-explorer export: expected n_phi >= 4, n_gamma >= 2 and n_phi * n_gamma <= {MAX_TABLE_ENTRIES} "
            f"(GLSL constant-array limit), got {n_phi} x {n_gamma}"
        )
    lobe = lobe_parameters(model)
    table, d_gamma = resample_table(model, n_phi, n_gamma)
    halfvector = 1 if _halfvector(model) else 0
    info = {
        "n_phi": n_phi, "n_gamma": n_gamma, "d_phi_deg": 360.0 / n_phi, "d_gamma_deg": math.degrees(d_gamma),
        "entries_per_channel": n_phi * n_gamma, "normalisation": lobe["normalisation"], "extrapolation": lobe["extrapolation"],
    }
    text = f"""analytic

# kesbrdf extended-KES fabric model, evaluated by its own table lookup (not a fit).
# Table resampled to {n_phi} phi x {n_gamma} gamma ({info['d_phi_deg']:.3g} deg x {info['d_gamma_deg']:.3g} deg) from
# {model.phi_grid.size} x {model.gamma_grid.size}; frame: X = warp, Y = weft, N = normal.
# Foreshortening normalisation {lobe['normalisation']!r}, lobe beyond the last measured gamma: {lobe['extrapolation']!r}.
# [type] [name] [min val] [max val] [default val]

::begin parameters
float scale 0 4 1
bool halfvector {halfvector}
color tint 1 1 1
::end parameters

::begin shader
{glsl_function(table, d_gamma, _body3(model), **lobe)}
::end shader
"""
    return text, info


def _halfvector(model) -> bool:
    """Whether the table is read with the half-vector mapping: the model's own
    (``default_mapping``; ``deviation`` for a file that records none)."""
    return getattr(model, "default_mapping", "deviation") == "halfvector"


def downsampling_error(model, n_phi: int, n_gamma: int, n_pairs: int = 4000, seed: int = 20261201, max_theta_deg: float = 80.0) -> dict:
    """Relative error of the resampled table's f_r against the full model at random pairs
    (both read with the model's own mapping, the shader's default)."""
    from kesbrdf.models.brdf import evaluate

    table, d_gamma = resample_table(model, n_phi, n_gamma)
    rng = np.random.default_rng(seed)
    mu_min = math.cos(math.radians(max_theta_deg))

    def dirs():
        mu = rng.uniform(mu_min, 1, n_pairs)
        ph = rng.uniform(0, 2 * np.pi, n_pairs)
        s = np.sqrt(1 - mu**2)
        return np.stack([s * np.cos(ph), s * np.sin(ph), mu], -1)

    wi, wr = dirs(), dirs()
    ref = evaluate(model, wi, wr)
    if ref.shape[-1] == 1:
        ref = np.repeat(ref, 3, axis=-1)
    approx = numpy_port(table, d_gamma, _body3(model), wi, wr, halfvector=_halfvector(model), **lobe_parameters(model))
    rel = np.abs(approx - ref) / np.maximum(np.abs(ref), 1e-12)
    return {
        "median_rel": float(np.median(rel)),
        "p90_rel": float(np.quantile(rel, 0.9)),
        "max_rel": float(np.max(rel)),
        "n_pairs": n_pairs,
        "max_theta_deg": max_theta_deg,
    }


def numpy_port(table, d_gamma, body, wi, wr, halfvector: bool = False, *, normalisation: str, extrapolation: str, gamma_max: float,
               body_law=(0.0, 1.0)):
    """Line-by-line numpy port of :func:`glsl_function`'s ``BRDF`` (float64), shape (N, 3).

    ``normalisation``, ``extrapolation`` and ``gamma_max`` are the model's
    (:func:`lobe_parameters`).
    """
    n_phi, n_gamma, _ = table.shape
    lam, slope = _lobe_constants(normalisation, extrapolation)
    wi = np.asarray(wi, float)
    wr = np.asarray(wr, float)
    if halfvector:
        h = wi + wr
        h = h / np.linalg.norm(h, axis=-1, keepdims=True)
        gam = 2 * np.arctan2(np.hypot(h[..., 0], h[..., 1]), h[..., 2])
        s = h[..., :2]
    else:
        m = np.concatenate([-wi[..., :2], wi[..., 2:]], -1)
        gam = np.arctan2(np.linalg.norm(np.cross(wr, m), axis=-1), np.sum(wr * m, -1))
        s = wi[..., :2] + wr[..., :2]
    small = np.hypot(s[..., 0], s[..., 1]) < 1e-12
    s = np.where(small[..., None], wr[..., :2] - wi[..., :2], s)
    phi = np.arctan2(s[..., 1], s[..., 0])
    u = np.mod(phi, 2 * np.pi) / (2 * np.pi) * n_phi
    u0 = np.floor(u)
    fu = (u - u0)[..., None]
    i0 = u0.astype(int) % n_phi
    i1 = (i0 + 1) % n_phi
    v = np.clip(gam / d_gamma, 0, n_gamma - 1)
    v0 = np.floor(v)
    fv = (v - v0)[..., None]
    j0 = np.minimum(v0.astype(int), n_gamma - 1)
    j1 = np.minimum(j0 + 1, n_gamma - 1)
    a = table[i0, j0] * (1 - fv) + table[i0, j1] * fv
    b = table[i1, j0] * (1 - fv) + table[i1, j1] * fv
    q = a * (1 - fu) + b * fu
    w = np.maximum(np.sqrt(wi[..., 2] * wr[..., 2]), lam * np.maximum(wi[..., 2], wr[..., 2]))
    fade = np.clip(1.0 - (gam - gamma_max) * slope, 0.0, 1.0)
    a, p = body_law
    shape = 1.0 if a == 0.0 else ((1 - a * np.clip(1 - wi[..., 2], 0, 1) ** p) * (1 - a * np.clip(1 - wr[..., 2], 0, 1) ** p))[..., None]
    f = np.asarray(body) * shape + q * (fade / w)[..., None]
    above = (wi[..., 2] > 0) & (wr[..., 2] > 0)
    return np.where(above[..., None], f, 0.0)


#: File endings ``kesbrdf export`` accepts for this format (checked before any work).
EXTENSIONS = (".brdf",)
HELP = 'Disney BRDF Explorer analytic .brdf whose GLSL evaluates the KES table itself (not a fit)'


def export(model, out, *, n_phi: int | None = None, n_gamma: int | None = None) -> ExportResult:
    """Write ``model`` as a BRDF Explorer analytic ``.brdf`` file.

    Returns
    -------
    ExportResult
        ``agreement``: ``table`` (baked grid), ``downsampling_error`` (relative f_r error
        of the baked table against the model), ``exact``.
    """
    out = Path(out)
    if out.suffix.lower() != ".brdf":
        raise KesbrdfError(f"brdf-explorer export: expected an output ending in .brdf, got {out.name!r}")
    if not callable(getattr(model, "table_view", None)):
        raise KesbrdfError(f"brdf-explorer export: expected a 'kes' model or a model of any kind (its (phi, gamma) "
                           f"table view), got {type(model).__name__}")
    notes = [] if model.has_table else [
        f"the GLSL evaluates the (phi, gamma) table tabulated from the {model.kind!r} model "
        "(kesbrdf.models.table.tabulate), exact on the paper's incidence line"]
    model = model.table_view()
    text, info = brdf_explorer_source(model, n_phi, n_gamma)
    err = downsampling_error(model, info["n_phi"], info["n_gamma"])
    with atomic_path(out) as tmp:
        tmp.write_text(text)
    agreement = {
        "table": info,
        "downsampling_error": err,
        "fit_error": None,
        "exact": info["n_phi"] == model.phi_grid.size and info["n_gamma"] == model.gamma_grid.size,
    }
    return ExportResult("brdf-explorer", [out], size=out.stat().st_size, agreement=agreement, notes=notes,
                        open_with=OPEN_WITH)
