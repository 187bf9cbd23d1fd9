r"""The ``kesbrdf_prior`` BSDF: a ``fibre-prior`` model file as a Mitsuba 3 plugin.

Evaluation is :meth:`kesbrdf.models.fibre_prior.FibrePriorModel.evaluate` in Dr.Jit (single
precision):

.. math::

    f_r(\omega_i, \omega_r) = g(\omega_i)\,g(\omega_r)\,f_\text{prior}(\omega_i, \omega_r)\cdot r(\omega_i, \omega_r)^{\tau}

* :math:`f_\text{prior} = k_d + \Phi(\theta_d)\sum_j k_{s,j} S_j` as
  :func:`kesbrdf.models.fibre_physics.evaluate_batch` (docs/prior.md): a filament family in closed form
  (u* = atan2(h'_y, h'_z), Ā the mean of the Seeliger law over the fixed
  :data:`kesbrdf.models.fibre_physics.N_V` across-yarn nodes); a staple family as the fixed
  :data:`kesbrdf.models.fibre_physics.N_U`-node tilt quadrature, a Python loop over the nodes that builds
  one Dr.Jit expression (the tilt profile P(u)·Δu of each node is a constant of the
  fitted model, computed once in float64).
* r is the residual table, read by the lookup code of the other plugins:
  :class:`kesbrdf.render.bsdf.KesTable` over (deviation φ, γ) for a paper-protocol fit,
  divided by the line weight √((cos γ + cos S)/2); :class:`kesbrdf.render.halfdiff_bsdf.HalfDiffTable`
  over (φ_h, θ_h, θ_d) for a dense fit.  The relaxation τ is
  :data:`kesbrdf.models.fibre_prior.RELAX_DEG`'s smoothstep beyond the measured γ (or θ_h),
  as in :meth:`~kesbrdf.models.fibre_prior.FibrePriorModel.residual_ratio`.
* g is the model's energy scale (:func:`kesbrdf.models.fibre_prior.energy_scale`): its table
  over cos θ (and φ mod 180° when it has more than one φ node) read (bi)linearly; 1
  for files without one.

Frames as :mod:`kesbrdf.render.bsdf`: local x = UV-u tangent = warp (the family at
α = 0); ``si.wi`` is the viewer ω_r, ``wo`` the light ω_i; two-sided mirroring, ``eval``,
``pdf`` and ``sample`` come from :class:`~kesbrdf.render.bsdf.FabricBSDF`.

Colour.  The body of this kind is the fitted Lambertian k_d; the lobe is everything
above it, L = f_r − k_d (the specular families and what the residual adds or removes).
``base_color`` replaces k_d by base_color/π and ``lobe_tint`` multiplies L:
f = max(0, c + t·L).  Unset, f is the model's f_r exactly.

Sampling: the mixture of :mod:`kesbrdf.render.sampling` with the ``halfvector`` lobe
(the fibre highlights live in the half vector), whose (φ_h, γ = 2θ_h) density is
:func:`lobe_table`: the lobe L·√(cos θ_i cos θ_r) averaged over a few difference
directions.  The pdf is the sampler's own, exact, whatever the density table is.

Parameters (scene description): ``filename`` (a ``fibre-prior`` model file),
``base_color``, ``lobe_tint``, ``two_sided``, ``sampling`` (``lobe`` or ``cosine``), as
the ``kesbrdf`` plugin.  ``extrapolation`` is accepted and ignored: the residual relaxes
to 1 by itself beyond the measured range, and the prior is defined everywhere.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

import drjit as dr
import mitsuba as mi

from kesbrdf.errors import ModelError, where
from kesbrdf.optics import fresnel_dielectric
from kesbrdf.render.bsdf import EXTRAPOLATIONS, SAMPLINGS, FabricBSDF, KesTable, parse_rgb, phi_gamma
from kesbrdf.render.halfdiff_bsdf import HalfDiffTable, half_diff
from kesbrdf.render.jit import opaque_float, opaque_rgb

__all__ = ["FibrePriorBSDF", "PriorDrJit", "family_frame", "as_rgb", "register", "check_prior_model", "lobe_table",
           "PLUGIN"]

#: Name of the plugin.
PLUGIN = "kesbrdf_prior"
#: Half-vector grid of the sampling density: φ_h step and θ_h step, degrees; θ_h up to
#: LOBE_THETA_H_MAX (beyond, h near the horizon reflects most viewers below it).
LOBE_DPHI_DEG = 2.5
LOBE_DTHETA_DEG = 1.5
LOBE_THETA_H_MAX_DEG = 81.0
#: Difference directions (θ_d, φ_d) the density averages over, degrees.
LOBE_THETA_D_DEG = (10.0, 30.0, 50.0)
LOBE_PHI_D_DEG = (0.0, 90.0)


def _prop(props, name, default=None):
    return props[name] if name in props else default


def as_rgb(a):
    """Per-channel values (..., 1 or 3) as RGB (..., 3): a grey channel repeated."""
    a = np.asarray(a, float)
    return np.repeat(a, 3, axis=-1) if a.shape[-1] == 1 else a


def check_prior_model(path, plugin_name: str = PLUGIN, kind: str = "fibre-prior"):
    """Load a model file and check that ``plugin_name`` draws it (a ``kind`` model) and it has 1 or 3 channels."""
    from kesbrdf.io.model_file import load_model as load

    model = load(Path(path))
    plugin, _ = model.render_plugin()
    if plugin != plugin_name:
        raise ModelError(f"{where(path)}the {plugin_name} BSDF reads models of kind {kind!r}, got {model.kind!r} "
                         f"(drawn by the {plugin!r} plugin)")
    if model.n_channels not in (1, 3):
        raise ModelError(f"{where(path)}expected 1 (grey) or 3 (RGB) channels, got {model.n_channels}")
    return model


def lobe_table(model):
    """Sampling density nodes of a fibre-prior model: (q̄ (n_phi, n_h), φ_h grid, γ = 2θ_h grid).

    q̄ is the channel mean of max(0, f_r − k_d)·√(cos θ_i cos θ_r) (the ``kes-halfdiff``
    table's normalisation) at the half vector (φ_h, θ_h), averaged over the difference
    directions :data:`LOBE_THETA_D_DEG` × :data:`LOBE_PHI_D_DEG` (pairs below the horizon
    count 0), evaluated with the numpy model.
    """
    phi = np.radians(np.arange(0.0, 360.0, LOBE_DPHI_DEG))
    th = np.radians(np.arange(0.0, LOBE_THETA_H_MAX_DEG + 1e-9, LOBE_DTHETA_DEG))
    td, pd = (np.radians(a).ravel() for a in np.meshgrid(LOBE_THETA_D_DEG, LOBE_PHI_D_DEG, indexing="ij"))
    # d in the half-vector frame (K, 3), rotated by θ_h about y, then by φ_h about z (Rusinkiewicz)
    dx, dy, dz = np.sin(td) * np.cos(pd), np.sin(td) * np.sin(pd), np.cos(td)
    ct, st = np.cos(th)[None, :, None], np.sin(th)[None, :, None]
    cp, sp = np.cos(phi)[:, None, None], np.sin(phi)[:, None, None]
    x = dx * ct + dz * st
    z = -dx * st + dz * ct + 0.0 * cp
    y = dy + 0.0 * x
    wi = np.stack([x * cp - y * sp, x * sp + y * cp, z], -1)  # (n_phi, n_h, K, 3)
    h = np.stack([st * cp, st * sp, ct + 0.0 * cp], -1)
    wr = 2.0 * np.sum(wi * h, -1, keepdims=True) * h - wi
    f = model.evaluate(wi, wr)
    kd = np.exp([model.prior.parameters()[f"log_kd_{c}"] for c in range(model.prior.spec.n_channels)])
    cos = np.sqrt(np.clip(wi[..., 2] * wr[..., 2], 0.0, None))
    lobe = np.clip(np.nan_to_num(f - kd), 0.0, None).mean(axis=-1) * cos
    return lobe.mean(axis=-1), phi, 2.0 * th


# -- the prior in Dr.Jit ---------------------------------------------------------------
def _sigmoid(x):
    return 0.5 * (1.0 + dr.tanh(0.5 * x))


def _seeliger(ci, cr):
    ok = (ci > 0.0) & (cr > 0.0)
    return dr.select(ok, ci * cr / dr.select(ok, ci + cr, 1.0), 0.0)


def _lobe_rho(cos_phi, rho):
    """N(φ; ρ) = (1 − ρ)² / (1 − 2ρ cos φ + ρ²) + 10⁻⁴ (:mod:`kesbrdf.models.fibre_physics`);
    ``rho`` a :class:`_LobeRho` of opaque constants."""
    return rho.num / (rho.den - rho.two_rho * cos_phi) + 1e-4


class _LobeRho:
    """The constants of N(φ; ρ), computed in float64 as the literals were, kept opaque."""

    def __init__(self, rho: float):
        self.num = opaque_float((1.0 - rho) ** 2)
        self.den = opaque_float(1.0 + rho * rho)
        self.two_rho = opaque_float(2.0 * rho)


def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _cos_phi(wi, wr, t):
    """cos of the angle between the projections of ω_i and ω_r on the plane ⟂ t (tuples)."""
    di, dq = _dot(wi, t), _dot(wr, t)
    pi = [wi[k] - di * t[k] for k in range(3)]
    pr = [wr[k] - dq * t[k] for k in range(3)]
    den = dr.sqrt(_dot(pi, pi) * _dot(pr, pr))
    return dr.clip(dr.select(den > 1e-30, _dot(pi, pr) / dr.maximum(den, 1e-30), 1.0), -1.0, 1.0)


def family_frame(w, alpha):
    """w in the frame of a family at angle α: (x' across, y' along, z) as kesbrdf.models.fibre_physics's family frame.

    ``alpha`` is an angle (a constant of the code) or a ``(sin α, cos α)`` pair (a
    fabric's axis, opaque so that the kernel does not depend on it)."""
    s, c = (math.sin(alpha), math.cos(alpha)) if isinstance(alpha, (int, float)) else alpha
    return (s * w.x - c * w.y, c * w.x + s * w.y, w.z)


#: Staple tilt nodes are evaluated in blocks of this many: the kernel depends on which
#: blocks carry weight, not on the weights, so fabrics with similar tilt ranges share it.
NODE_BLOCK = 4


def _block_has_weight(w, k: int) -> bool:
    """Whether node ``k``'s block of :data:`NODE_BLOCK` staple nodes has any non-zero weight."""
    start = k - k % NODE_BLOCK
    return bool(np.any(np.asarray(w[start:start + NODE_BLOCK]) != 0.0))


class PriorDrJit:
    """f_prior of a :class:`kesbrdf.models.fibre_physics.FibrePrior` in Dr.Jit (module docstring).

    The fabric's numbers (k_d, k_s, the tilt profile, ρ, the twist ψ, the axis offset, the
    θ_d law) are opaque kernel parameters (:mod:`kesbrdf.render.jit`): the traced kernel
    depends only on the prior's structure (filament/staple per family, free θ_d law,
    which blocks of staple nodes carry weight), so the next fabric of a batch, or a
    colourway, launches the kernel already compiled.
    """

    def __init__(self, prior):
        from kesbrdf.models import fibre_physics as P

        self.P = P
        spec = prior.spec
        p = prior.parameters()
        C = spec.n_channels
        self.kd = as_rgb(np.exp([p[f"log_kd_{c}"] for c in range(C)]))
        self.kd_c = opaque_rgb(self.kd)
        self.offset = p["axis_offset"] if spec.free_axes else 0.0
        self.d = (opaque_float(p["d1"]), opaque_float(p["d2"])) if spec.free_theta_d else None
        held = spec.theta_d_range if spec.free_theta_d else None
        self.held = None if held is None else tuple(opaque_float(v) for v in held)
        self.f45 = float(fresnel_dielectric(math.cos(math.pi / 4), P.THETA_D_ETA))
        self.families = []
        for fam, kind, alpha in zip(("warp", "weft"), spec.kinds, (0.0, math.pi / 2)):
            lo, hi, log_s, c2, rho = (p[f"{fam}_{k}"] for k in ("u_lo", "u_hi", "log_s", "c2", "rho"))
            ks = as_rgb(np.exp([p[f"{fam}_log_ks_{c}"] for c in range(C)]))
            a = alpha + self.offset
            entry = {"kind": kind, "alpha": (opaque_float(math.sin(a)), opaque_float(math.cos(a))),
                     "ks": opaque_rgb(ks), "rho": _LobeRho(rho),
                     "shape": tuple(opaque_float(v) for v in (lo, hi, 1.0 / math.exp(log_s), c2))}
            if kind == "staple":
                psi = p[f"{fam}_psi"]
                # P(u)·Δu at the fixed nodes: constants of the fitted model, in float64
                w = P.tilt_profile(P.U_NODES, lo, hi, log_s, c2) * P.DU
                entry.update(psi=tuple(opaque_float(v) for v in (math.tan(psi), math.sin(psi), math.cos(psi),
                                                                   1.0 / max(abs(math.sin(psi)), 1e-6))),
                             nodes=[(math.sin(u), math.cos(u), opaque_float(wu))
                                    for k, (u, wu) in enumerate(zip(P.U_NODES, w)) if _block_has_weight(w, k)])
            self.families.append(entry)

    def _profile(self, u, shape):
        lo, hi, inv_s, c2 = shape
        return _sigmoid((u - lo) * inv_s) * _sigmoid((hi - u) * inv_s) * dr.exp(dr.clip(c2 * u * u, -700.0, 50.0))

    def _filament(self, fam, h, i, r, norm_sum):
        hx, hy, hz = h
        u = dr.atan2(hy, hz)
        su, cu = dr.sin(u), dr.cos(u)
        a_bar = 0.0
        for v in self.P.V_NODES:
            sv, cv = math.sin(v), math.cos(v)
            ci = i[0] * sv + (i[1] * su + i[2] * cu) * cv
            cr = r[0] * sv + (r[1] * su + r[2] * cu) * cv
            a_bar = a_bar + _seeliger(ci, cr)
        a_bar = a_bar * (1.0 / self.P.N_V)
        cphi = _cos_phi(i, r, (0.0, cu, -su))
        jac = dr.sqrt(dr.maximum(1.0 - hx * hx, 1e-12))
        return self._profile(u, fam["shape"]) * _lobe_rho(cphi, fam["rho"]) * a_bar / (norm_sum * jac)

    def _staple(self, fam, h, i, r, norm_sum):
        hx, hy, hz = h
        tpsi, sp, cp, inv_abs_sp = fam["psi"]
        total = 0.0
        for su, cu, weight in fam["nodes"]:
            A = hy * su + hz * cu
            Bq = hy * cu - hz * su
            D = Bq / (dr.sqrt(hx * hx + A * A) * tpsi)
            v = dr.atan2(-A, hx) + dr.acos(dr.clip(D, -1.0, 1.0))
            v = dr.select(v > math.pi, v - 2.0 * math.pi, v)  # wrapped as kesbrdf.models.fibre_physics does
            ok = (dr.abs(D) < 1.0) & (dr.abs(v) < 0.5 * math.pi)
            sv, cv = dr.sin(v), dr.cos(v)
            n = (sv, su * cv, cu * cv)
            t = (-cv * sp, cu * cp + su * sv * sp, -su * cp + cu * sv * sp)
            nh = dr.abs(_dot(n, h))
            g = dr.select(ok, _seeliger(_dot(n, i), _dot(n, r)) / dr.maximum(nh, 1e-9), 0.0)
            total = total + weight * _lobe_rho(_cos_phi(i, r, t), fam["rho"]) * g
        return total * inv_abs_sp / norm_sum

    def parts(self, wi, wr):
        """[warp part, weft part] (Color3f each): Φ(θ_d) k_s,j S_j, so that f_prior = k_d + Σ parts
        (as :func:`kesbrdf.models.fibre_coord.family_parts`)."""
        s = wi + wr
        norm_sum = dr.norm(s)
        h = s / dr.maximum(norm_sum, 1e-30)
        phi_td = fresnel_dielectric(dr.dot(wi, h), self.P.THETA_D_ETA, dr) * (1.0 / self.f45)
        if self.d is not None:
            x = dr.dot(wi, wr)
            if self.held is not None:  # the law held outside the fitted range (PriorSpec.theta_d_range)
                x = dr.clip(x, self.held[0], self.held[1])
            phi_td = phi_td * dr.exp(dr.clip(self.d[0] * x + self.d[1] * x * x, -50.0, 50.0))
        out = []
        for fam in self.families:
            hf, i, r = family_frame(h, fam["alpha"]), family_frame(wi, fam["alpha"]), family_frame(wr, fam["alpha"])
            S = (self._filament if fam["kind"] == "filament" else self._staple)(fam, hf, i, r, norm_sum)
            out.append(fam["ks"] * (phi_td * S))
        return out

    def __call__(self, wi, wr):
        """f_prior (Color3f) for unit directions above the horizon."""
        f = mi.Color3f(self.kd_c)
        for part in self.parts(wi, wr):
            f = f + part
        return f


class _Residual:
    """r^τ of a fibre-prior model's residual in Dr.Jit (module docstring)."""

    def __init__(self, res):
        from kesbrdf.models.fibre_prior import RELAX_DEG

        self.relax = 1.0 / math.radians(RELAX_DEG)
        table = np.clip(np.nan_to_num(as_rgb(res.table)), 0.0, None)
        self.mode = getattr(res, "mode", "line")
        if self.mode == "halfdiff":
            self.table = HalfDiffTable(table, res.theta_h_grid, res.theta_d_grid)
            self.limit = opaque_float(res.theta_h_max)
        else:
            self.table = KesTable(table, res.gamma_grid)
            self.limit = opaque_float(res.gamma_max)
            self.cos_line = opaque_float(math.cos(float(res.line_sum)))

    def __call__(self, wi, wr):
        if self.mode == "halfdiff":
            phi, theta_h, theta_d = half_diff(wi, wr)
            r = self.table(phi, theta_h, theta_d)
            beyond = theta_h
        else:
            phi, gamma = phi_gamma(wi, wr, "deviation")
            g_in = dr.minimum(gamma, self.limit)
            weight = dr.sqrt(dr.maximum(0.5 * (dr.cos(g_in) + self.cos_line), 0.0))
            r = self.table(phi, g_in) / weight
            beyond = gamma
        x = dr.clip((beyond - self.limit) * self.relax, 0.0, 1.0)
        tau = 1.0 - x * x * (3.0 - 2.0 * x)
        return dr.exp(tau * dr.log(dr.maximum(r, 1e-30)))


class _EnergyScale:
    """g(ω) of :func:`kesbrdf.models.fibre_prior.energy_scale` in Dr.Jit: bilinear over uniform
    cos θ nodes and φ nodes on the half circle (periodic)."""

    def __init__(self, energy):
        scale = as_rgb(np.asarray(energy.scale, float))  # (n_mu, n_phi, 3)
        self.n_mu, self.n_phi = scale.shape[:2]
        self.table = [mi.Float(np.ascontiguousarray(scale[..., c]).ravel()) for c in range(3)]

    def __call__(self, w):
        mu = dr.clip(w.z, 0.0, 1.0) * (self.n_mu - 1)
        i0 = dr.minimum(mi.UInt32(dr.floor(mu)), self.n_mu - 2)
        tm = mu - mi.Float(i0)
        ph = dr.atan2(w.y, w.x)
        ph = dr.select(ph < 0.0, ph + math.pi, ph)
        ph = dr.select(ph >= math.pi, ph - math.pi, ph) * (self.n_phi / math.pi)
        j0f = dr.floor(ph)
        tp = ph - j0f
        j0 = mi.UInt32(j0f) % self.n_phi
        j1 = (j0 + 1) % self.n_phi
        out = []
        for t in self.table:
            g = lambda i, j: dr.gather(mi.Float, t, i * self.n_phi + j)  # noqa: E731
            lo = g(i0, j0) * (1.0 - tp) + g(i0, j1) * tp
            hi = g(i0 + 1, j0) * (1.0 - tp) + g(i0 + 1, j1) * tp
            out.append(lo * (1.0 - tm) + hi * tm)
        return mi.Color3f(*out)


class FibrePriorBSDF(FabricBSDF):
    """Mitsuba BSDF of a ``fibre-prior`` model (module docstring).

    Subclasses for kinds that share the residual and energy scale and differ in the
    prior set :attr:`PLUGIN`, :attr:`KIND` and :meth:`make_prior`
    (:mod:`kesbrdf.render.fibre_coord_bsdf`).
    """

    PLUGIN = PLUGIN
    KIND = "fibre-prior"

    @staticmethod
    def make_prior(prior):
        """The Dr.Jit f_prior of the model's prior: callable (wi, wr) -> Color3f with ``kd`` (RGB k_d)."""
        return PriorDrJit(prior)

    def __init__(self, props):
        mi.BSDF.__init__(self, props)
        PLUGIN = self.PLUGIN
        filename = _prop(props, "filename")
        if filename is None:
            raise ModelError(f"{PLUGIN} BSDF: expected a 'filename' parameter (a model file), got none")
        path = Path(str(filename))
        if not path.is_absolute() and not path.exists():
            path = Path(str(mi.file_resolver().resolve(str(filename))))
        model = check_prior_model(path, PLUGIN, self.KIND)
        self.filename = str(path)
        self.two_sided = bool(_prop(props, "two_sided", False))
        extrapolation = str(_prop(props, "extrapolation", "hold"))
        if extrapolation not in EXTRAPOLATIONS:
            raise ModelError(f"{PLUGIN} BSDF: unknown extrapolation {extrapolation!r}; expected one of {', '.join(EXTRAPOLATIONS)}")
        sampling = str(_prop(props, "sampling", "lobe"))
        if sampling not in SAMPLINGS:
            raise ModelError(f"{PLUGIN} BSDF sampling: expected one of {', '.join(SAMPLINGS)}, got {sampling!r}")
        self.sampling = sampling

        self.prior = self.make_prior(model.prior)
        self.residual = None if model.residual is None else _Residual(model.residual)
        self.energy = None if getattr(model, "energy", None) is None else _EnergyScale(model.energy)
        kd = self.prior.kd
        tint = parse_rgb(_prop(props, "lobe_tint", "1,1,1"), "lobe_tint")
        base = _prop(props, "base_color")
        body = kd
        if base is not None:
            albedo = parse_rgb(base, "base_color")
            if np.any(albedo > 1):
                raise ModelError(f"base_color: expected a body albedo with R,G,B in [0, 1], got {base!r}")
            body = albedo / math.pi
        self.recolour = base is not None or not np.all(tint == 1.0)
        # opaque: a colourway sheet (one body colour a tile) compiles its scene once (render.jit)
        self.kd, self.body, self.tint = opaque_rgb(kd), opaque_rgb(body), opaque_rgb(tint)

        q_mean, phi_grid, gamma_grid = lobe_table(model)
        q_mean = q_mean * float(np.mean(tint))
        self.sampler = self._table_sampler(q_mean, phi_grid, gamma_grid, body, sampling)
        self._set_flags()

    def f_model(self, wi, wr):
        """The model's f_r = g(ω_i) g(ω_r) f_prior · r^τ (Color3f) for unit directions above the horizon."""
        f = self.prior(wi, wr)
        if self.residual is not None:
            f = f * self.residual(wi, wr)
        if self.energy is not None:
            f = f * self.energy(wi) * self.energy(wr)
        return f

    def f_r(self, wi, wr, active=True):
        """f_r (1/sr, no cosine) for light ω_i and viewer ω_r in the fabric frame."""
        above = (wi.z > 0.0) & (wr.z > 0.0) & active
        f = self.f_model(wi, wr)
        if self.recolour:
            f = dr.maximum(self.body + self.tint * (f - self.kd), 0.0)
        ok = above & dr.isfinite(f.x) & dr.isfinite(f.y) & dr.isfinite(f.z)
        return dr.select(ok, f, 0.0)

    def to_string(self):
        return (f"{type(self).__name__}[filename={self.filename!r}, two_sided={self.two_sided}, "
                f"sampling={self.sampling!r}, lobe_weight={self.sampler.lobe_weight:.3f}]")


def register() -> None:
    """Register the plugin under the name ``kesbrdf_prior`` (idempotent)."""
    mi.register_bsdf(PLUGIN, lambda props: FibrePriorBSDF(props))
