"""Checks shared by the tests of a table kind's stored σ (eq. K1): kes (tests/test_kes_sigma.py)
and kes-halfdiff (tests/test_halfdiff_sigma.py)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from kesbrdf.errors import ModelError
from kesbrdf.geometry import spherical_to_cartesian
from kesbrdf.io.model_file import load_model as load
from kesbrdf.measure.gonio import measure
from kesbrdf.validate.compare import HELD_OUT_DEG, hemisphere_directions
from kesbrdf.validate.uncertainty import coverage, predict_sigma


def saved(model, directory):
    """(model, path): ``model`` saved as ``directory``/m.kes.json."""
    model.save(directory / "m.kes.json")
    return model, directory / "m.kes.json"


def assert_sigma_is_the_noise(model, wi, wr, noise):
    """On pairs of the data (d_φ = d_slice = 0) σ_ln f = n, and n lies within [noise,
    1.2 noise] (the measurement's relative noise; 1.2 for the absolute noise floor's share
    on dark samples)."""
    _, _, sl = model.predict_sigma(wi, wr)
    assert np.allclose(sl, model.sigma["noise"])
    assert noise <= model.sigma["noise"] <= 1.2 * noise


def assert_scales_act_alone(model, wi, wr, between, on_phi, off, on_slice):
    """Each scale of eq. (K1) acts on its own term: twice the kind's azimuth scale widens σ
    at the pairs ``between`` measured azimuths and leaves the pairs ``on_phi`` (d_φ = 0)
    unchanged; twice its slice scale widens the pairs ``off`` the support and leaves
    ``on_slice`` unchanged (lists of pair indices)."""
    from kesbrdf.models.kes_sigma import predict_kes_sigma

    base = predict_kes_sigma(model, wi, wr)[2][:, 0]
    wide_az = predict_kes_sigma(model, wi, wr, {"azimuth": 2 * model.sigma_scales["azimuth"]})[2][:, 0]
    wide_sl = predict_kes_sigma(model, wi, wr, {"slice": 2 * model.sigma_scales["slice"]})[2][:, 0]
    assert np.all(wide_az[between] > base[between]) and np.allclose(wide_az[on_phi], base[on_phi])
    assert np.all(wide_sl[off] > base[off]) and np.allclose(wide_sl[on_slice], base[on_slice])


def assert_round_trip(model, path, wi, wr):
    """The σ summary and every σ it gives are the same to the bit after save and load,
    and a second save writes the same ``sigma`` document."""
    again = load(path)
    assert again.has_sigma and again.sigma == model.sigma
    for a, b in zip(model.predict_sigma(wi, wr), again.predict_sigma(wi, wr)):
        assert np.array_equal(a, b)
    again.save(path.with_name("again.kes.json"))
    assert json.loads(path.read_text())["sigma"] == json.loads(path.with_name("again.kes.json").read_text())["sigma"]


def assert_old_file_refuses(model, path, tmp_path, wi, wr) -> str:
    """The file without ``sigma`` (as written before it) loads, evaluates the same and
    refuses σ with a one-line ModelError; returns the message."""
    doc = json.loads(path.read_text())
    del doc["sigma"]
    old = tmp_path / "old.kes.json"
    old.write_text(json.dumps(doc))
    m = load(old)
    assert not m.has_sigma and m.predict_sigma(wi, wr) is None
    np.testing.assert_array_equal(m.evaluate(wi, wr), model.evaluate(wi, wr))
    with pytest.raises(ModelError) as exc:
        predict_sigma(m, wi, wr, source=str(old))
    assert "carries no uncertainty" in str(exc.value) and "\n" not in str(exc.value)
    return str(exc.value)


def load_with_sigma_field(path, tmp_path, field, value) -> str:
    """Loading the file with ``sigma[field] = value`` is a one-line ModelError; its message."""
    doc = json.loads(path.read_text())
    doc["sigma"][field] = value
    bad = tmp_path / "bad.kes.json"
    bad.write_text(json.dumps(doc))
    with pytest.raises(ModelError) as exc:
        load(bad)
    assert "\n" not in str(exc.value)
    return str(exc.value)


def truths(ref, protocol: str = "paper", hemispheres: bool = True, step_deg: float = 10.0):
    """[(case, wi, wr, truth)]: the held-out orientations (the ``protocol``'s geometry) and,
    with ``hemispheres``, the Fig. 6 hemispheres (light θ_i = 30°, φ_i = 90° and 45°)."""
    held = measure(ref, protocol=protocol, orientations_deg=HELD_OUT_DEG)
    out = [("held_out", held.wi, held.wr, held.values)]
    if hemispheres:
        wr, _, _ = hemisphere_directions(step_deg)
        wr = wr.reshape(-1, 3)
        for phi_i in (90.0, 45.0):
            wi = np.broadcast_to(spherical_to_cartesian(np.radians(30.0), np.radians(phi_i)), wr.shape)
            out.append((f"hemi{phi_i:g}", wi, wr, np.asarray(ref(wi, wr), float)))
    return out


def coverage_rows(model, cases) -> list:
    """[(case, f, σ_ln f, truth)] of ``model`` on :func:`truths`."""
    rows = []
    for case, wi, wr, truth in cases:
        f, _, sl = predict_sigma(model, wi, wr)
        rows.append((case, f, sl, truth))
    return rows


def fitted_family_rows(directory, families: dict, fit, protocol: str, hemispheres, step_deg: float = 10.0) -> dict:
    """{family: [(case, f, σ_ln f, truth)]}: each reference of ``families`` ({family:
    [reference]}) fitted by ``fit`` (reference -> model), saved in ``directory`` and loaded
    (the σ a user's file gives), scored on :func:`truths` (hemispheres when
    ``hemispheres(family)``)."""
    out = {}
    for fam, refs in families.items():
        rows = []
        for k, ref in enumerate(refs):
            path = directory / f"{fam}{k}.kes.json"
            fit(ref).save(path)
            rows += coverage_rows(load(path), truths(ref, protocol, hemispheres(fam), step_deg))
        out[fam] = rows
    return out


def family_coverage(rows, factor=1.0) -> dict:
    """{case: (mean within 1σ, mean within 2σ)} over a family's references, σ × ``factor``."""
    out = {}
    for case in dict.fromkeys(c for c, *_ in rows):
        cov = [coverage(f, factor * sl, t) for c, f, sl, t in rows if c == case]
        out[case] = (np.mean([c["within_1sigma"] for c in cov]), np.mean([c["within_2sigma"] for c in cov]))
    return out
