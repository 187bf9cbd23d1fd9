"""The ``fibre-coord`` kind: fibre coordinates, reciprocity, energy, round trips, σ, files."""

from __future__ import annotations

import math

import numpy as np
import pytest

from kesbrdf.geometry import grazing_albedo
from kesbrdf.measure.gonio import measure
from kesbrdf.models.base import kind_class
from kesbrdf.models.fibre_coord import FibreCoordModel, fibre_coordinates
from kesbrdf.models.fibre_prior import predict_with_uncertainty
from kesbrdf.references.irawan2012 import Irawan2012


def _random_pairs(n, seed):
    rng = np.random.default_rng(seed)
    w = rng.normal(size=(2, n, 3))
    w[..., 2] = np.abs(w[..., 2]) + 0.05
    return w / np.linalg.norm(w, axis=-1, keepdims=True)


@pytest.fixture(scope="module")
def paper_fit(fibre_coord_fit):
    """(measurement, model): the shared fit of tests/conftest.py (fibre_coord_fit)."""
    return fibre_coord_fit


def test_pairs_on_a_fibre_cone_have_zero_tilt():
    # the cone is built in: a pair with ω_o·t = −ω_i·t for the warp tangent t = x (the
    # mirror condition of a cylinder, θ_o = −θ_i) has u* = 0 whatever its azimuths
    rng = np.random.default_rng(0)
    for _ in range(20):
        a = rng.uniform(-0.6, 0.6)
        phi_i, phi_o = rng.uniform(0.2, 2.9, 2)
        ca = math.sqrt(1 - a * a)
        wi = np.array([[a, ca * math.cos(phi_i), ca * math.sin(phi_i)]])
        wo = np.array([[-a, ca * math.cos(phi_o), ca * math.sin(phi_o)]])
        u, phi, G = fibre_coordinates(wi, wo, 0.0)
        assert abs(u[0]) < 1e-9
        # and φ is the angle between the two projections on the plane ⟂ t
        assert phi[0] == pytest.approx(abs(phi_i - phi_o), abs=1e-9)
    # the weft (α = 90°) of the same pair is generally off its cone
    assert abs(fibre_coordinates(wi, wo, math.pi / 2)[0][0]) > 1e-3


def test_reciprocal(paper_fit):
    _, model = paper_fit
    wi, wr = _random_pairs(500, 1)
    a, b = model.evaluate(wi, wr), model.evaluate(wr, wi)
    # every factor is symmetric in ωi ↔ ωr (module docstring); round-off only
    assert np.max(np.abs(a - b) / np.maximum(np.abs(a), 1e-12)) < 1e-9


def test_energy_conserving(paper_fit):
    _, model = paper_fit
    a = grazing_albedo(model.evaluate, [0.0, 30.0, 60.0, 80.0, 89.0], 0.0, 48, 96)
    a90 = grazing_albedo(model.evaluate, [0.0, 60.0, 89.0], 90.0, 48, 96)
    # the energy scale bounds the albedo at 0.95 up to its interpolation (< 0.03 measured
    # on the reference families, fibre_prior.ENERGY_BOUND): 1 is the physical limit
    assert np.all(a < 1.0) and np.all(a90 < 1.0)
    assert np.all(a > 0.0)


def test_reproduces_the_measured_samples(paper_fit):
    m, model = paper_fit
    # the KES residual multiplies the ratio back on the incidence line (paper protocol)
    pred = model.evaluate(m.wi, m.wr)
    above = m.values > 1e-4 * m.values.max(axis=0)
    assert np.max(np.abs(pred - m.values)[above] / m.values[above]) < 1e-6


def test_file_round_trip(tmp_path, paper_fit):
    from kesbrdf.io.model_file import load_model

    _, model = paper_fit
    model.save(tmp_path / "m.kes.json")
    back = load_model(tmp_path / "m.kes.json")
    assert back.kind == "fibre-coord" and isinstance(back, FibreCoordModel)
    wi, wr = _random_pairs(300, 2)
    np.testing.assert_allclose(back.evaluate(wi, wr), model.evaluate(wi, wr), rtol=1e-12, atol=0)


def test_sigma_per_prediction(paper_fit):
    _, model = paper_fit
    wi, wr = _random_pairs(200, 4)
    f, sigma, sigma_log = predict_with_uncertainty(model, wi, wr)
    assert np.all(np.isfinite(sigma)) and np.all(sigma_log > 0)
    # off the measured support (out of the plane) σ grows: median σ_ln off-plane above
    # its value on the measured line
    m, _ = paper_fit
    on = predict_with_uncertainty(model, m.wi, m.wr)[2]
    assert np.median(sigma_log) > np.median(on)


def test_bad_option_is_one_line():
    from kesbrdf.errors import ModelError

    m = measure(Irawan2012("silk_charmeuse"), protocol="paper", step_deg=15)
    with pytest.raises(ModelError, match="unknown option"):
        kind_class("fibre-coord").fit_measurement(m, kinds="auto")
