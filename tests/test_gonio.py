"""Virtual gonioreflectometer protocols and noise model."""

import numpy as np
import pytest

from kesbrdf.errors import KesbrdfError
from kesbrdf.measure.gonio import measure, protocol_geometry
from kesbrdf.references.ward import AnisotropicWard


def test_paper_protocol_is_116_samples_with_theta_sum_90():
    psi, ti, tr = protocol_geometry("paper")
    assert psi.size == 116
    np.testing.assert_allclose(np.degrees(ti + tr), 90.0, atol=1e-12)
    gamma = np.degrees(tr - ti)
    np.testing.assert_allclose(np.unique(np.round(gamma, 9)), np.arange(-84, 85, 6))
    np.testing.assert_allclose(np.unique(np.degrees(psi)), [0, 45, 90, 135])


def test_dense_protocol_counts():
    psi, ti, tr = protocol_geometry("dense", step_deg=6)
    assert psi.size == 4 * 15 * 15


def test_noise_statistics(rng):
    ref = AnisotropicWard(0.2, 0.3, rho_d=0.3, rho_s=0.1)
    clean = measure(ref)
    noisy = [measure(ref, noise=0.05, rng=seed).values for seed in range(200)]
    rel = (np.array(noisy) - clean.values) / clean.values
    # 200 × 116 draws: the sample std of a unit-σ normal is within 2 % of 1
    assert np.std(rel) == pytest.approx(0.05, rel=0.02)
    assert measure(ref, noise=0.05, rng=1).uncertainty is not None


def test_labelled_simulated():
    m = measure(AnisotropicWard(0.2, 0.3))
    assert m.metadata["simulated"] == "true" and "ward" in m.metadata["generator"]


def test_bad_step():
    with pytest.raises(KesbrdfError, match="divides 90"):
        protocol_geometry("paper", step_deg=7)
    with pytest.raises(KesbrdfError, match="protocol: expected one of paper"):
        protocol_geometry("sparse")
