"""Importers: RGL tensor files read in numpy, MERL .binary files, as reference BRDFs."""

import importlib.util

import numpy as np
import pytest

from kesbrdf.errors import FormatError
from kesbrdf.references.registry import SHIPPED_RGL_DIR
from source_helpers import merl_bin_centres, pairs_from_half_diff, write_merl

FELT = SHIPPED_RGL_DIR / "acrylic_felt_white_rgb.bsdf"
HAS_MITSUBA = importlib.util.find_spec("mitsuba") is not None


def _dirs(rng, n, min_cos=0.0):
    v = rng.normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2])
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return v[v[:, 2] > min_cos]


# -- RGL tensor files without Mitsuba ---------------------------------------------------
def test_numpy_reader_reads_the_felt():
    from kesbrdf.references.rgl_tensor import RGLTensorBRDF

    felt = RGLTensorBRDF(FELT)
    assert felt.channels == ("R", "G", "B") and felt.isotropic and felt.jacobian
    assert felt.description.startswith("White acrylic felt")
    # a white felt: albedo-like values, f_r·π around 0.5-1 at normal incidence and view
    f = felt([[0, 0, 1.0]], [[0.3, 0.0, np.sqrt(1 - 0.09)]])
    assert np.all((0.1 < f * np.pi) & (f * np.pi < 1.5))


@pytest.mark.render
@pytest.mark.skipif(not HAS_MITSUBA, reason="needs mitsuba (kesbrdf[render])")
@pytest.mark.parametrize("parameterised_by", ["light", "viewer"])
def test_numpy_reader_equals_mitsuba_on_the_felt(rng, parameterised_by):
    """Same algorithm as Mitsuba's measured plugin: agreement to float32 round-off.

    Measured on 20 000 pairs: median 3e-7, p99 6e-5 relative; the worst (2 %) is on
    values 1e-5 of the peak at 89.6° where float32 acos/asin lose digits.
    """
    from kesbrdf.references.rgl import RGLMeasured
    from kesbrdf.references.rgl_tensor import RGLTensorBRDF

    wi, wr = _dirs(rng, 6000), _dirs(rng, 6000)
    n = min(len(wi), len(wr))
    wi, wr = wi[:n], wr[:n]
    a = RGLMeasured(FELT, parameterised_by)(wi, wr)
    b = RGLTensorBRDF(FELT, parameterised_by)(wi, wr)
    rel = np.abs(b - a) / np.maximum(np.abs(a), 1e-3 * np.abs(a).max())
    assert np.median(rel) < 1e-5 and np.percentile(rel, 99) < 1e-3


def test_numpy_reader_rejects_bad_files(tmp_path):
    from kesbrdf.io.tensor_file import read_tensor_file, write_tensor_file
    from kesbrdf.references.rgl_tensor import RGLTensorBRDF

    bad = tmp_path / "x.bsdf"
    bad.write_bytes(b"not a tensor file")
    with pytest.raises(FormatError, match="tensor_file"):
        RGLTensorBRDF(bad)
    fields = dict(read_tensor_file(FELT))
    del fields["vndf"]
    write_tensor_file(bad, fields)
    with pytest.raises(FormatError, match="missing vndf"):
        RGLTensorBRDF(bad)


# -- MERL .binary -------------------------------------------------------------------------
_bin_centres = merl_bin_centres
_pairs_from_half_diff = pairs_from_half_diff


@pytest.fixture(scope="module")
def merl_file(tmp_path_factory):
    """A full-size synthetic MERL file of an isotropic Ward + Lambert BRDF (35 MB, written here)."""
    from kesbrdf.references.ward import AnisotropicWard

    truth = AnisotropicWard(0.25, 0.25, rho_d=[0.3, 0.2, 0.1], rho_s=0.15)
    path = tmp_path_factory.mktemp("merl") / "ward.binary"
    missing = write_merl(path, truth)
    return path, truth, missing


def test_merl_exact_at_bin_centres(merl_file, rng):
    from kesbrdf.references.merl import MERLBinary

    path, truth, missing = merl_file
    merl = MERLBinary(path)
    assert merl.missing_fraction == pytest.approx(missing)
    th, td, pd = _bin_centres()
    pick = rng.integers(0, th.size, 5000)
    wi, wr = _pairs_from_half_diff(th.ravel()[pick], td.ravel()[pick], pd.ravel()[pick])
    ok = (wi[:, 2] > 1e-3) & (wr[:, 2] > 1e-3)
    np.testing.assert_allclose(merl(wi[ok], wr[ok]), truth(wi[ok], wr[ok]), rtol=1e-9)


def test_merl_is_isotropic_and_reciprocal(merl_file, rng):
    from kesbrdf.references.merl import MERLBinary

    merl = MERLBinary(merl_file[0])
    wi, wr = _dirs(rng, 3000, 0.1)[:1000], _dirs(rng, 3000, 0.1)[:1000]
    a = rng.uniform(0, 2 * np.pi, len(wi))
    rot = lambda v: np.stack([np.cos(a) * v[:, 0] - np.sin(a) * v[:, 1], np.sin(a) * v[:, 0] + np.cos(a) * v[:, 1], v[:, 2]], -1)
    # the binning is symmetric under rotation and swap except on bin boundaries
    assert np.mean(np.isclose(merl(rot(wi), rot(wr)), merl(wi, wr), rtol=1e-9)) > 0.98
    assert np.mean(np.isclose(merl(wr, wi), merl(wi, wr), rtol=1e-9)) > 0.98


def test_merl_random_pairs_match_the_analytic_brdf(merl_file, rng):
    """Nearest-bin reading of a smooth BRDF: measured median 5e-5 (the Lambert part is exact), p90 1.8 % (cos θ > 0.2)."""
    from kesbrdf.references.merl import MERLBinary

    path, truth, _ = merl_file
    wi, wr = _dirs(rng, 8000, 0.2)[:4000], _dirs(rng, 8000, 0.2)[:4000]
    rel = np.abs(MERLBinary(path)(wi, wr) - truth(wi, wr)) / truth(wi, wr)
    assert np.median(rel) < 0.01 and np.percentile(rel, 90) < 0.05


def test_merl_through_the_gonio_simulator(merl_file):
    from kesbrdf.measure.gonio import measure
    from kesbrdf.references.merl import MERLBinary

    m = measure(MERLBinary(merl_file[0]))
    assert np.all(np.isfinite(m.values)) and m.values.max() > 0


def test_merl_rejects_bad_files(tmp_path):
    from kesbrdf.references.merl import MERLBinary

    p = tmp_path / "x.binary"
    p.write_bytes(np.array([90, 90, 360], "<i4").tobytes())
    with pytest.raises(FormatError, match="expected MERL dimensions"):
        MERLBinary(p)
    p.write_bytes(np.array([90, 90, 180], "<i4").tobytes() + b"\0" * 16)
    with pytest.raises(FormatError, match="bytes"):
        MERLBinary(p)
