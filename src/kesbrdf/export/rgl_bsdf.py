r"""Export a model as an RGL tensor file ``.bsdf`` (Dupuy & Jakob 2018).

The measured-BRDF format of Mitsuba 3's ``measured`` plugin (RGB variant, format
``rgl-bsdf``) and pbrt-v4's ``MeasuredBxDF`` (spectral variant, ``rgl-bsdf-spectral``).
The file stores, per incident direction ω_i on a (φ_i, θ_i) grid, the ratio

.. math:: T(s \mid \omega_i) = \frac{f_r(\omega_i, \omega_o)\cos\theta_o \; 4\sigma(\omega_i)}{D(m)}

on a uniform N × N grid of points s of the *sample space* of the visible-normal
warp: m = VNDF(s | ω_i) (Marginal2D, :mod:`kesbrdf.references.marginal2d`), ω_o = reflect(ω_i, m).
A reader inverts the warp, interpolates T and multiplies by D/(4σ) (``jacobian`` = 1).

The parameterisation is built from the model itself (Dupuy & Jakob sec. 4–5):

* **NDF** D(m): the retro-reflection proxy D ∝ Y(f_r(m, m))·cos²θ_m (for a microfacet BRDF
  f_r(ω, ω) = D F G / (4 cos²θ)), normalised to ∫D cos θ dω = 1, then mixed with a
  cosine floor, D ← (1 − ε) D + ε/π, so that D > 0 wherever the model reflects
  (the body term included);  tabulated on the (u_φ, u_θ) grid u_θ = sqrt(2θ/π),
  u_φ = (φ + π)/2π;
* **σ(ω)** = ∫ D(m) ⟨ω, m⟩₊ dm by quadrature of the interpolant (σ(normal) = 1);
* **VNDF** per (φ_i, θ_i): D(m)⟨ω_i, m⟩₊/σ(ω_i) times the u-space Jacobian 2π² u_θ sin θ_m;
* **luminance**: Y = 0.2126 R + 0.7152 G + 0.0722 B of the stored table (sampling only).

Option ``vndf="model"`` replaces the VNDF by the model's own lobe in half-vector space
(and the luminance by 1): better value-weighted agreement on narrow satins, worse 90th
percentiles elsewhere (``docs/exports.md``).

The writer divides by the *interpolated* D(u_m) and σ(u_i) that the reader computes,
so that the ratio is exact at the grid nodes.  The model is evaluated as Mitsuba
renders it: the table's incident direction is Mitsuba's ``si.wi`` (toward the camera,
the model's ω_r) and ω_o the light (ω_i); the models are reciprocal, so this only
fixes where the cosine sits.  Frame: Mitsuba's shading frame (s, t, n) = (warp, weft,
normal), i.e. the fabric frame.  Outgoing directions that fall below the horizon are
evaluated at z = 10⁻³ (they still enter the interpolation).

Grid (default 17 θ_i × 33 φ_i × 48², NDF/VNDF 32 × 32, 21.9 MiB) and floor ε = 0.2 were
chosen from measured error (``benchmarks/bench_export.py``, table in ``docs/exports.md``):
halving φ_i (33 → 17) costs most, then the table resolution N (32 → 48 halves the error at
the nodes on a satin), then θ_i (17 → 25 gains little); the NDF resolution (32 vs 64)
does not matter; ε = 0.2 beats 0.05 and 0.01 at the 90th percentile.  Grazing pairs are
worst.

Spectral variant (pbrt-v4 has no RGB path): each RGB table value is turned into a
spectrum by the linear smooth basis of :mod:`kesbrdf.export.spectra`
(ρ(λ) = R b_R(λ) + G b_G(λ) + B b_B(λ), b ≥ 0, b_R + b_G + b_B ≈ 1), sampled at
``wavelengths``.  φ_i covers [−π, π] (reduction 1), which pbrt-v4 requires.
"""

from __future__ import annotations

import time

import numpy as np

from kesbrdf.errors import ExportError
from kesbrdf.export._framework import ExportResult
from kesbrdf.references.marginal2d import Marginal2D

__all__ = ["export", "build_fields", "model_brdf", "agreement", "EXTENSIONS", "HELP", "DEFAULTS"]

EXTENSIONS = (".bsdf",)
HELP = "RGL tensor file for Mitsuba 3 `measured` (RGB; 'rgl-bsdf-spectral' for pbrt-v4 MeasuredBxDF)"

#: Default resolution (see module docstring and docs/exports.md for how it was chosen).
DEFAULTS = {"n_theta_i": 17, "n_phi_i": 33, "n": 48, "n_ndf": 32, "floor": 0.2, "theta_i_max_deg": 89.0,
            "vndf": "microfacet"}
#: Table resolution of the spectral variant (about 44 MiB with 17 wavelengths).
SPECTRAL_N = 32
#: How the visible-normal warp is built (module docstring).
VNDF_KINDS = ("microfacet", "model")
#: Rec. 709 / sRGB luminance weights.
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
#: Lowest cos θ_o at which a sample below the horizon is evaluated.
HORIZON_Z = 1e-3
#: Samples per chunk when warping (bounds memory: chunk × 4 corners × grid width).
CHUNK = 1 << 15


def _sph(theta, phi):
    st = np.sin(theta)
    return np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)], axis=-1)


def _u2theta(u):
    return u * u * (np.pi / 2)


def _u2phi(u):
    return (2 * u - 1) * np.pi


def resolve_mapping(model, mapping=None) -> str:
    """``mapping``, or the model kind's default (``deviation`` for kinds that have none)."""
    if mapping is not None:
        return mapping
    try:
        return model.default_mapping
    except (AttributeError, IndexError):
        return "deviation"  # kesbrdf.models.brdf.evaluate's default; kinds with one mapping ignore it


def model_brdf(model, mapping=None):
    """f(w_light, w_view) -> (n, 3) RGB in 1/sr for a model of 1 or 3 channels."""
    from kesbrdf.models.brdf import evaluate

    channels = getattr(model, "channels", ())
    if len(channels) not in (1, 3):
        raise ExportError(f"rgl-bsdf: expected a model with 1 (grey) or 3 (RGB) channels, got {len(channels)}")
    mapping = resolve_mapping(model, mapping)

    def f(w_light, w_view):
        v = np.asarray(evaluate(model, w_light, w_view, mapping), float)
        v = np.nan_to_num(v, nan=0.0, posinf=0.0)
        return np.repeat(v, 3, axis=-1) if v.shape[-1] == 1 else v

    return f


def _ndf_sigma(f, n_ndf: int, floor: float):
    """NDF and σ tables on the (u_φ, u_θ) grid, shape (n_ndf, n_ndf) each."""
    u = np.linspace(0.0, 1.0, n_ndf)
    theta = _u2theta(u)[None, :]
    phi = _u2phi(u)[:, None]
    m = _sph(np.broadcast_to(theta, (n_ndf, n_ndf)), np.broadcast_to(phi, (n_ndf, n_ndf))).reshape(-1, 3)
    back = f(m, m) @ LUMINANCE
    d = np.maximum(back, 0.0) * m[:, 2] ** 2
    d = d.reshape(n_ndf, n_ndf)
    # quadrature of the bilinear interpolant in u-space: dω = 2π² u_θ sin θ du_θ du_φ
    k = 2 * n_ndf
    uq = (np.arange(k) + 0.5) / k
    qx, qy = np.meshgrid(uq, uq)
    q = np.stack([qx.ravel(), qy.ravel()], axis=-1)
    tq = _u2theta(q[:, 0])
    wq = 2 * np.pi**2 * q[:, 0] * np.sin(tq) / (k * k)
    mq = _sph(tq, _u2phi(q[:, 1]))

    def cos_integral(table):
        return float(np.sum(Marginal2D(table, normalize=False, sampling=False).eval(q) * np.cos(tq) * wq))

    total = cos_integral(d)
    if not np.isfinite(total) or total <= 0:
        d = np.full_like(d, 1.0 / np.pi)
    else:
        d = (1 - floor) * d / total + floor / np.pi
    d /= cos_integral(d)
    dq = Marginal2D(d, normalize=False, sampling=False).eval(q) * wq
    # σ at the grid nodes: ∫ D(m) <ω, m>+ dm
    sigma = np.concatenate([np.maximum(m[a : a + 256] @ mq.T, 0.0) @ dq for a in range(0, m.shape[0], 256)])
    return d, sigma.reshape(n_ndf, n_ndf)


def _unit_slices(t):
    """Each (φ_i, θ_i) slice scaled to unit sum."""
    total = t.sum(axis=(2, 3), keepdims=True)
    return t / np.where(total > 0, total, 1.0)


def _lobe_vndf(f, w_in, m_grid, jac):
    """The model's own lobe in u-space of the half vector, per incident direction:
    Y(f_r cos θ_o) |dω_o/dm| 2π² u_θ sin θ_m, with |dω_o/dm| = 4⟨ω_i, m⟩ (``vndf="model"``)."""
    npi, nt = w_in.shape[:2]
    nd = m_grid.shape[0]
    wi = np.broadcast_to(w_in[:, :, None, None, :], (npi, nt, nd, nd, 3)).reshape(-1, 3)
    m = np.broadcast_to(m_grid[None, None], (npi, nt, nd, nd, 3)).reshape(-1, 3)
    dot = np.sum(wi * m, axis=1)
    wo = 2 * dot[:, None] * m - wi
    above = (wo[:, 2] > 0) & (dot > 0)
    lobe = np.zeros(wi.shape[0])
    lobe[above] = (f(wo[above], wi[above]) @ LUMINANCE) * wo[above, 2] * 4 * dot[above]
    return lobe.reshape(npi, nt, nd, nd) * jac[None, None]


def build_fields(model, *, n_theta_i=None, n_phi_i=None, n=None, n_ndf=None, floor=None,
                 theta_i_max_deg=None, mapping=None, vndf=None, spectral=False, wavelengths=None,
                 description=None) -> dict:
    """The tensor-file fields for ``model`` (module docstring); nothing is written.

    Parameters
    ----------
    model : ReflectanceModel
    n_theta_i, n_phi_i : int
        Incident grid: θ_i uniform in [0, theta_i_max_deg], φ_i uniform in [−π, π].
    n : int
        Table resolution N (N × N points of the VNDF sample space per incident direction).
    n_ndf : int
        Resolution of the NDF, σ and VNDF grids (square).
    floor : float
        ε, weight of the cosine floor in D (and of the microfacet VNDF when ``vndf="model"``).
    theta_i_max_deg : float
        Last θ_i node (< 90°); beyond it the readers use the last node.
    mapping : str, optional
        Passed to :func:`kesbrdf.models.brdf.evaluate`; default the kind's own.
    vndf : {"microfacet", "model"}
        ``microfacet`` (default): D(m)⟨ω_i, m⟩/σ(ω_i), the luminance = Y of the table
        (Dupuy & Jakob).  ``model``: the model's lobe in half-vector space, luminance 1
        (docs/exports.md compares them).
    spectral : bool
        Write ``spectra`` + ``wavelengths`` (pbrt-v4) instead of ``rgb``.
    wavelengths : array_like, optional
        nm; default :data:`kesbrdf.export.spectra.WAVELENGTHS`.
    """
    o = dict(DEFAULTS)
    for k, v in dict(n_theta_i=n_theta_i, n_phi_i=n_phi_i, n=n, n_ndf=n_ndf, floor=floor,
                     theta_i_max_deg=theta_i_max_deg).items():
        if v is not None:
            o[k] = v
    for k in ("n_theta_i", "n_phi_i", "n", "n_ndf"):
        if not isinstance(o[k], (int, np.integer)) or isinstance(o[k], bool) or o[k] < (3 if k == "n_phi_i" else 2):
            raise ExportError(f"rgl-bsdf: option {k}: expected an integer >= {3 if k == 'n_phi_i' else 2}, got {o[k]!r}")
    if not (0 < float(o["floor"]) < 1):
        raise ExportError(f"rgl-bsdf: option floor: expected a number in (0, 1), got {o['floor']!r}")
    vndf_kind = o["vndf"] if vndf is None else vndf
    if vndf_kind not in VNDF_KINDS:
        raise ExportError(f"rgl-bsdf: option vndf: expected one of {', '.join(map(repr, VNDF_KINDS))}, got {vndf_kind!r}")
    if not (0 < float(o["theta_i_max_deg"]) < 90):
        raise ExportError(f"rgl-bsdf: option theta_i_max_deg: expected degrees in (0, 90), got {o['theta_i_max_deg']!r}")
    f = model_brdf(model, mapping)
    nt, npi, N, nd = int(o["n_theta_i"]), int(o["n_phi_i"]), int(o["n"]), int(o["n_ndf"])

    ndf, sigma = _ndf_sigma(f, nd, float(o["floor"]))
    ndf_i = Marginal2D(ndf, normalize=False, sampling=False)
    sigma_i = Marginal2D(sigma, normalize=False, sampling=False)

    theta_i = np.linspace(0.0, np.radians(float(o["theta_i_max_deg"])), nt).astype(np.float32)
    phi_i = np.linspace(-np.pi, np.pi, npi).astype(np.float32)
    th, ph = np.meshgrid(theta_i.astype(float), phi_i.astype(float))  # (npi, nt)
    w_in = _sph(th, ph)  # (npi, nt, 3)
    u_in = np.stack([np.sqrt(th * 2 / np.pi), (ph + np.pi) / (2 * np.pi)], axis=-1)
    sig_in = sigma_i.eval(u_in.reshape(-1, 2)).reshape(npi, nt)

    # VNDF per incident direction, in u-space (x = u_θ, y = u_φ)
    u = np.linspace(0.0, 1.0, nd)
    tm = _u2theta(u)[None, :]
    pm = _u2phi(u)[:, None]
    m_grid = _sph(np.broadcast_to(tm, (nd, nd)), np.broadcast_to(pm, (nd, nd)))  # (nd, nd, 3)
    jac = 2 * np.pi**2 * u[None, :] * np.sin(tm)
    dots = np.maximum(np.einsum("pti,yxi->ptyx", w_in, m_grid), 0.0)
    micro = ndf[None, None] * dots * jac[None, None] / sig_in[:, :, None, None]
    if vndf_kind == "microfacet":
        vndf_table = micro
    else:
        fl = float(o["floor"])
        vndf_table = (1 - fl) * _unit_slices(_lobe_vndf(f, w_in, m_grid, jac)) + fl * _unit_slices(micro)
    warp = Marginal2D(vndf_table, [phi_i, theta_i])

    # sample-space grid -> m -> ω_o, per incident direction
    s = np.linspace(0.0, 1.0, N)
    sx, sy = np.meshgrid(s, s)  # [j (y), i (x)]
    s_flat = np.stack([sx.ravel(), sy.ravel()], axis=-1)
    n_s = s_flat.shape[0]
    P = np.repeat(ph.ravel(), n_s)
    T = np.repeat(th.ravel(), n_s)
    S = np.tile(s_flat, (npi * nt, 1))
    um = np.empty_like(S)
    for a in range(0, S.shape[0], CHUNK):
        um[a : a + CHUNK], _ = warp.sample(S[a : a + CHUNK], (P[a : a + CHUNK], T[a : a + CHUNK]))
    m = _sph(_u2theta(um[:, 0]), _u2phi(um[:, 1]))
    wi = np.repeat(w_in.reshape(-1, 3), n_s, axis=0)
    wo = 2 * np.sum(wi * m, axis=1, keepdims=True) * m - wi
    low = wo[:, 2] < HORIZON_Z
    if low.any():
        xy = wo[low, :2]
        scale = np.sqrt((1 - HORIZON_Z**2) / np.maximum(np.sum(xy * xy, axis=1, keepdims=True), 1e-30))
        wo[low, :2] = xy * scale
        wo[low, 2] = HORIZON_Z
    value = f(wo, wi) * wo[:, 2:3]  # f_r(light = ω_o, viewer = ω_i) cos θ_o
    d_m = ndf_i.eval(um)
    ratio = value * (4 * np.repeat(sig_in.ravel(), n_s))[:, None] / np.maximum(d_m, 1e-30)[:, None]
    rgb = ratio.reshape(npi, nt, N, N, 3).transpose(0, 1, 4, 2, 3)  # (φ_i, θ_i, 3, N(y), N(x))
    if vndf_kind == "microfacet":
        lum = np.einsum("ptcyx,c->ptyx", rgb, LUMINANCE)
        lum = np.maximum(lum, 1e-4 * max(float(lum.mean()), 1e-30))
    else:
        lum = np.ones((npi, nt, N, N))  # the VNDF already follows f_r cos: sample it as is

    fields = {
        "description": description or _description(model, {**o, "vndf": vndf_kind, "mapping": resolve_mapping(model, mapping),
                                                             "spectral": bool(spectral)}),
        "jacobian": np.array([1], np.uint8),
        "theta_i": theta_i,
        "phi_i": phi_i,
        "ndf": ndf.astype(np.float32),
        "sigma": sigma.astype(np.float32),
        "vndf": vndf_table.astype(np.float32),
        "luminance": lum.astype(np.float32),
    }
    if spectral:
        from kesbrdf.export import spectra as _spectra

        lam = np.asarray(_spectra.WAVELENGTHS if wavelengths is None else wavelengths, float)
        basis = _spectra.basis(lam)  # (3, n_λ)
        fields["spectra"] = np.einsum("ptcyx,cl->ptlyx", rgb, basis).astype(np.float32)
        fields["wavelengths"] = lam.astype(np.float32)
    else:
        fields["rgb"] = rgb.astype(np.float32)
    return fields


def model_sha256(model) -> str:
    """sha256 of the model's file content (what ``model.save`` writes), for provenance."""
    import hashlib
    import json

    try:
        from kesbrdf.io.model_file import model_to_dict

        text = json.dumps(model_to_dict(model), sort_keys=True, default=str)
    except Exception:  # a kind without a model-file form: hash what identifies it
        text = repr((getattr(model, "kind", ""), getattr(model, "parameters", {})))
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def _description(model, options: dict) -> str:
    """Human-readable provenance in the file's ``description`` (readers print it)."""
    from kesbrdf._version import __version__

    kind = getattr(model, "kind", "model")
    grid = ", ".join(f"{k}={v}" for k, v in options.items())
    return (f"kesbrdf {kind} model (sha256 {model_sha256(model)[:16]}), exported by kesbrdf {__version__}; "
            f"{grid}")


def agreement(model, path, n_pairs: int = 4000, seed: int = 0, min_cos: float = 0.2, mapping=None) -> dict:
    """Agreement of the file (read in numpy, :class:`~kesbrdf.references.rgl_tensor.RGLTensorBRDF`)
    with the model at random pairs, both directions with cos θ > ``min_cos``.

    Relative error per pair and channel |f_file − f_model| / f_model, on the luminance;
    "grazing" = either direction beyond 60°.
    """
    from kesbrdf.references.rgl_tensor import RGLTensorBRDF

    rng = np.random.default_rng(seed)

    def dirs(k):
        z = rng.uniform(min_cos, 1.0, k)
        p = rng.uniform(-np.pi, np.pi, k)
        r = np.sqrt(1 - z * z)
        return np.stack([r * np.cos(p), r * np.sin(p), z], axis=-1)

    wi, wr = dirs(n_pairs), dirs(n_pairs)
    ref = RGLTensorBRDF(path, parameterised_by="viewer")
    got = ref(wi, wr)
    if ref.wavelengths is not None:
        from kesbrdf.export import spectra as _spectra

        got = _spectra.to_rgb(got, ref.wavelengths)
    want = model_brdf(model, mapping)(wi, wr)
    return relative_errors(got @ LUMINANCE, want @ LUMINANCE, wi, wr)


def relative_errors(got, want, wi, wr, grazing_deg: float = 60.0) -> dict:
    """Median / p90 / p99 relative error and the value-weighted error, split grazing vs not."""
    rel = np.abs(got - want) / np.maximum(np.abs(want), 1e-12)
    grazing = np.minimum(wi[:, 2], wr[:, 2]) < np.cos(np.radians(grazing_deg))
    out = {
        "median_rel_err": float(np.median(rel)),
        "p90_rel_err": float(np.percentile(rel, 90)),
        "p99_rel_err": float(np.percentile(rel, 99)),
        "weighted_rel_err": float(np.sum(np.abs(got - want)) / np.sum(np.abs(want))),
    }
    for name, mask in (("not_grazing", ~grazing), ("grazing", grazing)):
        if mask.any():
            out[f"median_rel_err_{name}"] = float(np.median(rel[mask]))
            out[f"p90_rel_err_{name}"] = float(np.percentile(rel[mask], 90))
    return out


#: Tensors built in this process, by model content and options: ``kesbrdf demo`` exports
#: ``rgl-bsdf`` and then ``mitsuba-scene``, whose ``measured`` scene needs the same RGB
#: tensor; without this the second export rebuilt it (15 s of the demo's CPU, profiled
#: with cProfile: 96 % of the mitsuba-scene export was ``build_fields``).  Two entries
#: (RGB and spectral); the arrays are a few MiB.
_FIELDS_MEMO: dict = {}
_FIELDS_MEMO_SIZE = 2


def _memo_key(model, spectral, options) -> str:
    import json

    resolved = {**options, "mapping": resolve_mapping(model, options.get("mapping"))}
    return json.dumps([model_sha256(model), bool(spectral), sorted((k, repr(v)) for k, v in resolved.items())])


def built_fields(model, spectral: bool = False, **options) -> dict:
    """:func:`build_fields`, memoised in this process by model content and options."""
    key = _memo_key(model, spectral, options)
    if key not in _FIELDS_MEMO:
        fields = build_fields(model, spectral=spectral, **options)
        while len(_FIELDS_MEMO) >= _FIELDS_MEMO_SIZE:
            _FIELDS_MEMO.pop(next(iter(_FIELDS_MEMO)))
        _FIELDS_MEMO[key] = fields
    return _FIELDS_MEMO[key]


def _export(model, out, spectral, check, **options) -> ExportResult:
    t0 = time.perf_counter()
    fields = built_fields(model, spectral=spectral, **options)
    seconds = time.perf_counter() - t0
    from kesbrdf.io.tensor_file import write_tensor_file

    write_tensor_file(out, fields)
    shape = fields["vndf"].shape[:2] + fields["luminance"].shape[2:]
    notes = [
        f"grid θ_i × φ_i × N² = {shape[1]} × {shape[0]} × {shape[2]}², NDF {fields['ndf'].shape[1]}², "
        f"written in {seconds:.1f} s",
        "exact at the grid nodes; between them interpolated (worst at grazing incidence)",
    ]
    agree = {}
    if check:
        agree = agreement(model, out, mapping=options.get("mapping"))
        notes.append("agreement: numpy re-implementation of the reader (same as Mitsuba's to ~1e-6), "
                     "random pairs with cos θ > 0.2, luminance")
    if spectral:
        notes.append("spectra from RGB by the smooth non-negative basis of kesbrdf.export.spectra (approximate)")
        open_with = ('pbrt-v4: Material "measured" "string filename" "OUT.bsdf"; '
                     'Mitsuba 3 (spectral variants): <bsdf type="measured"><string name="filename" value="OUT.bsdf"/></bsdf>')
    else:
        open_with = 'Mitsuba 3 (RGB variants): <bsdf type="measured"><string name="filename" value="OUT.bsdf"/></bsdf>'
    return ExportResult("rgl-bsdf-spectral" if spectral else "rgl-bsdf", [out], agreement=agree, notes=notes,
                        open_with=open_with.replace("OUT.bsdf", out.name))


def export(model, out, *, n_theta_i=None, n_phi_i=None, n=None, n_ndf=None, floor=None,
           theta_i_max_deg=None, mapping=None, vndf=None, description=None, check=True) -> ExportResult:
    """Write the RGB tensor file (Mitsuba 3 ``measured``); options as :func:`build_fields`.

    ``check`` (default true) measures the agreement of the written file with the model.
    """
    return _export(model, out, False, check, n_theta_i=n_theta_i, n_phi_i=n_phi_i, n=n, n_ndf=n_ndf,
                   floor=floor, theta_i_max_deg=theta_i_max_deg, mapping=mapping, vndf=vndf,
                   description=description)


def export_spectral(model, out, *, n_theta_i=None, n_phi_i=None, n=None, n_ndf=None, floor=None,
                    theta_i_max_deg=None, mapping=None, vndf=None, description=None, wavelengths=None,
                    check=True) -> ExportResult:
    """Write the spectral tensor file (pbrt-v4 ``MeasuredBxDF``, Mitsuba spectral variants).

    The table resolution defaults to :data:`SPECTRAL_N` (not ``DEFAULTS["n"]``): the file
    holds 17 wavelengths instead of 3 channels.
    """
    n = SPECTRAL_N if n is None else n
    return _export(model, out, True, check, n_theta_i=n_theta_i, n_phi_i=n_phi_i, n=n, n_ndf=n_ndf,
                   floor=floor, theta_i_max_deg=theta_i_max_deg, mapping=mapping, vndf=vndf,
                   description=description, wavelengths=wavelengths)
