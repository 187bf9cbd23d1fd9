"""Measurement CSV: round trip, quantities, and every bad-input case (one line, file:line)."""

import numpy as np
import pytest

from kesbrdf.cli.main import main
from kesbrdf.errors import FormatError, MeasurementError
from kesbrdf.measure.gonio import measure
from kesbrdf.io.measurement_csv import read_measurement, write_measurement
from kesbrdf.references.ward import AnisotropicWard

GOOD_HEADER = "# sample: test\n# quantity: brdf\npsi_deg,theta_i_deg,theta_r_deg,value\n"


def _rows():
    return "".join(
        f"{psi},{90 - 3 * k},{3 * k},{0.3 - 0.01 * abs(15 - k):.2f}\n" for psi in (0, 45, 90, 135) for k in range(1, 30)
    )


def test_write_read_round_trip(tmp_path):
    m = measure(AnisotropicWard(0.1, 0.2, rho_d=[0.3, 0.2, 0.1]), noise=0.01, rng=1)
    back = read_measurement(write_measurement(tmp_path / "m.csv", m))
    np.testing.assert_array_equal(back.values, m.values)
    np.testing.assert_allclose(back.theta_i, m.theta_i, rtol=1e-15)
    np.testing.assert_array_equal(back.uncertainty, m.uncertainty)
    assert back.channels == ("R", "G", "B") and back.metadata["simulated"] == "true"


def test_general_geometry_and_spectral_channels(tmp_path):
    p = tmp_path / "g.csv"
    p.write_text("theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg,nm450,nm550,nm450_unc\n30,180,30,0,0.1,0.2,0.01\n")
    m = read_measurement(p)
    # the one row is in the plane of incidence (light opposite the viewer): it reads as psi = 0
    assert m.channels == ("nm450", "nm550") and m.psi is not None and m.psi.tolist() == [0.0]
    np.testing.assert_allclose(m.uncertainty[0], [0.01, 0.0])


@pytest.mark.parametrize("quantity,scale", [("brdf", 1.0), ("reflectance_factor", 1 / np.pi), ("radiance_ratio", 1 / np.cos(np.radians(60)))])
def test_quantities_are_converted_at_the_edge(tmp_path, quantity, scale):
    p = tmp_path / "q.csv"
    p.write_text(f"# quantity: {quantity}\npsi_deg,theta_i_deg,theta_r_deg,value\n0,60,30,0.5\n")
    assert read_measurement(p).values[0, 0] == pytest.approx(0.5 * scale, rel=1e-12)


def test_negative_values_are_allowed_and_reported(tmp_path):
    p = tmp_path / "n.csv"
    p.write_text(GOOD_HEADER + "0,60,30,-0.001\n0,50,40,0.2\n")
    m = read_measurement(p)
    assert m.values[0, 0] < 0 and "negative" in m.notes[0] and "line 4" in m.notes[0]


BAD = {
    "missing_column": ("psi_deg,theta_i_deg,value\n0,60,0.1\n", "missing column(s) theta_r_deg", 1),
    "unknown_column": ("psi_deg,theta_i_deg,theta_r_deg,value,colour\n0,60,30,0.1,red\n", "unknown column 'colour'", 1),
    "no_value": ("psi_deg,theta_i_deg,theta_r_deg\n0,60,30\n", "missing value column", 1),
    "text_in_number": (GOOD_HEADER + "0,60,thirty,0.1\n", "column theta_r_deg: expected a number, got 'thirty'", 4),
    "nan": (GOOD_HEADER + "0,60,30,nan\n", "expected a finite number", 4),
    "inf": (GOOD_HEADER + "0,60,30,inf\n", "expected a finite number", 4),
    "theta_out_of_range": (GOOD_HEADER + "0,95,30,0.1\n", "theta_i_deg: expected degrees in [0, 90], got 95", 4),
    "psi_out_of_range": (GOOD_HEADER + "200,60,30,0.1\n", "psi_deg: expected degrees in [0, 180)", 4),
    "radians": ("psi_deg,theta_i_deg,theta_r_deg,value\n0,1.5,0.05,0.1\n0,1.4,0.15,0.1\n0,1.3,0.25,0.1\n0,1.2,0.35,0.1\n", "look like radians", 2),
    "duplicate_conflict": (GOOD_HEADER + "0,60,30,0.1\n0,60,30,0.2\n", "same geometry as line 4 with a conflicting value", 5),
    "unknown_quantity": ("# quantity: luminance\npsi_deg,theta_i_deg,theta_r_deg,value\n0,60,30,0.1\n", "quantity: expected one of brdf, reflectance_factor, radiance_ratio, got 'luminance'", 1),
    "wrong_field_count": (GOOD_HEADER + "0,60,30\n", "expected 4 fields", 4),
    "empty": ("# only comments\n", "expected a header row", None),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_input_raises_one_line_error_with_location(tmp_path, case):
    text, message, line = BAD[case]
    p = tmp_path / f"{case}.csv"
    p.write_text(text)
    with pytest.raises((FormatError, MeasurementError)) as info:
        read_measurement(p)
    msg = str(info.value)
    assert message in msg and "\n" not in msg
    assert msg.startswith(f"{p}:{line}: " if line else f"{p}: ")


@pytest.mark.parametrize("case", sorted(BAD) + ["orientations_missing"])
def test_cli_fit_bad_input_exit_code_and_no_output(tmp_path, capsys, case):
    if case == "orientations_missing":
        text = GOOD_HEADER + "".join(f"0,{90 - 3 * k},{3 * k},0.1\n" for k in range(1, 30))
        message = "KES needs orientations psi = 0, 45, 90 deg; missing 45, 90"
    else:
        text, message, _ = BAD[case]
    p = tmp_path / "in.csv"
    p.write_text(text)
    out = tmp_path / "model.kes.json"
    code = main(["fit", str(p), "-o", str(out)])
    err = capsys.readouterr().err
    assert code == 2
    assert message in err and err.count("\n") == 1 and "Traceback" not in err
    assert not out.exists() and not list(tmp_path.glob(".model*"))


def test_good_file_fits(tmp_path):
    p = tmp_path / "ok.csv"
    p.write_text(GOOD_HEADER + _rows())
    assert main(["fit", str(p), "-o", str(tmp_path / "m.kes.json")]) == 0


def test_a_measurement_reads_the_same_whichever_columns_wrote_it(tmp_path):
    """The paper protocol plus out-of-plane pairs is written in the general columns (some
    rows have no psi); read back, its in-plane rows get their psi again, so `kesbrdf fit`
    sees the incidence lines plus extras, as in memory, and not a general measurement
    for the scattered fit (found by trying the product: 0.733 in memory, 1.194 from the CSV)."""
    from kesbrdf.fitting import choose_fitter
    from kesbrdf.io.measurement_csv import format_measurement
    from kesbrdf.measure import planning
    from kesbrdf.references.ward import AnisotropicWard

    m = planning.simulate(AnisotropicWard(0.12, 0.3), ("paper", "oop:30", "oop:60"))
    text = format_measurement(m)
    assert text.splitlines()[len(m.metadata) + 1].startswith("theta_i_deg,phi_i_deg")  # general columns
    p = tmp_path / "mixed.csv"
    p.write_text(text)
    back = read_measurement(p)
    np.testing.assert_array_equal(np.isfinite(back.psi), np.isfinite(m.psi))
    np.testing.assert_allclose(back.psi[np.isfinite(m.psi)], m.psi[np.isfinite(m.psi)], atol=1e-12)
    name, mask, *_ = choose_fitter(back)
    name0, mask0, *_ = choose_fitter(m)
    assert name == name0 == "kes" and mask.tolist() == mask0.tolist() and mask.sum() == 116
    # a row at phi_r in [180, 360) stays general: the in-plane form would swap theta_i and theta_r
    g = tmp_path / "back.csv"
    g.write_text("theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg,value\n30,0,40,180,0.1\n30,225,40,45,0.1\n")
    two = read_measurement(g)
    assert np.isnan(two.psi[0]) and two.psi[1] == pytest.approx(np.radians(45))
