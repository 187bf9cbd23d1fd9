"""CUReT reader: values, angles, negative handling, errors.

Original-format files are rebuilt in ``tmp_path`` from the committed extract
``tests/data/curet_fabrics.csv`` (see tests/data/README.md), so these tests need
nothing outside the repository; one extra test compares with the full database when
``$KESBRDF_CURET_DIR`` names a folder holding it (``table.txt``, ``abrdf.dat``).
"""

import os
from pathlib import Path

import numpy as np
import pytest

from kesbrdf.models.brdf import to_phi_gamma
from kesbrdf.errors import FormatError, MeasurementError
from kesbrdf.io.curet import FABRICS, N_CONFIGURATIONS, read_curet
from kesbrdf.io.measurement_csv import read_measurement
from source_helpers import write_curet

DATA = Path(__file__).resolve().parents[1] / "data"
EXTRACT = DATA / "curet_fabrics.csv"
SHARED = Path(os.environ["KESBRDF_CURET_DIR"]) if os.environ.get("KESBRDF_CURET_DIR") else None

#: The extract stores angles in degrees rounded to 1e-9°, i.e. 2e-11 rad.
ANGLE_ATOL = 1e-10
#: CUReT values are printed with three decimals; the extract keeps them exactly.
VALUE_ATOL = 1e-12


@pytest.fixture(scope="module")
def extract():
    return read_measurement(EXTRACT)


def _write_original(tmp_path, extract, samples=(1, 42), negative_at=None):
    """table.txt and abrdf.dat in CUReT's own layout, from the extract."""
    return write_curet(tmp_path, extract, samples=samples, negative_at=negative_at)


def test_extract_holds_every_fabric(extract):
    assert len(extract) == N_CONFIGURATIONS
    assert len(extract.channels) == len(FABRICS)
    for s in FABRICS:
        assert any(c.startswith(f"band_s{s:02d}_") for c in extract.channels)
    assert "Dana" in extract.metadata["citation"]


def test_reader_values_and_angles(tmp_path, extract):
    table, abrdf = _write_original(tmp_path, extract)
    m = read_curet(table, abrdf, 42)
    k = extract.channels.index("band_s42_corduroy")
    np.testing.assert_allclose(m.values[:, 0], extract.values[:, k], atol=VALUE_ATOL)
    # six decimals of radians in the rebuilt file: 5e-7 rad
    np.testing.assert_allclose(m.theta_i, extract.theta_i, atol=5e-7)
    np.testing.assert_allclose(np.cos(m.phi_r - extract.phi_r), 1.0, atol=1e-12)
    assert m.channels == ("value",)
    assert m.psi is None
    assert m.metadata["sample"] == "CUReT sample 42 (corduroy)"
    assert np.all((m.phi_i >= 0) & (m.phi_i < 2 * np.pi))
    assert m.notes == []


def test_viewer_is_theta_v_and_light_is_theta_i(tmp_path):
    # one configuration at the mirror direction: light at (30°, 0), viewer at (30°, 180°)
    (tmp_path / "table.txt").write_text("1 0.523599 3.141593 0.523599 0.000000\n2 0.2 0.5 0.7 0.1\n")
    (tmp_path / "abrdf.dat").write_text("15 1.5 0.1\n")
    m = read_curet(tmp_path / "table.txt", tmp_path / "abrdf.dat", 15)
    _, gamma = to_phi_gamma(m.wi[:1], m.wr[:1])
    assert gamma[0] < 1e-5
    np.testing.assert_allclose([m.theta_r[1], m.phi_r[1], m.theta_i[1], m.phi_i[1]], [0.2, 0.5, 0.7, 0.1])


def test_negative_values_are_kept_and_reported(tmp_path, extract):
    table, abrdf = _write_original(tmp_path, extract, samples=(1,), negative_at=[3, 7])
    m = read_curet(table, abrdf, 1)
    assert m.values[3, 0] == -0.016 and m.values[7, 0] == -0.016
    assert len(m.notes) == 1 and "2 negative" in m.notes[0] and "configuration 4" in m.notes[0]


def test_missing_sample_names_the_file(tmp_path, extract):
    table, abrdf = _write_original(tmp_path, extract, samples=(1, 42))
    with pytest.raises(MeasurementError, match=r"abrdf\.dat: expected a row for sample 7, got samples 1\.\.42"):
        read_curet(table, abrdf, 7)


def test_duplicate_sample_row(tmp_path, extract):
    table, abrdf = _write_original(tmp_path, extract, samples=(1, 1))
    with pytest.raises(MeasurementError, match=r"abrdf\.dat:2: sample 1 appears twice"):
        read_curet(table, abrdf, 1)


def test_value_count_must_match_table(tmp_path):
    (tmp_path / "table.txt").write_text("1 0.1 0.0 0.2 0.0\n2 0.3 0.0 0.4 0.0\n")
    (tmp_path / "abrdf.dat").write_text("1 0.5 0.6 0.7\n")
    with pytest.raises(FormatError, match=r"abrdf\.dat:1: expected 1 \+ 2 fields .* got 4"):
        read_curet(tmp_path / "table.txt", tmp_path / "abrdf.dat", 1)


@pytest.mark.parametrize(
    "table_text, message",
    [
        ("1 0.1 0.0 0.2\n", r"table\.txt:1: expected 5 fields"),
        ("1 0.1 0.0 0.2 0.0\n3 0.1 0.0 0.2 0.0\n", r"table\.txt:2: expected configuration index 2, got 3"),
        ("1 0.1 0.0 abc 0.0\n", r"table\.txt:1: column 4: expected a number, got 'abc'"),
        ("1 45.0 0.0 30.0 0.0\n", r"table\.txt:1: theta_v: expected radians in \[0, pi/2\], got 45"),
        ("\n\n", r"table\.txt: expected CUReT table rows, got none"),
    ],
)
def test_table_errors_name_file_and_line(tmp_path, table_text, message):
    (tmp_path / "table.txt").write_text(table_text)
    (tmp_path / "abrdf.dat").write_text("1 0.5\n")
    with pytest.raises(FormatError, match=message):
        read_curet(tmp_path / "table.txt", tmp_path / "abrdf.dat", 1)


def test_non_numeric_value(tmp_path):
    (tmp_path / "table.txt").write_text("1 0.1 0.0 0.2 0.0\n2 0.3 0.0 0.4 0.0\n")
    (tmp_path / "abrdf.dat").write_text("2 0.5 0.6\n1 0.5 nan?\n")
    with pytest.raises(FormatError, match=r"abrdf\.dat:2: column \d+ \(configuration \d+\): expected a number, got 'nan\?'"):
        read_curet(tmp_path / "table.txt", tmp_path / "abrdf.dat", 1)


@pytest.mark.skipif(SHARED is None or not SHARED.exists(), reason="full CUReT files not available ($KESBRDF_CURET_DIR)")
def test_extract_matches_full_database(extract):
    for s, name in FABRICS.items():
        m = read_curet(SHARED / "table.txt", SHARED / "abrdf.dat", s)
        col = [c for c in extract.channels if c.startswith(f"band_s{s:02d}_")][0]
        np.testing.assert_allclose(m.values[:, 0], extract.values[:, extract.channels.index(col)], atol=VALUE_ATOL)
        np.testing.assert_allclose(m.theta_r, extract.theta_r, atol=ANGLE_ATOL)
        np.testing.assert_allclose(np.cos(m.phi_i - extract.phi_i), 1.0, atol=1e-15)
    # sample 4 has negative values (dark noise) in the real file
    m4 = read_curet(SHARED / "table.txt", SHARED / "abrdf.dat", 4)
    assert m4.notes and "negative" in m4.notes[0]
