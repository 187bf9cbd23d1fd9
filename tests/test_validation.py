"""Metrics, leave-one-orientation-out, reference comparison."""

import numpy as np
import pytest

from kesbrdf.measure.gonio import measure
from kesbrdf.references.ward import AnisotropicWard
from kesbrdf.validate.compare import compare_reference, leave_one_orientation_out, metrics


def test_metrics_by_hand():
    pred = np.array([[1.0], [2.0], [4.0]])
    truth = np.array([[1.0], [1.0], [4.0]])
    m = metrics(pred, truth, ["v"])["v"]
    assert m["rmse"] == pytest.approx(np.sqrt(1 / 3), rel=1e-12)
    assert m["max_abs"] == pytest.approx(1.0)
    assert m["nrmse"] == pytest.approx(np.sqrt(1 / 3) / 2, rel=1e-12)
    eps = 1e-3 * 4
    assert m["log_rmse"] == pytest.approx(np.sqrt(np.log((2 + eps) / (1 + eps)) ** 2 / 3), rel=1e-12)


def test_leave_one_orientation_out_is_exact_for_a_symmetric_fabric():
    # Ward is symmetric under φ → π − φ, so the mirrored 135° predicts 45° exactly
    m = measure(AnisotropicWard(0.1, 0.2, rho_d=0.2, rho_s=0.1))
    res = leave_one_orientation_out(m)
    assert res["0"]["possible"] is False and res["90"]["possible"] is False
    assert res["45"]["metrics"]["all"]["rmse"] < 1e-12
    assert res["135"]["metrics"]["all"]["rmse"] < 1e-12


def test_leave_one_orientation_out_detects_asymmetry():
    # a lobe rotated off the warp breaks the φ → π − φ symmetry
    ref = AnisotropicWard(0.1, 0.25, rho_d=0.2, rho_s=0.1)
    rot = np.radians(20)
    R = np.array([[np.cos(rot), -np.sin(rot), 0], [np.sin(rot), np.cos(rot), 0], [0, 0, 1]])

    def rotated(wi, wr):
        return ref(wi @ R, wr @ R)

    rotated.channels = ref.channels
    res = leave_one_orientation_out(measure(rotated))
    assert res["45"]["metrics"]["all"]["nrmse"] > 0.05


def test_compare_reference_structure_and_perfect_isotropic():
    iso = AnisotropicWard(0.2, 0.2, rho_d=0.3, rho_s=0.1)
    r = compare_reference(measure(iso), iso)
    held = r["cases"]["held_out_orientations"]
    assert set(held) == {"kes", "nearest", "linear"}
    assert held["kes"]["all"]["rmse"] < 1e-10  # isotropic: every orientation is exact
    assert "hemisphere_theta_i30_phi_i90" in r["cases"]


def _pairs_at_deviation(gammas_deg, theta_i_deg=30.0):
    """Light at θ_i in the x-z plane; viewer the mirror direction turned by γ about the
    y axis toward the normal and beyond (so the deviation is exactly γ)."""
    from kesbrdf.geometry import spherical_to_cartesian

    ti = np.radians(theta_i_deg)
    wi = np.repeat(spherical_to_cartesian(ti, np.pi)[None, :], len(gammas_deg), axis=0)
    tr = ti - np.radians(np.asarray(gammas_deg, float))  # signed polar angle in the x-z plane
    wr = np.stack([np.sin(tr), np.zeros_like(tr), np.cos(tr)], axis=1)
    return wi, wr


def test_deviation_bands_place_an_error_in_its_band():
    """An error put only at γ = 40° is 100 % of the squared error in the 30-60° band; the
    other bands hold 0 and a median ratio of exactly 1; the band NRMSE uses the mean
    |truth| of all samples (metrics' scale)."""
    from kesbrdf.validate.compare import DEVIATION_BANDS_DEG, deviation_bands

    gammas = [0.0, 5.0, 20.0, 40.0, 40.0, 70.0, 100.0]
    wi, wr = _pairs_at_deviation(gammas)
    truth = np.array([[4.0], [2.0], [1.0], [0.5], [0.5], [0.25], [0.25]])
    pred = truth.copy()
    pred[3:5] *= 2.0  # the model twice as bright at γ = 40° only
    bands = deviation_bands(pred, truth, wi, wr)
    by_lo = {b["lo"]: b for b in bands}
    assert [b["lo"] for b in bands] == list(DEVIATION_BANDS_DEG[:-1])
    assert [b["n"] for b in bands] == [2, 1, 2, 1, 1]
    assert by_lo[30.0]["share"] == pytest.approx(1.0, abs=1e-12)
    assert sum(b["share"] for b in bands) == pytest.approx(1.0, abs=1e-12)
    assert by_lo[30.0]["ratio"] == pytest.approx(2.0, rel=1e-12)
    assert all(b["share"] == 0.0 and b["ratio"] == 1.0 for b in bands if b["lo"] != 30.0)
    assert by_lo[30.0]["nrmse"] == pytest.approx(0.5 / np.mean(truth), rel=1e-12)


def test_validate_reports_where_the_error_is():
    """validate() splits the error by deviation: a KES fit of an anisotropic Ward's paper
    samples, checked on a dense measurement of the same Ward, errs on the dense grid's
    other incidence lines; the shares sum to 1 over the bands."""
    from kesbrdf.models.kes import fit
    from kesbrdf.validate.compare import validate

    ref = AnisotropicWard(0.1, 0.3, rho_d=0.2, rho_s=0.1)
    model = fit(measure(ref))
    result = validate(model, measure(ref, protocol="dense"))
    bands = result["by_deviation"]
    assert sum(b["n"] for b in bands) == result["n"]
    assert sum(b["share"] for b in bands) == pytest.approx(1.0, abs=1e-9)
    assert min(b["lo"] for b in bands) == 0.0


def test_leave_one_orientation_out_scores_the_incidence_line_only():
    """With a 30° incidence line beside the paper's (``simulate --extras line:30``) the
    check is the one of the paper rows alone: the same fits on the same rows, the other
    rows counted as left out (before, they were scored too: Sadeghi satin 0.074)."""
    from kesbrdf.measure import planning
    from kesbrdf.references.sadeghi2013 import Sadeghi2013

    ref = Sadeghi2013(preset="satin")
    both = planning.simulate(ref, ("paper", "line:30"))
    paper = planning.simulate(ref, ("paper",))
    res, alone = leave_one_orientation_out(both), leave_one_orientation_out(paper)
    for held in ("45", "135"):
        assert res[held]["rows"] == 29 and res[held]["line_deg"] == 90.0
        assert res[held]["rows_off_line"] == 14  # line:30's 15 rows at ψ, its θ_r = 60° shared with the paper line
        assert res[held]["metrics"]["all"]["nrmse"] == pytest.approx(alone[held]["metrics"]["all"]["nrmse"],
                                                                     rel=1e-9, abs=1e-15)
        assert res[held]["metrics"]["all"]["nrmse"] < 1e-9  # the satin's biases are mirror images
