"""The numpy Marginal2D warp against Mitsuba's own (mi.MarginalContinuous2D0/2/3), and the
tensor-file container round trip."""

import importlib.util

import numpy as np
import pytest

from kesbrdf.references.marginal2d import Marginal2D
from kesbrdf.references.registry import SHIPPED_RGL_DIR

HAS_MITSUBA = importlib.util.find_spec("mitsuba") is not None
FELT = SHIPPED_RGL_DIR / "acrylic_felt_white_rgb.bsdf"
#: float32 (Mitsuba) vs float64 (here): positions agree to this; the sample() quadratic
#: loses ~4 digits where a segment's density is nearly constant.
POS_TOL = {"sample": 1e-4, "invert": 2e-6}
PDF_RTOL = 2e-4


def _data(rng, shape):
    return rng.uniform(0.05, 2.0, shape).astype(np.float32)


def test_sample_invert_roundtrip_and_density(rng):
    w = Marginal2D(_data(rng, (3, 4, 7, 9)), [[-1, 0, 2.5], [0, 0.3, 0.4, 1.2]])
    u = rng.uniform(0, 1, (2000, 2))
    par = (rng.uniform(-1.5, 3, 2000), rng.uniform(-0.1, 1.3, 2000))
    x, pdf = w.sample(u, par)
    back, pdf2 = w.invert(x, par)
    # exact but where a segment counts as constant (|v0 - v1| < 1e-4 (v0 + v1), Mitsuba's rule)
    np.testing.assert_allclose(back, np.clip(u, 2**-24, 1 - 2**-24), atol=1e-5)
    np.testing.assert_allclose(pdf, w.eval(x, par), rtol=1e-9)
    np.testing.assert_allclose(pdf2, pdf, rtol=1e-9)
    # normalised: the density integrates to one for any parameter (midpoint rule)
    g = (np.arange(200) + 0.5) / 200
    X, Y = np.meshgrid(g, g)
    pts = np.stack([X.ravel(), Y.ravel()], -1)
    for p in [(0.3, 0.35), (2.0, 1.0)]:
        total = w.eval(pts, (np.full(len(pts), p[0]), np.full(len(pts), p[1]))).mean()
        assert total == pytest.approx(1.0, abs=1e-4)


@pytest.mark.render
@pytest.mark.skipif(not HAS_MITSUBA, reason="needs mitsuba")
@pytest.mark.parametrize("dim", [0, 2, 3])
@pytest.mark.parametrize("normalize", [True, False])
def test_matches_mitsuba(rng, dim, normalize):
    from kesbrdf._drjit import import_mitsuba

    mi, dr = import_mitsuba("test")
    if mi.variant() is None:
        mi.set_variant("llvm_ad_rgb")
    with mi.variant_context("llvm_ad_rgb"):
        res = [3, 4, 2][:dim]
        values = [np.sort(rng.uniform(-1, 2, n)).astype(np.float32) for n in res]
        data = _data(rng, tuple(res) + (6, 11))
        cls = {0: mi.MarginalContinuous2D0, 2: mi.MarginalContinuous2D2, 3: mi.MarginalContinuous2D3}[dim]
        theirs = cls(data, [v.tolist() for v in values], normalize=normalize) if dim else cls(data, normalize=normalize)
        ours = Marginal2D(data, values, normalize=normalize)
        n = 2000
        u = rng.uniform(0, 1, (n, 2))
        par = [rng.uniform(v[0] - 0.2, v[-1] + 0.2, n) for v in values]
        U = mi.Point2f(u[:, 0].astype(np.float32), u[:, 1].astype(np.float32))
        args = (U, getattr(mi, f"Vector{dim}f")(*[p.astype(np.float32) for p in par])) if dim else (U,)
        for op in ("sample", "invert"):
            pos, pdf = getattr(theirs, op)(*args)
            mine, mpdf = getattr(ours, op)(u, par)
            assert np.abs(np.array(pos).T - mine).max() < POS_TOL[op], op
            np.testing.assert_allclose(np.array(pdf), mpdf, rtol=PDF_RTOL)
        np.testing.assert_allclose(np.array(theirs.eval(*args)), ours.eval(u, par), rtol=PDF_RTOL)


def test_tensor_file_roundtrip_is_byte_identical(tmp_path):
    from kesbrdf.io.tensor_file import read_tensor_file, write_tensor_file

    fields = read_tensor_file(FELT)
    out = write_tensor_file(tmp_path / "copy.bsdf", dict(fields))
    back = read_tensor_file(out)
    assert list(back) == list(fields)
    for k in fields:
        assert back[k].dtype == fields[k].dtype and np.array_equal(back[k], fields[k])
    # the reference writer's layout (8-byte aligned blobs in field order) gives the same bytes
    assert out.read_bytes() == FELT.read_bytes()


def test_tensor_file_roundtrip_of_every_dtype(tmp_path, rng):
    from kesbrdf.io.tensor_file import DTYPE_CODES, read_tensor_file, write_tensor_file

    fields = {"description": "ünïcode text"}
    for k, dt in enumerate(DTYPE_CODES):
        shape = tuple(int(v) for v in rng.integers(1, 5, size=int(rng.integers(0, 4))))
        fields[f"f{k}"] = (rng.normal(size=shape) * 50).astype(dt)
    back = read_tensor_file(write_tensor_file(tmp_path / "t.bsdf", fields))
    assert bytes(back["description"]).decode("utf-8") == "ünïcode text"
    for k, dt in enumerate(DTYPE_CODES):
        a = back[f"f{k}"]
        assert a.dtype == dt and a.shape == fields[f"f{k}"].shape and np.array_equal(a, fields[f"f{k}"])
