"""Directional albedo quadrature, reciprocity error, γ → 0 behaviour."""

import numpy as np
import pytest

from kesbrdf.validate.diagnostics import diagnose, directional_albedo, reciprocity_error
from kesbrdf.measure.gonio import measure
from kesbrdf.models.kes import fit
from kesbrdf.references.ward import AnisotropicWard

#: Midpoint quadrature at 1°: the Lambertian albedo is exact to O(Δθ²) ≈ 1e-4.
QUADRATURE_RTOL = 2e-4


def test_lambertian_albedo_is_rho():
    lam = AnisotropicWard(0.2, 0.2, rho_d=0.7, rho_s=0.0)
    a = directional_albedo(lam, [[0, 0, 1.0], [0.6, 0, 0.8]])
    np.testing.assert_allclose(a, 0.7, rtol=QUADRATURE_RTOL)


def test_white_furnace_flags_albedo_above_one():
    hot = fit(measure(AnisotropicWard(0.2, 0.2, rho_d=1.5, rho_s=0.0)))
    d = diagnose(hot)
    assert d["albedo"]["above_one"], "an albedo-1.5 model must be flagged"
    ok = diagnose(fit(measure(AnisotropicWard(0.2, 0.2, rho_d=0.5, rho_s=0.1))))
    assert ok["albedo"]["above_one"] == []


def test_reciprocity_error_detects_a_non_reciprocal_brdf():
    def skew(wi, wr):
        return (1 + wi[..., :1]) * np.ones((1,))

    assert reciprocity_error(skew) > 0.1


def test_gamma0_reports_peak_spread():
    m = measure(AnisotropicWard(0.1, 0.2, rho_d=0.2, rho_s=0.1))
    d = diagnose(fit(m))
    peaks = d["gamma0"]["measured_peaks"]
    assert set(peaks["q_deg"]) == {"0", "45", "90", "135"}
    assert peaks["max_over_min"][0] == pytest.approx(1.0, abs=1e-9)  # Ward: one peak value
