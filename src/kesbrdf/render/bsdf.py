r"""The ``kesbrdf`` BSDF: an extended-KES model file as a Mitsuba 3 plugin.

Evaluation follows ``docs/formats.md`` ("How to evaluate a model") exactly, in
Dr.Jit (single precision), so it agrees with :func:`kesbrdf.models.brdf.evaluate`:

.. math::

    f_r(\omega_i, \omega_r) = c + t\,\frac{q(\phi, \gamma)}{w(\theta_i, \theta_r)}

with w the model's foreshortening weight (:func:`foreshortening`, the Dr.Jit twin of
:func:`kesbrdf.models.mappings.foreshortening`: √(cos θ_i cos θ_r), bounded toward grazing
angles for models with ``normalisation="bounded"``), (φ, γ) from the ``deviation`` or ``halfvector`` mapping (docs/method.md, "From the table to a BRDF"), q read by
bilinear lookup (φ periodic, γ clamped to the measured range; a ``mi.Texture2f``
whose first φ row is repeated after the last, so clamping equals periodic
wrapping), c the body term and t the lobe tint.

Frames (docs/architecture.md, "Tools it runs on").  Mitsuba's local shading frame is (s, t, n) with s the
normalised UV-u tangent ∂p/∂u, so **u runs along the warp (fabric x) and v along the
weft**.  Mitsuba's ``si.wi`` points to the camera, i.e. it is the model's ω_r, and
``wo`` points to the light, the model's ω_i.

Colour (docs/method.md, "Colour").  ``base_color`` is the Lambertian albedo of the dyed body:
c = base_color/π replaces the measured body term; unset, the measured body is used.
``lobe_tint`` multiplies the measured lobe q (default 1: the measured sheen, which
for a dyed satin stays nearly neutral).  Gloss and anisotropy live in q alone, so
a colourway changes c and keeps the highlight.

Parameters (scene description)
------------------------------
filename : str
    A model file (``*.kes.json``, kind ``kes``).
mapping : str
    ``halfvector`` or ``deviation``; default: the one the model records (its
    ``default_mapping``: ``halfvector`` for new fits, ``deviation`` for files that record
    none).  ``paper`` is rejected: eq. 3–4 taken
    literally is singular (sin β → 0, grazing angles), not reciprocal, and has no
    lobe around the mirror direction to sample; use it through :mod:`kesbrdf.models.brdf`.
base_color : "r,g,b" or list of 3 floats, optional
    Body albedo in [0, 1].
lobe_tint : "r,g,b" or list of 3 floats, optional
    Tint of the lobe (default 1,1,1).
two_sided : bool
    Default ``False``.  When true, a hit from the back side is shaded as the front
    (the fabric frame mirrored through its plane: same warp and weft).
sampling : str
    ``lobe`` (default, the mixture of :mod:`kesbrdf.render.sampling`) or ``cosine``
    (cosine-weighted only; a baseline for the benchmark).
extrapolation : str
    What the lobe does beyond the last measured deviation γ_max (84° in the paper's
    protocol); default: the model's own ``parameters["extrapolation"]``, as
    :func:`kesbrdf.models.brdf.evaluate` and ``docs/formats.md`` (``fade`` for new fits, ``hold``
    for files written before).  ``hold`` keeps the last column; ``fade`` scales it by
    max(0, 1 − (γ − γ_max)/Δ) with Δ = :data:`FADE_DEG` (one deviation step of the
    paper's protocol), so pairs the measurement never came near get the body only.
    Holding the column puts the in-plane grazing value (θ_i = 3°, θ_r = 87°) on every
    retro-reflection pair; on the virtual black satin it doubles the render error
    against the reference (docs/rendering.md, "Satin findings").

Models with one channel are used grey; three channels are taken as RGB.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

import drjit as dr
import mitsuba as mi

from kesbrdf.errors import ModelError, validate_choice, where
from kesbrdf.models.mappings import BOUNDED_LAMBDA, FADE_DEG  # noqa: F401  (FADE_DEG re-exported)
from kesbrdf.render import sampling as _sampling
from kesbrdf.render.jit import opaque_float, opaque_rgb

__all__ = ["FabricBSDF", "KesBSDF", "KesTable", "phi_gamma", "foreshortening", "register", "MAPPINGS", "SAMPLINGS", "parse_rgb", "model_rgb", "check_model"]

MAPPINGS = ("deviation", "halfvector")
SAMPLINGS = ("lobe", "cosine")
EXTRAPOLATIONS = ("hold", "fade")
#: Projected length below which the azimuth falls back to the plane of incidence
#: (float32 counterpart of kesbrdf.models.brdf.AZIMUTH_EPS).
AZIMUTH_EPS = 1e-7


def parse_rgb(value, name: str = "colour") -> np.ndarray:
    """Three floats from ``"r,g,b"``, a sequence, or a Mitsuba colour/vector."""
    if isinstance(value, str):
        parts = [p for p in value.replace(";", ",").split(",") if p.strip()]
    else:
        try:
            parts = list(value)
        except TypeError:
            parts = [value]
    try:
        rgb = np.array([float(p) for p in parts], float)
    except (TypeError, ValueError):
        raise ModelError(f"{name}: expected three numbers R,G,B, got {value!r}") from None
    if rgb.size == 1:
        rgb = np.repeat(rgb, 3)
    if rgb.size != 3 or not np.all(np.isfinite(rgb)) or np.any(rgb < 0):
        raise ModelError(f"{name}: expected three non-negative numbers R,G,B, got {value!r}")
    return rgb


def model_rgb(model, source=None):
    """(table (n_phi, n_gamma, 3), body (3,)) of a model's (φ, γ) table as RGB
    (``model.table_view()``: the ``kes`` table, or any kind's tabulated view)."""
    model = model.table_view()
    c = model.table.shape[-1]
    if c == 1:
        return np.repeat(model.table, 3, axis=-1), np.repeat(model.body, 3)
    if c == 3:
        return model.table, model.body
    raise ModelError(
        f"{where(source)}the renderer needs a model with 1 (grey) or 3 (RGB) channels, "
        f"got {c} ({', '.join(model.channels)})"
    )


def body_law_of(model):
    """(a, p) of a model's body law (eq. B3 of :mod:`kesbrdf.models.body`), or None: Lambertian."""
    law = getattr(model, "body_law", None)
    return None if law is None else (float(law.a), float(law.p))


def body_shape(law, cos_i, cos_r):
    """g(cos θ_i) g(cos θ_r) in Dr.Jit, g(μ) = 1 − a (1 − μ)^p for ``law`` = (a, p); 1 for None."""
    if law is None:
        return 1.0
    a, p = law
    g = lambda mu: 1.0 - a * dr.power(dr.clip(1.0 - mu, 0.0, 1.0), p)  # noqa: E731
    return g(cos_i) * g(cos_r)


def check_model(path, mapping: str | None = None):
    """Load and check a model for the renderer before Mitsuba sees it.

    Errors raised inside a plugin constructor reach Python as Mitsuba's RuntimeError
    with a traceback; checking first gives the CLI a one-line ModelError.  Every kind is
    accepted: ``model.render_plugin()`` says which plugin draws it and whether it takes
    ``mapping`` (the KES mapping of the ``kesbrdf`` table plugin; None: the model's own).
    """
    from kesbrdf.io.model_file import load_model as load

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(2, "No such file or directory", str(path))
    if mapping is not None and mapping not in MAPPINGS:
        raise ModelError(f"unknown mapping {mapping!r}; the renderer supports {', '.join(MAPPINGS)}")
    model = load(path)
    if model.n_channels not in (1, 3):
        raise ModelError(f"{where(path)}the renderer needs a model with 1 (grey) or 3 (RGB) channels, got {model.n_channels}")
    plugin, _ = model.render_plugin(mapping=mapping)
    if plugin == "kesbrdf":  # the table plugin: the (φ, γ) view must exist before Mitsuba asks
        model_rgb(model, path)
    return model


def phi_gamma(wi, wr, mapping: str = "deviation"):
    """(φ, γ) of light ω_i and viewer ω_r in Dr.Jit, as :func:`kesbrdf.models.mappings.to_phi_gamma`
    (formats.md step 1); φ ∈ [0, 2π), the plane of incidence ω_r − ω_i where the
    azimuth vector vanishes."""
    plane = wr - wi
    s = wi + wr
    if mapping == "deviation":
        m = mi.Vector3f(-wi.x, -wi.y, wi.z)
        gamma = dr.atan2(dr.norm(dr.cross(wr, m)), dr.dot(wr, m))
    else:
        gamma = 2.0 * dr.atan2(dr.norm(mi.Vector2f(s.x, s.y)), s.z)
    small = dr.norm(mi.Vector2f(s.x, s.y)) < AZIMUTH_EPS
    x = dr.select(small, plane.x, s.x)
    y = dr.select(small, plane.y, s.y)
    phi = dr.atan2(y, x)
    phi = dr.select(phi < 0.0, phi + 2.0 * math.pi, phi)
    return phi, gamma


def foreshortening(cos_i, cos_r, normalisation: str = "bounded"):
    """Foreshortening weight w of f_r = c + q/w in Dr.Jit, as
    :func:`kesbrdf.models.mappings.foreshortening` (``bounded`` or ``sqrtcos``); callers mask
    pairs below the horizon."""
    g = dr.sqrt(dr.maximum(cos_i * cos_r, 1e-20))
    if normalisation == "sqrtcos":
        return g
    return dr.maximum(g, BOUNDED_LAMBDA * dr.maximum(cos_i, cos_r))


class KesTable:
    """A KES table q(φ, γ), shape (n_phi, n_gamma, 3), read bilinearly in Dr.Jit.

    φ is periodic (a ``mi.Texture2f`` whose first φ row is repeated after the last, so
    clamping equals periodic wrapping), γ is clamped to the uniform grid [0, γ_max]:
    :func:`kesbrdf.models.kes.lookup` in single precision.  Used by the ``kesbrdf`` plugin
    for the lobe and by the ``kesbrdf_prior`` plugin for the residual.
    """

    def __init__(self, table, gamma_grid):
        table = np.asarray(table, float)
        self.n_phi, self.n_gamma = table.shape[:2]
        self.gamma_max = float(gamma_grid[-1])
        self.dgamma = float(gamma_grid[1] - gamma_grid[0])
        self._gamma_max, self._inv_dgamma = opaque_float(self.gamma_max), opaque_float(1.0 / self.dgamma)
        padded = np.concatenate([table, table[:1]], axis=0).astype(np.float32)
        self.texture = mi.Texture2f(
            mi.TensorXf(padded), use_accel=False, filter_mode=dr.FilterMode.Linear, wrap_mode=dr.WrapMode.Clamp
        )

    def __call__(self, phi, gamma):
        """q(φ, γ) → Color3f."""
        u = dr.clip(phi * (self.n_phi / (2.0 * math.pi)), 0.0, float(self.n_phi))
        v = dr.clip(gamma, 0.0, self._gamma_max) * self._inv_dgamma
        v = dr.clip(v, 0.0, float(self.n_gamma - 1))
        pos = mi.Point2f((v + 0.5) / self.n_gamma, (u + 0.5) / (self.n_phi + 1))
        r, g, b = self.texture.eval(pos)
        return mi.Color3f(r, g, b)


def _prop(props, name, default=None):
    return props[name] if name in props else default


class FabricBSDF(mi.BSDF):
    """What every kesbrdf Mitsuba BSDF shares: the fabric frame, two-sided mirroring,
    ``eval``/``pdf``/``sample`` around a subclass's ``f_r(wi, wr, active)`` and ``sampler``
    (:mod:`kesbrdf.render.sampling`).  Subclasses set ``two_sided``, ``sampler`` and ``f_r``.

    Mitsuba's ``si.wi`` points to the camera (the paper's ω_r) and ``wo`` to the light (ω_i).
    """

    def _set_flags(self):
        """Mitsuba's component flags: an anisotropic glossy lobe and a diffuse body, both
        sides when ``two_sided``.  Call after setting ``two_sided``."""
        flags_lobe = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide | mi.BSDFFlags.Anisotropic
        flags_body = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide
        if self.two_sided:
            flags_lobe = flags_lobe | mi.BSDFFlags.BackSide
            flags_body = flags_body | mi.BSDFFlags.BackSide
        self.m_components = [flags_lobe, flags_body]
        self.m_flags = flags_lobe | flags_body

    @staticmethod
    def _table_sampler(q_mean, phi_grid, gamma_grid, body, sampling, mapping="halfvector"):
        """The lobe/cosine mixture sampler of a tabulated lobe q_mean(φ, γ) over a body
        (1/sr): lobe weight from the lobe's albedo proxy against π·mean(body), 0 for
        ``sampling="cosine"`` (:mod:`kesbrdf.render.sampling`)."""
        if sampling == "cosine":
            weight = 0.0
        else:
            lobe = _sampling.lobe_albedo_proxy(q_mean, phi_grid, gamma_grid)
            weight = _sampling.lobe_weight(lobe, math.pi * float(np.mean(body)))
        return _sampling.LobeSampler(
            _sampling.lobe_density_table(q_mean, gamma_grid, mapping), float(gamma_grid[-1]), mapping, weight
        )

    def _orient(self, si, wo):
        """Fabric-frame (ω_r, ω_i) with the back side mirrored when two-sided."""
        wr = mi.Vector3f(si.wi)
        wi = mi.Vector3f(wo)
        if self.two_sided:
            back = wr.z < 0.0
            wr.z = dr.select(back, -wr.z, wr.z)
            wi.z = dr.select(back, -wi.z, wi.z)
        return wr, wi

    def eval(self, ctx, si, wo, active=True):
        wr, wi = self._orient(si, wo)
        f = self.f_r(wi, wr, active)
        return dr.select(active, f * dr.maximum(wi.z, 0.0), 0.0)

    def pdf(self, ctx, si, wo, active=True):
        wr, wi = self._orient(si, wo)
        ok = active & (wr.z > 0.0) & (wi.z > 0.0)
        return dr.select(ok, self.sampler.pdf(wr, wi), 0.0)

    def eval_pdf(self, ctx, si, wo, active=True):
        return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

    def sample(self, ctx, si, sample1, sample2, active=True):
        wr = mi.Vector3f(si.wi)
        back = wr.z < 0.0
        if self.two_sided:
            wr.z = dr.select(back, -wr.z, wr.z)
        wi, pdf, from_lobe = self.sampler.sample(wr, sample1, sample2)
        ok = active & (wr.z > 0.0) & (wi.z > 0.0) & (pdf > 0.0)
        f = self.f_r(wi, wr, ok) * wi.z
        weight = dr.select(ok, f / dr.maximum(pdf, 1e-30), 0.0)
        wo = mi.Vector3f(wi)
        if self.two_sided:
            wo.z = dr.select(back, -wo.z, wo.z)
        bs = dr.zeros(mi.BSDFSample3f)
        bs.wo = wo
        bs.pdf = dr.select(ok, pdf, 0.0)
        bs.eta = 1.0
        bs.sampled_type = dr.select(
            from_lobe, mi.UInt32(+mi.BSDFFlags.GlossyReflection), mi.UInt32(+mi.BSDFFlags.DiffuseReflection)
        )
        bs.sampled_component = dr.select(from_lobe, mi.UInt32(0), mi.UInt32(1))
        return bs, weight

    def traverse(self, callback):
        pass

    def parameters_changed(self, keys):
        pass


class KesBSDF(FabricBSDF):
    """Mitsuba BSDF evaluating and sampling a kesbrdf model (module docstring)."""

    def __init__(self, props):
        mi.BSDF.__init__(self, props)
        from kesbrdf.io.model_file import load_model as load

        filename = _prop(props, "filename")
        if filename is None:
            raise ModelError("kesbrdf BSDF: expected a 'filename' parameter (a model file), got none")
        path = Path(str(filename))
        if not path.is_absolute() and not path.exists():
            # relative to the scene file, as Mitsuba resolves its own filenames (mi.load_file)
            path = Path(str(mi.file_resolver().resolve(str(filename))))
        model = load(path).table_view()  # any kind: its (φ, γ) table or its tabulated view
        self.filename = str(path)
        # default: the mapping the table was fitted for (halfvector for new fits, deviation
        # for files that record none), as every other consumer reads it
        mapping = str(_prop(props, "mapping", model.default_mapping))
        if mapping == "paper":
            raise ModelError(
                f"kesbrdf BSDF mapping: expected one of {', '.join(MAPPINGS)}, got 'paper' ('paper' is "
                "singular and not reciprocal; render with deviation or halfvector, see docs/rendering.md)"
            )
        validate_choice("kesbrdf BSDF mapping", mapping, MAPPINGS, error=ModelError)
        self.mapping = mapping
        sampling = str(_prop(props, "sampling", "lobe"))
        validate_choice("kesbrdf BSDF sampling", sampling, SAMPLINGS, error=ModelError)
        self.two_sided = bool(_prop(props, "two_sided", False))
        # default: the model's own (fade for fits since the grazing-energy fix, hold before)
        extrapolation = str(_prop(props, "extrapolation", model.extrapolation))
        if extrapolation not in EXTRAPOLATIONS:
            raise ModelError(
                f"kesbrdf BSDF: unknown extrapolation {extrapolation!r}; expected one of {', '.join(EXTRAPOLATIONS)}"
            )
        self.extrapolation = extrapolation

        table, body = model_rgb(model, path)
        tint = parse_rgb(_prop(props, "lobe_tint", "1,1,1"), "lobe_tint")
        base = _prop(props, "base_color")
        if base is not None:
            albedo = parse_rgb(base, "base_color")
            if np.any(albedo > 1):
                raise ModelError(f"base_color: expected a body albedo with R,G,B in [0, 1], got {base!r}")
            body = albedo / math.pi
        self.base_color = None if base is None else parse_rgb(base, "base_color")
        self.lobe_tint = tint
        table = np.clip(np.nan_to_num(table * tint), 0.0, None)

        self.table = KesTable(table, model.gamma_grid)
        self.normalisation = model.normalisation
        # the body's shape, eq. (B3) of kesbrdf.models.body: c g(cos θ_i) g(cos θ_r),
        # g(μ) = 1 − a (1 − μ)^p; None: Lambertian.  A colourway's base colour keeps it.
        self.body_law = body_law_of(model)
        self.gamma_max = self.table.gamma_max
        self._gamma_max = opaque_float(self.gamma_max)
        self.body = opaque_rgb(body)

        self.sampling = sampling
        self.sampler = self._table_sampler(table.mean(axis=-1), model.phi_grid, model.gamma_grid, body, sampling, mapping)
        self._set_flags()

    # -- evaluation ------------------------------------------------------------
    def _phi_gamma(self, wi, wr):
        """(φ, γ) of light ω_i and viewer ω_r, formats.md step 1."""
        return phi_gamma(wi, wr, self.mapping)

    def lobe_q(self, phi, gamma):
        """Bilinear table lookup q(φ, γ) → Color3f (formats.md step 2)."""
        q = self.table(phi, gamma)
        if self.extrapolation == "fade":
            q = q * dr.clip(1.0 - (gamma - self._gamma_max) * (1.0 / math.radians(FADE_DEG)), 0.0, 1.0)
        return q

    def f_r(self, wi, wr, active=True):
        """f_r (1/sr, no cosine) for light ω_i and viewer ω_r in the fabric frame."""
        cos_i = wi.z
        cos_r = wr.z
        above = (cos_i > 0.0) & (cos_r > 0.0) & active
        phi, gamma = self._phi_gamma(wi, wr)
        q = self.lobe_q(phi, gamma)
        f = self.body * body_shape(self.body_law, cos_i, cos_r) + q / foreshortening(cos_i, cos_r, self.normalisation)
        return dr.select(above, f, 0.0)

    def to_string(self):
        return (
            f"KesBSDF[filename={self.filename!r}, mapping={self.mapping!r}, two_sided={self.two_sided}, "
            f"sampling={self.sampling!r}, lobe_weight={self.sampler.lobe_weight:.3f}]"
        )


def register() -> None:
    """Register the plugin under the name ``kesbrdf`` (idempotent)."""
    mi.register_bsdf("kesbrdf", lambda props: KesBSDF(props))
