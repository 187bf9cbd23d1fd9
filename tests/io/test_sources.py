"""Opening any measurement source by path (``kesbrdf.io.sources``): recognition, CUReT
samples by number or name, BRDF tables sampled at a protocol's geometries, and the
one-line errors.  Every file is in the repository or written here (tests/source_helpers.py).
"""

import shutil

import numpy as np
import pytest
from source_helpers import CURET_EXTRACT, RGL_FELT, write_curet, write_merl

from kesbrdf.errors import FormatError, KesbrdfError
from kesbrdf.geometry import spherical_to_cartesian
from kesbrdf.io.curet import FABRICS, read_curet
from kesbrdf.io.measurement_csv import read_measurement
from kesbrdf.io.sources import curet_sample, detect, read_source, reference_from_file
from kesbrdf.references.registry import make_reference
from kesbrdf.references.rgl_tensor import RGLTensorBRDF
from kesbrdf.references.ward import AnisotropicWard

#: The synthetic MERL material: isotropic Ward + Lambert, a broad lobe that the
#: nearest-bin reader resolves (docs/exports.md: random pairs median 5e-5, p90 1.8 %).
MERL_TRUTH = AnisotropicWard(0.25, 0.25, rho_d=[0.3, 0.2, 0.1], rho_s=0.15)
#: MERL is read at the nearest bin; at the paper protocol's 116 geometries the measured
#: error against the analytic BRDF is median 0.5 %, p90 1.7 %, worst 3.3 %.
MERL_NEAREST_BIN_RTOL = 0.05


@pytest.fixture(scope="module")
def merl_path(tmp_path_factory):
    path = tmp_path_factory.mktemp("merl") / "ward.binary"
    write_merl(path, MERL_TRUTH)
    return path


@pytest.fixture
def curet_dir(tmp_path):
    write_curet(tmp_path, samples=(1, 29, 42))
    return tmp_path


def _directions(m):
    return spherical_to_cartesian(m.theta_i, m.phi_i), spherical_to_cartesian(m.theta_r, m.phi_r)


# -- recognition ----------------------------------------------------------------------------
def test_detect_by_name_and_by_content(tmp_path, curet_dir, merl_path):
    assert detect(CURET_EXTRACT) == "measurement-csv"
    assert detect(curet_dir / "abrdf.dat") == detect(curet_dir / "table.txt") == detect(curet_dir) == "curet"
    assert detect(RGL_FELT) == "rgl-bsdf"
    assert detect(merl_path) == "merl-binary"
    # content wins over a misleading or missing ending
    shutil.copy(RGL_FELT, tmp_path / "felt.dat")
    assert detect(tmp_path / "felt.dat") == "rgl-bsdf"
    (tmp_path / "merl_copy").symlink_to(merl_path)
    assert detect(tmp_path / "merl_copy") == "merl-binary"
    shutil.copy(CURET_EXTRACT, tmp_path / "extract.txt")
    assert detect(tmp_path / "extract.txt") == "measurement-csv"
    # a renamed abrdf.dat is CUReT when its table.txt is beside it
    shutil.copy(curet_dir / "abrdf.dat", curet_dir / "fabrics.dat")
    assert detect(curet_dir / "fabrics.dat") == "curet"


def test_unknown_input_is_one_line_listing_the_kinds(tmp_path):
    p = tmp_path / "photo.png"
    p.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(range(256)))
    with pytest.raises(FormatError) as exc:
        detect(p)
    msg = str(exc.value)
    assert "\n" not in msg and str(p) in msg
    for kind in ("measurement CSV", "CUReT abrdf.dat", "RGL tensor file", "MERL .binary"):
        assert kind in msg
    with pytest.raises(FileNotFoundError):
        detect(tmp_path / "missing.bsdf")


# -- CUReT ------------------------------------------------------------------------------------
@pytest.mark.parametrize("spec, number", [("42", 42), (42, 42), ("corduroy", 42), ("Polyester-Zoomed", 29),
                                          ("polyester", 2), ("RUG A", 18), ("15", 15)])
def test_curet_sample_by_number_or_name(spec, number):
    assert curet_sample(spec) == number


@pytest.mark.parametrize("spec", [None, "", "silk", "corduroy2"])
def test_curet_sample_errors_list_the_fabrics(spec):
    with pytest.raises(KesbrdfError) as exc:
        curet_sample(spec)
    msg = str(exc.value)
    assert msg.startswith("--sample:") and "\n" not in msg
    assert all(name in msg for name in FABRICS.values())


@pytest.mark.parametrize("given", ["abrdf.dat", "table.txt", "."])
def test_curet_values_are_the_published_ones(curet_dir, given):
    """Round trip to the measured inputs: every row is the extract's value at its geometry."""
    extract = read_measurement(CURET_EXTRACT)
    m = read_source(curet_dir / given, sample="corduroy")
    k = extract.channels.index("band_s42_corduroy")
    # both sides hold the published three decimals exactly
    np.testing.assert_allclose(m.values[:, 0], extract.values[:, k], rtol=0, atol=1e-12)
    # six decimals of radians in the rebuilt table: 5e-7 rad
    np.testing.assert_allclose(m.theta_r, extract.theta_r, atol=5e-7)
    assert m.psi is None and m.metadata["sample"] == "CUReT sample 42 (corduroy)"
    same = read_curet(curet_dir / "table.txt", curet_dir / "abrdf.dat", 42)
    np.testing.assert_array_equal(m.values, same.values)


def test_curet_needs_its_table_beside_it(tmp_path, curet_dir):
    lone = tmp_path / "lone"
    lone.mkdir()
    shutil.copy(curet_dir / "abrdf.dat", lone / "abrdf.dat")
    with pytest.raises(FormatError) as exc:
        read_source(lone / "abrdf.dat", sample=42)
    assert "expected table.txt" in str(exc.value) and "\n" not in str(exc.value)


def test_curet_sample_missing_from_the_file(curet_dir):
    with pytest.raises(KesbrdfError, match="expected a row for sample 44"):
        read_source(curet_dir, sample="linen")


# -- BRDF tables ------------------------------------------------------------------------------
def test_rgl_is_sampled_at_the_protocol_geometries():
    reader = RGLTensorBRDF(RGL_FELT, parameterised_by="viewer")
    for protocol, rows in (("paper", 116), ("dense", 900)):
        m = read_source(RGL_FELT, protocol=protocol)
        assert len(m) == rows and m.psi is not None and m.channels == ("R", "G", "B")
        wi, wr = _directions(m)
        # the values are the reader's own at those geometries (same code, same float64 path)
        np.testing.assert_allclose(m.values, reader(wi, wr), rtol=1e-12)
    assert m.sha256 == reader.sha256 and "acrylic_felt_white_rgb.bsdf" in m.metadata["resampled_from"]
    assert "White acrylic felt" in m.metadata["sample"]


def test_rgl_felt_reads_the_same_at_every_orientation():
    """Physics: the felt was measured isotropic, so ψ = 0, 45, 90, 135 see the same values.

    Rows with the viewer at the pole are left out: there the tensor format's isotropic
    convention measures φ_m from an undefined φ_p (measured 7.7 % at θ_i = 84°).  Elsewhere
    the four orientations agree to 0.3 % (the reader's φ interpolation in float32 tables).
    """
    m = read_source(RGL_FELT, protocol="paper")
    psi = np.round(np.degrees(m.psi)).astype(int)
    ok = np.degrees(np.minimum(m.theta_i, m.theta_r)) > 1.0
    base = m.values[(psi == 0) & ok]
    for p in (45, 90, 135):
        np.testing.assert_allclose(m.values[(psi == p) & ok], base, rtol=5e-3)


def test_merl_matches_the_brdf_it_was_written_from(merl_path):
    m = read_source(merl_path)
    wi, wr = _directions(m)
    truth = MERL_TRUTH(wi, wr)
    rel = np.abs(m.values - truth) / truth
    assert np.max(rel) < MERL_NEAREST_BIN_RTOL
    assert m.metadata["sample"] == "ward (ward.binary)"


def test_options_that_do_not_apply_are_refused(curet_dir):
    with pytest.raises(KesbrdfError, match=r"^--sample: applies to CUReT input only"):
        read_source(CURET_EXTRACT, sample=42)
    with pytest.raises(KesbrdfError, match=r"^--protocol: applies to BRDF tables"):
        read_source(curet_dir, sample=42, protocol="dense")
    with pytest.raises(KesbrdfError, match=r"^--step-deg: applies to BRDF tables"):
        read_source(CURET_EXTRACT, step_deg=6.0)
    with pytest.raises(KesbrdfError, match=r"^--sample: applies to CUReT input only"):
        read_source(RGL_FELT, sample=1)


# -- references by path ------------------------------------------------------------------------
def test_make_reference_takes_table_paths(merl_path, rng):
    wi = spherical_to_cartesian(np.arccos(rng.uniform(0.2, 1, 200)), rng.uniform(0, 2 * np.pi, 200))
    wr = spherical_to_cartesian(np.arccos(rng.uniform(0.2, 1, 200)), rng.uniform(0, 2 * np.pi, 200))
    felt = make_reference(str(RGL_FELT))
    np.testing.assert_array_equal(felt(wi, wr), RGLTensorBRDF(RGL_FELT, parameterised_by="viewer")(wi, wr))
    light = make_reference(str(RGL_FELT), '{"parameterised_by": "light"}')
    assert light.parameterised_by == "light"
    np.testing.assert_array_equal(make_reference(str(merl_path))(wi, wr), reference_from_file(merl_path)(wi, wr))
    with pytest.raises(KesbrdfError, match="unknown parameter .alpha_x. of reference merl-file; it takes none"):
        make_reference(str(merl_path), '{"alpha_x": 0.1}')
    with pytest.raises(KesbrdfError, match="got a measurement-csv file"):
        make_reference(str(CURET_EXTRACT))
    with pytest.raises(FileNotFoundError):
        make_reference("no/such/felt.bsdf")
    with pytest.raises(KesbrdfError, match="expected one of ward"):
        make_reference("felt-white")
