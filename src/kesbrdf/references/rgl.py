r"""Measured BRDFs of the RGL-EPFL material database, evaluated by Mitsuba 3.

J. Dupuy and W. Jakob, "An Adaptive Parameterization for Efficient Material
Acquisition and Rendering", ACM Trans. Graph. 37(6), article 274, 2018.  The
database's isotropic materials (for instance the acrylic felts, licence CC0) come as
binary *tensor files* (``*.bsdf``, RGB variant: fields ``theta_i``, ``phi_i``,
``ndf``, ``sigma``, ``vndf``, ``luminance``, ``rgb``, ``jacobian``).  The measured
value is stored as a ratio to a fitted microfacet model, sampled on that model's
warped domain; Mitsuba 3's ``measured`` plugin reconstructs it.

Why Mitsuba rather than a numpy reader
--------------------------------------
Reconstructing a value means inverting the VNDF warp (a 2-D marginal/conditional
distribution interpolated over θ_i) to find where the half vector falls in the
sample grid, then interpolating the stored ratios there.  Mitsuba's plugin is the
reference implementation of exactly that, it is vectorised (LLVM backend) and it is the code that renders these materials.
A second implementation in numpy would be a re-derivation without a reference to
check it against.  So this module calls the plugin, variant ``llvm_ad_rgb`` (the one
:mod:`kesbrdf.render` uses).  It needs the extra ``kesbrdf[render]``.  Without Mitsuba,
:class:`kesbrdf.references.rgl_tensor.RGLTensorBRDF` is the same algorithm in numpy,
checked against this plugin (``tests/export/test_importers.py``).

Conventions (checked in ``tests/references/test_rgl.py``)
-----------------------------------------------------------
* Mitsuba's ``BSDF.eval(ctx, si, wo)`` returns f_r·cos θ_wo (the foreshortening of
  ``wo``); on a Lambertian ``diffuse`` BSDF of reflectance ρ it returns ρ/π·cos θ_wo.
  This module divides that cosine out: the callable returns f_r in 1/sr.
* The tables are parameterised by the *illumination* direction of the acquisition
  (the plugin's ``si.wi``).  By default (``parameterised_by="light"``) this module puts
  the light ``wi`` there and the viewer ``wr`` in ``wo``, so it returns the measured
  f_r(light = wi, viewer = wr) itself.  Mitsuba's own renders put the camera in
  ``si.wi`` (``parameterised_by="viewer"``), i.e. read the data through reciprocity;
  the two differ by the measurement's reciprocity error (white felt, directions
  up to 80°: median 1.3 %, 95th percentile 8 %, worst 74 % at grazing angles).
* Directions at or below the horizon give 0; NaN in gives NaN out.
* Where the acquisition has no data the plugin returns 0: on the felts, pairs with
  both directions beyond about 78° near the forward mirror direction (0.13 % of
  random pairs up to 89°).
* The materials are isotropic, so the fabric frame's x axis (warp) is arbitrary.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from kesbrdf._drjit import import_mitsuba
from kesbrdf._drjit import load_dict as _load_dict
from kesbrdf.errors import FormatError, validate_choice, where
from kesbrdf.io.tensor_file import read_tensor_file
from kesbrdf.references.base import ReferenceBRDF

__all__ = ["RGLMeasured", "read_tensor_file", "eval_plugin", "load_plugin", "VARIANT", "TENSOR_FIELDS_RGB"]

#: Mitsuba variant used for the evaluation (same as :mod:`kesbrdf.render`).
VARIANT = "llvm_ad_rgb"
#: Fields an RGB tensor file of the database must hold.
TENSOR_FIELDS_RGB = ("theta_i", "phi_i", "ndf", "sigma", "vndf", "luminance", "rgb", "jacobian")
def _import_mitsuba():
    return import_mitsuba("kesbrdf.references.rgl")


class _Variant:
    """Run a block in :data:`VARIANT`, restoring the caller's variant afterwards."""

    def __init__(self, mi):
        self.mi = mi
        self.ctx = None

    def __enter__(self):
        if self.mi.variant() is None:
            self.mi.set_variant(VARIANT)  # nothing to restore (kesbrdf.render picks the same)
        elif self.mi.variant() != VARIANT:
            self.ctx = self.mi.variant_context(VARIANT)
            self.ctx.__enter__()
        return self.mi

    def __exit__(self, *exc):
        if self.ctx is not None:
            self.ctx.__exit__(*exc)
        return False


def load_plugin(spec: dict):
    """``mitsuba.load_dict(spec)`` in variant :data:`VARIANT` (caller's variant restored)."""
    mi, _ = _import_mitsuba()
    with _Variant(mi):
        return _load_dict(spec)


def eval_plugin(bsdf, w_param, w_out) -> np.ndarray:
    """Mitsuba ``bsdf.eval`` on flat direction arrays, in variant :data:`VARIANT`.

    Parameters
    ----------
    bsdf : mitsuba.BSDF
        Loaded in :data:`VARIANT` (RGB).
    w_param, w_out : ndarray, shape (n, 3)
        Local-frame directions for ``si.wi`` and ``wo``.

    Returns
    -------
    ndarray, shape (n, 3)
        What Mitsuba returns: f_r·cos θ(w_out) (module docstring), float64.
    """
    mi, dr = _import_mitsuba()
    n = w_param.shape[0]
    with _Variant(mi):
        si = dr.zeros(mi.SurfaceInteraction3f, n)
        a = np.ascontiguousarray(np.asarray(w_param).T, dtype=np.float32)
        b = np.ascontiguousarray(np.asarray(w_out).T, dtype=np.float32)
        si.wi = mi.Vector3f(mi.Float(a[0]), mi.Float(a[1]), mi.Float(a[2]))
        si.sh_frame = mi.Frame3f(mi.Vector3f(0.0, 0.0, 1.0))
        wo = mi.Vector3f(mi.Float(b[0]), mi.Float(b[1]), mi.Float(b[2]))
        value = bsdf.eval(mi.BSDFContext(), si, wo)
        out = np.array(value, dtype=float)
    return out.T.reshape(n, 3)


class RGLMeasured(ReferenceBRDF):
    """An RGL-EPFL measured BRDF as a callable f(wi, wr) -> (..., 3) in 1/sr.

    Parameters
    ----------
    path : str or Path
        An RGB tensor file of the database (``*_rgb.bsdf``).
    parameterised_by : {"light", "viewer"}
        Which direction goes into the plugin's ``si.wi``, the acquisition's
        illumination direction (module docstring).  ``"light"`` returns the
        measurement as acquired; ``"viewer"`` is what Mitsuba renders.

    Attributes
    ----------
    channels : tuple of str
        ``("R", "G", "B")``, linear RGB as stored in the file.
    description : str
        The file's own description, e.g. ``"White acrylic felt (Edukit A4)"``.
    theta_i_nodes : ndarray
        Measured illumination elevations, radians.
    isotropic : bool
        One measured φ_i.
    sha256 : str
        Of the file.

    Examples
    --------
    >>> import numpy as np
    >>> from kesbrdf.references.rgl import RGLMeasured
    >>> felt = RGLMeasured("src/kesbrdf/data/rgl/acrylic_felt_white_rgb.bsdf")  # doctest: +SKIP
    >>> felt([[0, 0, 1.0]], [[0, 0, 1.0]]).shape  # doctest: +SKIP
    (1, 3)
    """

    channels = ("R", "G", "B")
    #: One Mitsuba call per 2^20 pairs: each call has a fixed cost (kernel launch).
    chunk = 1 << 20

    def __init__(self, path, parameterised_by: str = "light"):
        validate_choice("parameterised_by", parameterised_by, ("light", "viewer"), error=FormatError)
        self.path = Path(path)
        self.parameterised_by = parameterised_by
        fields = read_tensor_file(self.path)
        missing = [name for name in TENSOR_FIELDS_RGB if name not in fields]
        if missing:
            raise FormatError(
                f"{where(self.path)}expected an RGB tensor file with fields {', '.join(TENSOR_FIELDS_RGB)}; "
                f"missing {', '.join(missing)} (spectral files are not supported)"
            )
        if fields["rgb"].ndim != 5 or fields["rgb"].shape[2] != 3:
            raise FormatError(f"{where(self.path)}expected rgb of shape (φ_i, θ_i, 3, n, n), got {fields['rgb'].shape}")
        self.description = bytes(fields.get("description", np.zeros(0, np.uint8))).decode("utf-8", "replace")
        self.theta_i_nodes = np.asarray(fields["theta_i"], float)
        self.isotropic = fields["phi_i"].shape[0] <= 2
        self.sha256 = hashlib.sha256(self.path.read_bytes()).hexdigest()
        self._bsdf = load_plugin({"type": "measured", "filename": str(self.path.resolve())})

    def params(self) -> dict:
        """Generator parameters recorded by :func:`kesbrdf.measure.gonio.measure`."""
        return {
            "reference": "rgl",
            "file": self.path.name,
            "sha256": self.sha256,
            "description": self.description,
            "parameterised_by": self.parameterised_by,
        }

    def core(self, wi, wr) -> np.ndarray:
        """f_r(wi, wr) in 1/sr, (n, 3), of unit pairs above the horizon (edges: :class:`ReferenceBRDF`)."""
        w_param, w_out = (wi, wr) if self.parameterised_by == "light" else (wr, wi)
        # Mitsuba's eval includes the foreshortening cosine of wo: divide it out
        return eval_plugin(self._bsdf, w_param, w_out) / w_out[:, 2:3]
