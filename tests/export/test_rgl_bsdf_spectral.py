"""The spectral .bsdf (pbrt-v4): the RGB -> spectrum basis, and Mitsuba's spectral ``measured``."""

import importlib.util

import numpy as np
import pytest

from kesbrdf.export import spectra

HAS_MITSUBA = importlib.util.find_spec("mitsuba") is not None
GRID = dict(n_theta_i=5, n_phi_i=9, n=16, n_ndf=16)


def _mitsuba_in(variant):
    """(mi, dr, context manager running a block in ``variant``)."""
    from kesbrdf._drjit import import_mitsuba

    mi, dr = import_mitsuba("test")
    if mi.variant() is None:
        mi.set_variant("llvm_ad_rgb")  # variant_context needs a variant to restore
    return mi, dr, mi.variant_context(variant)


def test_basis_is_nonnegative_and_reproduces_rgb():
    b = spectra.basis()
    assert b.shape == (3, spectra.WAVELENGTHS.size) and b.min() >= 0
    # exact round trip under the module's observer (SLSQP equality tolerance)
    np.testing.assert_allclose(spectra.to_rgb(b, spectra.WAVELENGTHS), np.eye(3), atol=1e-6)
    # grey is nearly flat: within 16 % of 1 at every node (exactly flat is infeasible)
    assert np.all(np.abs(b.sum(axis=0) - 1) < 0.16)
    # linear, so table values above 1 keep their colour
    rgb = np.array([2.5, 1.0, 0.3])
    np.testing.assert_allclose(spectra.to_rgb(rgb @ b, spectra.WAVELENGTHS), rgb, atol=1e-5)


@pytest.mark.render
@pytest.mark.skipif(not HAS_MITSUBA, reason="needs mitsuba")
def test_analytic_observer_agrees_with_mitsubas_cie_tables():
    """Wyman et al.'s fit vs Mitsuba's tabulated CIE 1931: the basis' RGB within 3 %."""
    mi, _, ctx = _mitsuba_in("scalar_spectral")
    lam = np.arange(360.0, 831.0, 1.0)
    with ctx:
        xyz = np.array([list(mi.cie1931_xyz(float(l))) for l in lam])
    ours = spectra.cie_xyz(lam)
    assert np.abs(ours - xyz).max() < 0.03 * xyz.max()
    hats = np.stack([np.interp(lam, spectra.WAVELENGTHS, row) for row in spectra.basis()])
    rgb = hats @ xyz @ spectra.XYZ_TO_RGB.T
    rgb /= (np.ones_like(lam) @ xyz @ spectra.XYZ_TO_RGB.T)
    assert np.abs(rgb - np.eye(3)).max() < 0.03


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    from kesbrdf.export import export
    from kesbrdf.measure.gonio import measure
    from kesbrdf.models.kes import fit
    from kesbrdf.references.ward import AnisotropicWard

    model = fit(measure(AnisotropicWard(0.12, 0.3, rho_d=[0.3, 0.12, 0.05], rho_s=0.1)))
    root = tmp_path_factory.mktemp("spec")
    rgb = export(model, "rgl-bsdf", root / "m.bsdf", check=False, **GRID)
    spec = export(model, "rgl-bsdf-spectral", root / "m_spec.bsdf", check=False, **GRID)
    return rgb.paths[0], spec.paths[0]


def test_spectral_file_back_to_rgb_is_the_rgb_file(files, rng):
    from kesbrdf.io.tensor_file import read_tensor_file
    from kesbrdf.references.rgl_tensor import RGLTensorBRDF

    f = read_tensor_file(files[1])
    assert "rgb" not in f and f["spectra"].shape[2] == f["wavelengths"].size == spectra.WAVELENGTHS.size
    assert np.isclose(f["phi_i"][-1] - f["phi_i"][0], 2 * np.pi)  # reduction 1 for pbrt-v4
    v = rng.normal(size=(2000, 3))
    v[:, 2] = np.abs(v[:, 2]) + 0.2
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    wi, wr = v[:1000], v[1000:]
    a = RGLTensorBRDF(files[0])(wi, wr)
    b = spectra.to_rgb(RGLTensorBRDF(files[1])(wi, wr), f["wavelengths"])
    np.testing.assert_allclose(b, a, rtol=1e-4, atol=1e-6 * a.max())


@pytest.mark.render
@pytest.mark.skipif(not HAS_MITSUBA, reason="needs mitsuba")
def test_mitsuba_spectral_measured_reads_it(files, rng):
    """Mitsuba's spectral ``measured`` at four node wavelengths = the numpy reader there."""
    from kesbrdf.references.rgl_tensor import RGLTensorBRDF

    mi, dr, ctx = _mitsuba_in("llvm_ad_spectral")
    ref = RGLTensorBRDF(files[1])
    nodes = [3, 6, 9, 12]
    lam = [float(spectra.WAVELENGTHS[k]) for k in nodes]
    v = rng.normal(size=(2000, 3))
    v[:, 2] = np.abs(v[:, 2]) + 0.2
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    wi, wo = v[:1000], v[1000:]
    with ctx:
        bsdf = mi.load_dict({"type": "measured", "filename": str(files[1])})
        si = dr.zeros(mi.SurfaceInteraction3f, len(wi))
        a, b = wi.T.astype(np.float32), wo.T.astype(np.float32)
        si.wi = mi.Vector3f(mi.Float(a[0]), mi.Float(a[1]), mi.Float(a[2]))
        si.sh_frame = mi.Frame3f(mi.Vector3f(0.0, 0.0, 1.0))
        si.wavelengths = mi.Spectrum(*lam)
        got = np.array(bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(mi.Float(b[0]), mi.Float(b[1]), mi.Float(b[2]))))
    want = ref.eval_cosine(wi, wo)[:, nodes].T
    assert np.percentile(np.abs(got - want) / np.abs(want).max(), 99.9) < 1e-5
