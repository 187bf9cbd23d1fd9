r"""RGB → spectrum for the spectral ``.bsdf`` (pbrt-v4 has no RGB path).

Method (linear, smooth, non-negative; Smits 1999 in spirit, built here from scratch):

.. math:: \rho(\lambda) = R\,b_R(\lambda) + G\,b_G(\lambda) + B\,b_B(\lambda)

with three basis spectra b_c on the wavelength nodes :data:`WAVELENGTHS` (read
piecewise-linearly, as Mitsuba and pbrt interpolate a tabulated spectrum) that solve

    minimise Σ_c ‖Δ² b_c‖² + w ‖b_R + b_G + b_B − 1‖²   (smooth; grey close to flat)
    subject to  b_c ≥ 0,  rgb(b_c) = e_c (each basis spectrum reproduces its primary),

where rgb(ρ) = W⁻¹ M ∫ρ(λ) x̄ȳz̄(λ) dλ, x̄ȳz̄ the CIE 1931 2° observer in the analytic
multi-lobe fit of Wyman, Sloan & Shirley (JCGT 2(2), 2013), M the XYZ → linear sRGB
(Rec. 709) matrix and W the diagonal white balance that maps the flat (illuminant E)
spectrum to (1, 1, 1).  Being linear, the map is exact for any scale of RGB (the
table values are ratios that exceed 1), round-trips RGB exactly under this observer,
and gives grey values nearly flat spectra (an exactly flat sum is infeasible: the full
sRGB red primary lies at the edge of the object-colour solid).  It is an approximation of the (unknown) spectrum
of the fabric: metamers of the same RGB differ under other lights.
"""

from __future__ import annotations

import functools

import numpy as np

__all__ = ["WAVELENGTHS", "basis", "to_rgb", "cie_xyz", "XYZ_TO_RGB"]

#: nm; the wavelength nodes written in spectral files (17 values, 25 nm apart: the
#: file size grows with their number; grey stays within 15 % of flat at 25 nm, 30 % at
#: 40 nm, 3 % at 10 nm; the readers interpolate linearly between them)
WAVELENGTHS = np.arange(380.0, 781.0, 25.0)
#: CIE XYZ -> linear sRGB / Rec. 709 primaries
XYZ_TO_RGB = np.array([
    [3.2404542, -1.5371385, -0.4985314],
    [-0.9692660, 1.8760108, 0.0415560],
    [0.0556434, -0.2040259, 1.0572252],
])


def _g(lam, mu, s1, s2):
    s = np.where(lam < mu, s1, s2)
    return np.exp(-0.5 * ((lam - mu) / s) ** 2)


def cie_xyz(lam) -> np.ndarray:
    """CIE 1931 2° colour-matching functions, Wyman-Sloan-Shirley multi-lobe fit, (n, 3)."""
    lam = np.asarray(lam, float)
    x = 1.056 * _g(lam, 599.8, 37.9, 31.0) + 0.362 * _g(lam, 442.0, 16.0, 26.7) - 0.065 * _g(lam, 501.1, 20.4, 26.2)
    y = 0.821 * _g(lam, 568.8, 46.9, 40.5) + 0.286 * _g(lam, 530.9, 16.3, 31.1)
    z = 1.217 * _g(lam, 437.0, 11.8, 36.0) + 0.681 * _g(lam, 459.0, 26.0, 13.8)
    return np.stack([x, y, z], axis=-1)


def _rgb_operator(lam_nodes) -> np.ndarray:
    """A (3, L): rgb of the piecewise-linear spectrum with node values b is A @ b."""
    lam_nodes = np.asarray(lam_nodes, float)
    fine = np.arange(360.0, 831.0, 1.0)
    hats = np.stack([np.interp(fine, lam_nodes, np.eye(lam_nodes.size)[k], left=0.0, right=0.0)
                     for k in range(lam_nodes.size)])  # (L, F); zero outside the nodes
    # spectra are held constant beyond the end nodes (what the readers' clamping does)
    hats[0, fine < lam_nodes[0]] = 1.0
    hats[-1, fine > lam_nodes[-1]] = 1.0
    xyz = hats @ cie_xyz(fine)  # (L, 3), 1 nm steps
    rgb = xyz @ XYZ_TO_RGB.T  # (L, 3)
    white = rgb.sum(axis=0)
    return (rgb / white).T


#: weight of the flatness term ‖b_R + b_G + b_B − 1‖² against the smoothness term
FLATNESS_WEIGHT = 10.0


#: weight of the RGB equality rows in the penalised least squares (equality to ~1e-7)
EQUALITY_WEIGHT = 1e5


@functools.lru_cache(maxsize=8)
def _basis(lam_key: tuple) -> np.ndarray:
    """Solve the constrained problem of the module docstring as bounded least squares
    (scipy ``lsq_linear``), the equalities as heavily weighted rows."""
    from scipy.optimize import lsq_linear

    lam = np.array(lam_key)
    L = lam.size
    A = _rgb_operator(lam)
    D = np.diff(np.eye(L), 2, axis=0)
    eye3 = np.eye(3)
    rows = [np.kron(eye3, D), np.sqrt(FLATNESS_WEIGHT) * np.kron(np.ones((1, 3)), np.eye(L)),
            EQUALITY_WEIGHT * np.kron(eye3, A)]
    rhs = [np.zeros(3 * (L - 2)), np.sqrt(FLATNESS_WEIGHT) * np.ones(L), EQUALITY_WEIGHT * eye3.ravel()]
    res = lsq_linear(np.vstack(rows), np.concatenate(rhs), bounds=(0.0, np.inf), method="bvls", tol=1e-14)
    return np.maximum(res.x.reshape(3, L), 0.0)


def basis(lam=None) -> np.ndarray:
    """The basis spectra b_R, b_G, b_B at wavelengths ``lam`` (nm), shape (3, n_λ)."""
    lam = WAVELENGTHS if lam is None else np.asarray(lam, float)
    return _basis(tuple(float(v) for v in lam)).copy()


def to_rgb(spectra, lam) -> np.ndarray:
    """Linear RGB (..., 3) of spectra (..., n_λ) tabulated at ``lam`` (the inverse map)."""
    return np.asarray(spectra, float) @ _rgb_operator(lam).T
