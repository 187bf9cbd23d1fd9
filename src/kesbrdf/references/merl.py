r"""MERL ``.binary`` isotropic measured BRDFs (Matusik, Pfister, Brand, McMillan 2003) as references.

W. Matusik, H. Pfister, M. Brand and L. McMillan, "A Data-Driven Reflectance Model",
ACM Trans. Graph. 22(3), 759–769, 2003.  The 100 materials of the MERL database are
isotropic; a fabric measured with kesbrdf can be compared with them, or a MERL material
run through :func:`kesbrdf.measure.gonio.measure` like any reference.

Layout (checked against the database's reference reader ``BRDFRead.cpp`` and
re-implementations of it)::

    int32  dims[3] = 90, 90, 180             (θ_h, θ_d, φ_d bins)
    float64 R[90·90·180], G[...], B[...]     channel-planar, index i_φd + 180 (i_θd + 90 i_θh)

in the Rusinkiewicz half/difference angles: h = normalize(ω_i + ω_r), θ_h its elevation;
the difference vector d = R_y(−θ_h) R_z(−φ_h) ω_i (ω_i turned into the frame of h);
θ_d, φ_d its angles, φ_d folded to [0, π) by reciprocity (φ_d < 0 → φ_d + π).
Bins (nearest, no interpolation, as the reference reader):

* i_θh = ⌊sqrt(θ_h / (π/2)) · 90⌋ (non-linear: fine near the specular peak),
* i_θd = ⌊θ_d / (π/2) · 90⌋,  i_φd = ⌊φ_d / π · 180⌋, each clamped to the range.

The stored value times (1/1500, 1.15/1500, 1.66/1500) is f_r per channel in 1/sr, not
cosine-weighted.  Negative values mark bins the acquisition did not cover; this reader
returns 0 there (:attr:`MERLBinary.missing_fraction` says how many).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from kesbrdf.errors import FormatError, where
from kesbrdf.io.files import read_regular
from kesbrdf.references.base import ReferenceBRDF

__all__ = ["MERLBinary", "DIMS", "SCALE", "half_diff", "bin_index"]

#: Bins of θ_h, θ_d and φ_d (φ_d over [0, π)).
DIMS = (90, 90, 180)
#: Stored value -> f_r, per channel (R, G, B).
SCALE = np.array([1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0])


def _rotate(v, axis: str, angle):
    """Rotate vectors v (n, 3) about the z or y axis by ``angle`` (n,) (right-handed)."""
    c, s = np.cos(angle), np.sin(angle)
    x, y, z = v[:, 0], v[:, 1], v[:, 2]
    if axis == "z":
        return np.stack([c * x - s * y, s * x + c * y, z], axis=-1)
    return np.stack([c * x + s * z, y, -s * x + c * z], axis=-1)


def half_diff(wi, wr):
    """Rusinkiewicz angles (θ_h, φ_h, θ_d, φ_d) of direction pairs (n, 3)."""
    h = wi + wr
    h = h / np.linalg.norm(h, axis=1, keepdims=True)
    theta_h = np.arccos(np.clip(h[:, 2], -1.0, 1.0))
    phi_h = np.arctan2(h[:, 1], h[:, 0])
    d = _rotate(_rotate(wi, "z", -phi_h), "y", -theta_h)
    theta_d = np.arccos(np.clip(d[:, 2], -1.0, 1.0))
    phi_d = np.arctan2(d[:, 1], d[:, 0])
    return theta_h, phi_h, theta_d, phi_d


def bin_index(theta_h, theta_d, phi_d) -> np.ndarray:
    """Flat index into one channel of the table (module docstring)."""
    n_th, n_td, n_pd = DIMS
    i_th = np.clip(np.floor(np.sqrt(np.maximum(theta_h, 0.0) / (np.pi / 2)) * n_th), 0, n_th - 1)
    i_td = np.clip(np.floor(theta_d / (np.pi / 2) * n_td), 0, n_td - 1)
    phi_d = np.where(phi_d < 0, phi_d + np.pi, phi_d)
    i_pd = np.clip(np.floor(phi_d / np.pi * n_pd), 0, n_pd - 1)
    return (i_pd + n_pd * (i_td + n_td * i_th)).astype(np.int64)


class MERLBinary(ReferenceBRDF):
    """A MERL ``.binary`` file as a callable f(wi, wr) -> (..., 3) in 1/sr.

    Parameters
    ----------
    path : str or Path

    Attributes
    ----------
    channels : tuple of str
        ``("R", "G", "B")``.
    table : ndarray, shape (3, 90, 90, 180)
        f_r per channel and bin (θ_h, θ_d, φ_d), 1/sr; missing bins are negative.
    missing_fraction : float
        Share of bins marked missing.
    """

    channels = ("R", "G", "B")

    def __init__(self, path):
        self.path = Path(path)
        try:
            raw = read_regular(self.path)
        except OSError as exc:
            raise FormatError(f"{where(self.path)}expected a readable MERL .binary file, got {exc.strerror}") from exc
        if len(raw) < 12:
            raise FormatError(f"{where(self.path)}expected a MERL .binary file (12-byte header), got {len(raw)} bytes")
        dims = tuple(int(v) for v in np.frombuffer(raw, "<i4", 3))
        if dims != DIMS:
            raise FormatError(f"{where(self.path)}expected MERL dimensions {DIMS} (θ_h, θ_d, φ_d), got {dims}")
        n = int(np.prod(DIMS))
        expected = 12 + 3 * n * 8
        if len(raw) != expected:
            raise FormatError(f"{where(self.path)}expected {expected} bytes (header + 3 x {n} float64), got {len(raw)}")
        values = np.frombuffer(raw, "<f8", 3 * n, 12).reshape(3, n)
        self.table = (values * SCALE[:, None]).reshape((3,) + DIMS)
        self._flat = self.table.reshape(3, n)
        self.missing_fraction = float(np.mean(values < 0))
        self.sha256 = hashlib.sha256(raw).hexdigest()

    def params(self) -> dict:
        return {"reference": "merl", "file": self.path.name, "sha256": self.sha256}

    def core(self, wi, wr) -> np.ndarray:
        """f_r (n, 3) in 1/sr (nearest bin) of unit pairs above the horizon; 0 in missing bins."""
        th, _, td, pd = half_diff(wi, wr)
        return np.maximum(self._flat[:, bin_index(th, td, pd)].T, 0.0)
