"""Physical diagnostics of a model (docs/method.md, "Diagnostics"): reciprocity, directional albedo
(white-furnace check), and the behaviour at the mirror direction γ → 0.
"""

from __future__ import annotations

import numpy as np

from kesbrdf.models.brdf import evaluate
from kesbrdf.geometry import grazing_albedo, spherical_to_cartesian  # noqa: F401  (grazing_albedo: public here too)
from kesbrdf.models.table import gamma0_behaviour

__all__ = ["directional_albedo", "grazing_albedo", "GRAZING_ANGLES_DEG", "reciprocity_error", "gamma0_behaviour", "diagnose"]

#: Quadrature resolution of the albedo integral (θ midpoints × φ midpoints); at
#: 1°×1° it resolves lobes down to the table's own 1° resolution.
ALBEDO_N_THETA = 90
ALBEDO_N_PHI = 360


def directional_albedo(brdf, wi, n_theta: int = ALBEDO_N_THETA, n_phi: int = ALBEDO_N_PHI) -> np.ndarray:
    r"""Directional albedo :math:`a(\omega_i) = \int_{H^2} f_r(\omega_i, \omega_r)\cos\theta_r\,d\omega_r`.

    Midpoint quadrature in (θ_r, φ_r).  ``brdf`` is any callable f(wi, wr) -> (..., C).

    Parameters
    ----------
    wi : array_like, shape (K, 3)

    Returns
    -------
    ndarray, shape (K, C)

    >>> from kesbrdf.references.ward import AnisotropicWard
    >>> lam = AnisotropicWard(0.2, 0.2, rho_d=0.5, rho_s=0.0)
    >>> round(float(directional_albedo(lam, [[0, 0, 1.0]])[0, 0]), 4)
    0.5
    """
    wi = np.atleast_2d(np.asarray(wi, float))
    dtheta = (np.pi / 2) / n_theta
    dphi = 2 * np.pi / n_phi
    theta = (np.arange(n_theta) + 0.5) * dtheta
    phi = (np.arange(n_phi) + 0.5) * dphi
    T, P = np.meshgrid(theta, phi, indexing="ij")
    wr = spherical_to_cartesian(T, P).reshape(-1, 3)
    weight = (np.cos(T) * np.sin(T) * dtheta * dphi).reshape(-1)
    out = []
    for w in wi:
        f = np.asarray(brdf(w[None, :], wr))
        out.append(np.sum(f * weight[:, None], axis=0))
    return np.array(out)


#: Incidence angles of the grazing-energy check (tests, ``benchmarks/bench_energy.py``).
GRAZING_ANGLES_DEG = (0.0, 60.0, 80.0, 89.0, 89.9, 89.99)


def reciprocity_error(brdf, n: int = 4000, rng=0) -> float:
    """Max |f(i,r) − f(r,i)| / max(|f|) over ``n`` random pairs above the horizon."""
    rng = np.random.default_rng(rng)
    u = rng.uniform(size=(2, n, 2))
    wi = spherical_to_cartesian(np.arccos(u[0, :, 0]), 2 * np.pi * u[0, :, 1])
    wr = spherical_to_cartesian(np.arccos(u[1, :, 0]), 2 * np.pi * u[1, :, 1])
    a = np.asarray(brdf(wi, wr))
    b = np.asarray(brdf(wr, wi))
    scale = np.maximum(np.abs(a), np.abs(b))
    ok = scale > 0
    return float(np.max(np.abs(a - b)[ok] / scale[ok])) if ok.any() else 0.0


def diagnose(model, mapping: str | None = None, theta_deg=(0, 20, 40, 60, 80), phi_deg=(0, 45, 90, 135)) -> dict:
    """All diagnostics of a model of any kind as plain numbers (JSON-ready).

    ``mapping`` defaults to the kind's own; the mirror-direction report is the kind's
    :meth:`~kesbrdf.models.base.ReflectanceModel.mirror_behaviour`.
    """
    mapping = model.check_mapping(mapping)

    def brdf(wi, wr):
        return evaluate(model, wi, wr, mapping)

    T, P = np.meshgrid(np.radians(theta_deg), np.radians(phi_deg), indexing="ij")
    wi = spherical_to_cartesian(T, P).reshape(-1, 3)
    albedo = directional_albedo(brdf, wi)
    flagged = [
        {"theta_i_deg": float(t), "phi_i_deg": float(p), "albedo": albedo[k].tolist()}
        for k, (t, p) in enumerate(zip(np.degrees(T).ravel(), np.degrees(P).ravel()))
        if np.any(albedo[k] > 1.0)
    ]
    return {
        "mapping": mapping,
        "channels": list(model.channels),
        "reciprocity_error": reciprocity_error(brdf),
        "albedo": {
            "theta_i_deg": list(map(float, theta_deg)),
            "phi_i_deg": list(map(float, phi_deg)),
            "values": albedo.reshape(len(theta_deg), len(phi_deg), -1).tolist(),
            "max": albedo.max(axis=0).tolist(),
            "above_one": flagged,
        },
        "gamma0": model.mirror_behaviour(),
        "warnings": model.warnings,
        "kes": {
            "fallback_gamma_deg": model.diagnostics.get("fallback_gamma_deg", []),
            "floored": len(model.diagnostics.get("floored", [])),
            "lobe_clamped": model.diagnostics.get("lobe_clamped", 0),
            "residual_135": model.diagnostics.get("residual_135", {}),
        },
    }
