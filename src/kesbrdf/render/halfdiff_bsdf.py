r"""The ``kesbrdf_halfdiff`` BSDF: a ``kes-halfdiff`` model file as a Mitsuba 3 plugin.

Evaluation is :func:`kesbrdf.models.halfdiff.evaluate_halfdiff` in Dr.Jit (single precision):

.. math::

    f_r(\omega_i, \omega_r) = c + \frac{T(\phi_h, \theta_h, \theta_d)}{w(\theta_i, \theta_r)}

(w the model's foreshortening weight, :func:`kesbrdf.render.bsdf.foreshortening`;
no division for models with ``normalisation="none"``), with h = ω_i + ω_r, φ_h its
azimuth (the plane of incidence ω_r − ω_i where h ∥ z), θ_h = angle(h, z),
θ_d = half the angle between ω_i and ω_r, and T read by trilinear lookup (φ periodic
through a repeated first φ slice, θ_h and θ_d clamped to their grids), from a
``mi.Texture3f``.

Frames and colour as :mod:`kesbrdf.render.bsdf`: local x = UV-u tangent = warp;
``si.wi`` is the viewer ω_r, ``wo`` the light ω_i; ``base_color`` replaces the body by
base_color/π, ``lobe_tint`` multiplies T.

``extrapolation``: default the model's own ``parameters["extrapolation"]``, as
:func:`~kesbrdf.models.halfdiff.evaluate_halfdiff` (``fade`` for new fits, ``hold`` before).
``hold`` keeps the table at the last measured θ_h; ``fade`` scales the lobe by
max(0, 1 − (θ_h − θ_h,max)/(Δ/2)), Δ = :data:`kesbrdf.render.bsdf.FADE_DEG` (the same
fade as the ``kesbrdf`` plugin's, in γ = 2θ_h).

Sampling: the mixture of :mod:`kesbrdf.render.sampling` with the ``halfvector``
lobe, whose (φ_h, γ = 2θ_h) density is the table averaged over θ_d.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

import drjit as dr
import mitsuba as mi

from kesbrdf.errors import ModelError, where
from kesbrdf.render.bsdf import (AZIMUTH_EPS, EXTRAPOLATIONS, FADE_DEG, FabricBSDF, body_law_of, body_shape, foreshortening,
                                 parse_rgb)
from kesbrdf.render.jit import opaque_rgb

__all__ = ["HalfDiffBSDF", "HalfDiffTable", "half_diff", "register", "check_halfdiff_model"]


def _prop(props, name, default=None):
    return props[name] if name in props else default


def check_halfdiff_model(path):
    """Load a model file and check that it is a ``kes-halfdiff`` model with 1 or 3 channels."""
    from kesbrdf.io.model_file import load_model as load

    model = load(Path(path))
    plugin, _ = model.render_plugin()
    if plugin != "kesbrdf_halfdiff":
        raise ModelError(f"{where(path)}the kesbrdf_halfdiff BSDF reads models of kind 'kes-halfdiff', got "
                         f"{model.kind!r} (drawn by the {plugin!r} plugin)")
    if model.table.shape[-1] not in (1, 3):
        raise ModelError(f"{where(path)}expected 1 (grey) or 3 (RGB) channels, got {model.table.shape[-1]}")
    return model


def half_diff(wi, wr):
    """(φ_h, θ_h, θ_d) of light ω_i and viewer ω_r in Dr.Jit, as
    :func:`kesbrdf.models.mappings.to_half_diff`: h = ω_i + ω_r, φ_h its azimuth (the plane of
    incidence ω_r − ω_i where h ∥ z), θ_h = angle(h, z), θ_d = half the angle ω_i, ω_r."""
    h = wi + wr
    plane = wr - wi
    hxy = dr.norm(mi.Vector2f(h.x, h.y))
    small = hxy < AZIMUTH_EPS
    phi = dr.atan2(dr.select(small, plane.y, h.y), dr.select(small, plane.x, h.x))
    phi = dr.select(phi < 0.0, phi + 2.0 * math.pi, phi)
    theta_h = dr.atan2(hxy, h.z)
    theta_d = 0.5 * dr.atan2(dr.norm(dr.cross(wi, wr)), dr.dot(wi, wr))
    return phi, theta_h, theta_d


class HalfDiffTable:
    """A table T(φ_h, θ_h, θ_d), shape (n_phi, n_h, n_d, 3), read trilinearly in Dr.Jit.

    φ periodic through a repeated first φ slice of a ``mi.Texture3f``; θ_h and θ_d
    clamped to their uniform grids: :func:`kesbrdf.models.halfdiff.lookup_halfdiff` in single
    precision.  Used by the ``kesbrdf_halfdiff`` plugin for the lobe and by the
    ``kesbrdf_prior`` plugin for a dense fit's residual.
    """

    def __init__(self, table, theta_h_grid, theta_d_grid):
        table = np.asarray(table, float)
        self.n_phi, self.n_h, self.n_d = table.shape[:3]
        self.h_max = float(theta_h_grid[-1])
        self.d_max = float(theta_d_grid[-1])
        self.dh = float(theta_h_grid[1] - theta_h_grid[0])
        self.dd = float(theta_d_grid[1] - theta_d_grid[0])
        padded = np.concatenate([table, table[:1]], axis=0).astype(np.float32)
        self.texture = mi.Texture3f(
            mi.TensorXf(padded), use_accel=False, filter_mode=dr.FilterMode.Linear, wrap_mode=dr.WrapMode.Clamp
        )

    def __call__(self, phi, theta_h, theta_d):
        """T(φ_h, θ_h, θ_d) → Color3f."""
        u = dr.clip(phi * (self.n_phi / (2.0 * math.pi)), 0.0, float(self.n_phi))
        v = dr.clip(dr.clip(theta_h, 0.0, self.h_max) * (1.0 / self.dh), 0.0, float(self.n_h - 1))
        w = dr.clip(dr.clip(theta_d, 0.0, self.d_max) * (1.0 / self.dd), 0.0, float(self.n_d - 1))
        pos = mi.Point3f((w + 0.5) / self.n_d, (v + 0.5) / self.n_h, (u + 0.5) / (self.n_phi + 1))
        r, g, b = self.texture.eval(pos)
        return mi.Color3f(r, g, b)


class HalfDiffBSDF(FabricBSDF):
    """Mitsuba BSDF of a ``kes-halfdiff`` model (module docstring)."""

    def __init__(self, props):
        mi.BSDF.__init__(self, props)
        filename = _prop(props, "filename")
        if filename is None:
            raise ModelError("kesbrdf_halfdiff BSDF: expected a 'filename' parameter (a model file), got none")
        model = check_halfdiff_model(str(filename))
        self.filename = str(filename)
        table = model.table if model.table.shape[-1] == 3 else np.repeat(model.table, 3, axis=-1)
        body = model.body if model.body.size == 3 else np.repeat(model.body, 3)
        tint = parse_rgb(_prop(props, "lobe_tint", "1,1,1"), "lobe_tint")
        base = _prop(props, "base_color")
        if base is not None:
            albedo = parse_rgb(base, "base_color")
            if np.any(albedo > 1):
                raise ModelError(f"base_color: expected a body albedo with R,G,B in [0, 1], got {base!r}")
            body = albedo / math.pi
        table = np.clip(np.nan_to_num(table * tint), 0.0, None)
        self.normalisation = str(model.parameters.get("normalisation", "sqrtcos"))
        self.two_sided = bool(_prop(props, "two_sided", False))
        self.extrapolation = str(_prop(props, "extrapolation", model.parameters.get("extrapolation", "hold")))
        if self.extrapolation not in EXTRAPOLATIONS:
            raise ModelError(
                f"kesbrdf_halfdiff BSDF: unknown extrapolation {self.extrapolation!r}; "
                f"expected one of {', '.join(EXTRAPOLATIONS)}"
            )
        self.table = HalfDiffTable(table, model.theta_h_grid, model.theta_d_grid)
        self.h_max = self.table.h_max
        self.body = opaque_rgb(body)  # one compiled kernel for every body colour (render.jit)
        self.body_law = body_law_of(model)  # eq. (B3) of kesbrdf.models.body; a base colour keeps it

        sampling = str(_prop(props, "sampling", "lobe"))
        q_mean = table.mean(axis=(2, 3))  # (φ_h, θ_h)
        gamma_grid = 2.0 * np.asarray(model.theta_h_grid, float)
        self.sampling = sampling
        self.sampler = self._table_sampler(q_mean, model.phi_grid, gamma_grid, body, sampling)
        self._set_flags()

    def f_r(self, wi, wr, active=True):
        """f_r (1/sr) for light ω_i and viewer ω_r in the fabric frame."""
        above = (wi.z > 0.0) & (wr.z > 0.0) & active
        phi, theta_h, theta_d = half_diff(wi, wr)
        q = self.table(phi, theta_h, theta_d)
        if self.extrapolation == "fade":
            q = q * dr.clip(1.0 - (theta_h - self.h_max) * (2.0 / math.radians(FADE_DEG)), 0.0, 1.0)
        if self.normalisation != "none":
            q = q / foreshortening(wi.z, wr.z, self.normalisation)
        return dr.select(above, self.body * body_shape(self.body_law, wi.z, wr.z) + q, 0.0)

    def to_string(self):
        return f"HalfDiffBSDF[filename={self.filename!r}, two_sided={self.two_sided}, sampling={self.sampling!r}]"


def register() -> None:
    """Register the plugin under the name ``kesbrdf_halfdiff`` (idempotent)."""
    mi.register_bsdf("kesbrdf_halfdiff", lambda props: HalfDiffBSDF(props))
