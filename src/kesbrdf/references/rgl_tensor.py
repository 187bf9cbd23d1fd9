r"""RGL tensor files (``*.bsdf``, Dupuy & Jakob 2018) read and evaluated in numpy.

The same evaluation as Mitsuba 3's ``measured`` plugin, without Mitsuba: for a
parameterising direction ω_p (the plugin's ``si.wi``) and the other direction ω_o,

1. m = normalize(ω_p + ω_o); u(θ) = sqrt(2θ/π), u(φ) = (φ + π)/2π (for isotropic files
   φ_m is taken relative to φ_p);
2. s = VNDF⁻¹(u_m | φ_p, θ_p), the inverse of the visible-normal warp
   (:class:`kesbrdf.references.marginal2d.Marginal2D`, conditioned on (φ_p, θ_p));
3. value = T(s | φ_p, θ_p, λ) · D(u_m) / (4 σ(u_p)) if the file's ``jacobian`` flag is
   set, else T(s | …), with T the stored ``rgb`` or ``spectra`` table (bilinear in s,
   linear in φ_p, θ_p and λ), D the ``ndf`` and σ the ``sigma`` interpolants;
4. the value is f_r·cos θ_o (Dupuy & Jakob's cosine-weighted tables); this module
   divides the cosine out and returns f_r in 1/sr.

Files storing half or a quarter of the φ range (Mitsuba's "reduction" 2 or 4) are
folded as the plugin folds them.  Checked against Mitsuba's own ``eval`` on the RGL
felt (``tests/export/test_rgl_tensor.py``).

Which direction parameterises the table (``parameterised_by``) follows
:class:`kesbrdf.references.rgl.RGLMeasured`: ``"light"`` (default) puts ``wi`` (to the
light) in ω_p, the acquisition's convention; ``"viewer"`` puts ``wr`` there, as Mitsuba
does when rendering.  For a reciprocal BRDF the two agree.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from kesbrdf.errors import FormatError, where
from kesbrdf.io.tensor_file import read_tensor_file
from kesbrdf.references.base import ReferenceBRDF
from kesbrdf.references.marginal2d import Marginal2D

__all__ = ["RGLTensorBRDF", "REQUIRED_FIELDS"]

#: Fields every file must hold besides the table (``rgb``, or ``spectra`` + ``wavelengths``).
REQUIRED_FIELDS = ("theta_i", "phi_i", "ndf", "sigma", "vndf", "jacobian")


def _elevation(d):
    """θ of unit vectors, stable near the pole (Mitsuba's formulation)."""
    dist = np.sqrt(d[:, 0] ** 2 + d[:, 1] ** 2 + (d[:, 2] - 1.0) ** 2)
    return 2.0 * np.arcsin(np.clip(0.5 * dist, -1.0, 1.0))


def _theta2u(theta):
    return np.sqrt(np.maximum(theta, 0.0) * (2.0 / np.pi))


def _phi2u(phi):
    return (phi + np.pi) / (2.0 * np.pi)


def _mulsign_neg(a, b):
    return np.where(b >= 0, -a, a)


class RGLTensorBRDF(ReferenceBRDF):
    """A tensor-file BRDF as a callable f(wi, wr) -> (..., C) in 1/sr (module docstring).

    Parameters
    ----------
    path : str or Path
        An RGB or spectral tensor file (RGL database, or :mod:`kesbrdf.export.rgl_bsdf`).
    parameterised_by : {"light", "viewer"}
        Which direction goes into the table's incident axes.

    Attributes
    ----------
    channels : tuple of str
        ``("R", "G", "B")`` for RGB files; ``("560nm", ...)`` for spectral ones.
    wavelengths : ndarray or None
        nm, spectral files only.
    description : str
    isotropic : bool
    reduction : int
        1, 2 or 4 (φ range stored: 2π / reduction).
    """

    def __init__(self, path, parameterised_by: str = "light"):
        if parameterised_by not in ("light", "viewer"):
            raise FormatError(f"expected parameterised_by 'light' or 'viewer', got {parameterised_by!r}")
        self.path = Path(path)
        self.parameterised_by = parameterised_by
        f = read_tensor_file(self.path)
        table_name = "spectra" if "wavelengths" in f else "rgb"
        missing = [k for k in REQUIRED_FIELDS + (table_name,) if k not in f]
        if missing:
            raise FormatError(f"{where(self.path)}expected tensor-file fields {', '.join(REQUIRED_FIELDS)} "
                              f"and rgb (or spectra + wavelengths); missing {', '.join(missing)}")
        theta_i = np.asarray(f["theta_i"], float).ravel()
        phi_i = np.asarray(f["phi_i"], float).ravel()
        table = np.asarray(f[table_name], float)
        n_p, n_t = phi_i.size, theta_i.size
        vndf = np.asarray(f["vndf"], float)
        if vndf.ndim != 4 or vndf.shape[:2] != (n_p, n_t):
            raise FormatError(f"{where(self.path)}expected vndf of shape ({n_p}, {n_t}, H, W), got {vndf.shape}")
        if table.ndim != 5 or table.shape[:2] != (n_p, n_t) or table.shape[3] != table.shape[4]:
            raise FormatError(f"{where(self.path)}expected {table_name} of shape ({n_p}, {n_t}, C, N, N), got {table.shape}")
        for name in ("ndf", "sigma"):
            if np.ndim(f[name]) != 2:
                raise FormatError(f"{where(self.path)}expected a 2-D {name}, got shape {np.shape(f[name])}")
        if table_name == "spectra":
            self.wavelengths = np.asarray(f["wavelengths"], float).ravel()
            if self.wavelengths.size != table.shape[2]:
                raise FormatError(f"{where(self.path)}expected {table.shape[2]} wavelengths, got {self.wavelengths.size}")
            self.channels = tuple(f"{w:g}nm" for w in self.wavelengths)
            lam = self.wavelengths
        else:
            if table.shape[2] != 3:
                raise FormatError(f"{where(self.path)}expected rgb with 3 channels, got {table.shape[2]}")
            self.wavelengths = None
            self.channels = ("R", "G", "B")
            lam = np.arange(3.0)
        self._lam = lam
        self.description = bytes(np.asarray(f.get("description", np.zeros(0, np.uint8)), np.uint8)).decode("utf-8", "replace")
        self.jacobian = bool(np.asarray(f["jacobian"]).ravel()[0])
        self.isotropic = n_p <= 2
        self.reduction = 1 if self.isotropic else int(np.rint(2 * np.pi / (phi_i[-1] - phi_i[0])))
        if self.reduction not in (1, 2, 4):
            raise FormatError(f"{where(self.path)}expected phi_i to span 2π, π or π/2, got {phi_i[-1] - phi_i[0]:.4g} rad")
        self.theta_i_nodes = theta_i
        self._ndf = Marginal2D(f["ndf"], normalize=False, sampling=False)
        self._sigma = Marginal2D(f["sigma"], normalize=False, sampling=False)
        self._vndf = Marginal2D(vndf, [phi_i, theta_i])
        self._table = Marginal2D(table, [phi_i, theta_i, lam], normalize=False, sampling=False)
        self.sha256 = hashlib.sha256(self.path.read_bytes()).hexdigest()

    def params(self) -> dict:
        return {"reference": "rgl-tensor", "file": self.path.name, "sha256": self.sha256,
                "description": self.description, "parameterised_by": self.parameterised_by}

    def eval_cosine(self, w_param, w_out) -> np.ndarray:
        """The plugin's value f_r·cos θ_out for flat arrays (n, 3) -> (n, C)."""
        wi = np.array(w_param, float).reshape(-1, 3)
        wo = np.array(w_out, float).reshape(-1, 3)
        n = wi.shape[0]
        out = np.zeros((n, len(self.channels)))
        active = (wi[:, 2] > 0) & (wo[:, 2] > 0)
        if not active.any():
            return out
        wi, wo = wi[active], wo[active]
        if self.reduction >= 2:
            sy = wi[:, 1].copy()
            sx = wi[:, 0].copy() if self.reduction == 4 else sy
            for w in (wi, wo):
                w[:, 0] = _mulsign_neg(w[:, 0], sx)
                w[:, 1] = _mulsign_neg(w[:, 1], sy)
        m = wi + wo
        m /= np.linalg.norm(m, axis=1, keepdims=True)
        theta_i, phi_i = _elevation(wi), np.arctan2(wi[:, 1], wi[:, 0])
        theta_m, phi_m = _elevation(m), np.arctan2(m[:, 1], m[:, 0])
        u_wi = np.stack([_theta2u(theta_i), _phi2u(phi_i)], axis=-1)
        u_m = np.stack([_theta2u(theta_m), _phi2u(phi_m - phi_i if self.isotropic else phi_m)], axis=-1)
        u_m[:, 1] -= np.floor(u_m[:, 1])
        params = (phi_i, theta_i)
        s, _ = self._vndf.invert(u_m, params)
        spec = np.stack([self._table.eval(s, (phi_i, theta_i, np.full(s.shape[0], lam))) for lam in self._lam], axis=-1)
        if self.jacobian:
            spec *= (self._ndf.eval(u_m) / (4.0 * self._sigma.eval(u_wi)))[:, None]
        out[active] = spec
        return out

    def core(self, wi, wr) -> np.ndarray:
        """f_r(wi, wr) in 1/sr, (n, C), of unit pairs above the horizon (edges: :class:`ReferenceBRDF`)."""
        w_param, w_out = (wi, wr) if self.parameterised_by == "light" else (wr, wi)
        return self.eval_cosine(w_param, w_out) / w_out[:, 2:3]
