"""The staple geometry at its valid tilt nodes only (kesbrdf.models.fibre_physics._StapleEntry)
gives the same numbers, bit for bit, as over the whole (N, U) grid, and a fit is unchanged.

docs/decisions.md, "The default fit's speed": the fibre prior's multistart is sensitive to
the last bit (a 1-ulp change of the data moved the fitted values of the staple/staple fit
below by up to 1.8 %), so the speed-ups are held to exact equality, not to a tolerance.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from kesbrdf.measure.measurement import Measurement
from kesbrdf.models import fibre_physics as fp
from kesbrdf.models.fibre_physics import PriorSpec, evaluate_batch, evaluate_with_jacobian, fit_prior

SEED = 7
TWISTS_DEG = (4.0, -4.0, 20.0, -35.0, 60.0, -80.0)


def hemisphere(n, rng):
    v = rng.normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2]) + 0.05
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def full_grid(base, psi):
    """(ok, G, cos φ, ∂G/∂ψ, ∂cos φ/∂ψ) over the whole (K, N, U) grid: the computation before
    the valid-node one, kept here as the reference (the same formulas as _staple_geometry's docstring)."""
    su, cu, Bq, root, v0, hx, hy, hz, wi_, wr_, ns = base[:11]
    ix, iy, iz = wi_
    rx, ry, rz = wr_
    e = lambda a: a[..., None]  # noqa: E731
    tpsi = e(np.tan(psi))
    with np.errstate(invalid="ignore", divide="ignore"):
        D = Bq / (root * tpsi)
    ok = np.abs(D) < 1.0
    v = v0 + np.arccos(np.clip(D, -1.0, 1.0))
    v = np.where(v > np.pi, v - 2 * np.pi, v)
    ok &= np.abs(v) < np.pi / 2
    sv, cv = np.sin(v), np.cos(v)
    nx, ny, nz = sv, su * cv, cu * cv
    ci = nx * ix + ny * iy + nz * iz
    cr = nx * rx + ny * ry + nz * rz
    nh_signed = nx * hx + ny * hy + nz * hz
    nh = np.abs(nh_signed)
    sp, cp = e(np.sin(psi)), e(np.cos(psi))
    tx = -cv * sp
    ty = cu * cp + su * sv * sp
    tz = -su * cp + cu * sv * sp
    cphi = fp._cos_phi(*wi_, *wr_, tx, ty, tz)
    AS = fp._seeliger(ci, cr)
    nhf = np.maximum(nh, 1e-9)
    scale = 1.0 / (ns * np.abs(sp))
    with np.errstate(invalid="ignore", divide="ignore"):
        G = np.where(ok, AS / nhf, 0.0) * scale
        dv = np.where(ok, D / (np.sqrt(np.maximum(1.0 - D * D, 1e-300)) * sp * cp), 0.0)
        dnx, dny, dnz = cv * dv, -su * sv * dv, -cu * sv * dv
        dci = dnx * ix + dny * iy + dnz * iz
        dcr = dnx * rx + dny * ry + dnz * rz
        dnh = np.where(nh > 1e-9, np.sign(nh_signed) * (dnx * hx + dny * hy + dnz * hz), 0.0)
        pos = (ci > 0) & (cr > 0)
        dAS = np.where(pos, (cr * cr * dci + ci * ci * dcr) / np.where(pos, (ci + cr) ** 2, 1.0), 0.0)
        dG = np.where(ok, dAS / nhf - AS * dnh / (nhf * nhf), 0.0) * scale - G * (cp / sp)
    dt = (-cv * cp + sv * sp * dv, -cu * sp + su * sv * cp + su * cv * sp * dv, su * sp + cu * sv * cp + cu * cv * sp * dv)
    dcphi = np.where(ok, fp._cos_phi_derivative(wi_, wr_, (tx, ty, tz), dt), 0.0)
    return ok, G, cphi, dG, dcphi


def frame_base(wi, wr, alpha):
    norm_sum, h, _, _ = fp._base(wi, wr)
    return fp._staple_base(*(q[None] for q in fp._frames(h, wi, wr, alpha)), norm_sum[None])


@pytest.mark.parametrize("alpha", [0.0, math.pi / 2])
def test_valid_nodes_equal_the_full_grid(alpha):
    """Exact (0 ulp): each valid node goes through the same operations in the same order."""
    rng = np.random.default_rng(SEED)
    wi, wr = hemisphere(80, rng), hemisphere(80, rng)
    base = frame_base(wi, wr, alpha)
    for deg in TWISTS_DEG:
        psi = np.array([[math.radians(deg)]])
        ok, G, cphi, dG, dcphi = full_grid(base, psi)
        entry = fp._StapleEntry(base, psi)
        assert np.array_equal(entry.k, np.flatnonzero(ok)), deg
        assert 0 < entry.k.size < ok.size, deg  # both kinds of node are exercised
        assert np.array_equal(entry.cphi_k, cphi.reshape(-1)[entry.k]), deg
        assert np.array_equal(entry.G, G), deg
        new_dG, new_dcphi = entry.derivatives()
        assert np.array_equal(new_dG, dG), deg
        assert np.array_equal(new_dcphi, dcphi), deg


@pytest.mark.parametrize("kinds", [("filament", "staple"), ("staple", "staple")])
def test_one_vector_paths_equal_the_full_grid(kinds):
    """evaluate_batch for one vector (valid nodes) equals its path for several (the whole grid),
    and evaluate_with_jacobian's staple columns equal the full-grid formulas, exactly."""
    rng = np.random.default_rng(SEED)
    spec = PriorSpec(kinds, 1)
    wi, wr = hemisphere(70, rng), hemisphere(70, rng)
    idx = spec.index()
    x = np.zeros(len(idx))
    for name, value in {"log_kd_0": -4.0, "warp_log_ks_0": -1.0, "weft_log_ks_0": -0.5, "warp_u_lo": -0.5,
                        "warp_u_hi": 0.4, "weft_u_lo": -0.3, "weft_u_hi": 0.6, "warp_log_s": math.log(0.1),
                        "weft_log_s": math.log(0.15), "warp_c2": -1.0, "weft_c2": 0.3, "warp_rho": 0.3,
                        "weft_rho": -0.2, "warp_psi": math.radians(25), "weft_psi": math.radians(-40)}.items():
        if name in idx:
            x[idx[name]] = value
    other = x.copy()
    other[idx["weft_psi"]] += 0.1
    one = evaluate_batch(spec, x[None], wi, wr, cache={})[0]
    assert np.array_equal(one, evaluate_batch(spec, np.vstack([x, other]), wi, wr, cache={})[0])

    f, J = evaluate_with_jacobian(spec, x, wi, wr, cache={})
    norm_sum, _, Phi, _ = fp._base(wi, wr)
    ok, G, cphi, dG, dcphi = (a[0] for a in full_grid(frame_base(wi, wr, math.pi / 2), np.array([[x[idx["weft_psi"]]]])))
    lo, hi, log_s, c2, rho = (x[idx[f"weft_{n}"]] for n in ("u_lo", "u_hi", "log_s", "c2", "rho"))
    P, dP = fp._profile_derivatives(fp.U_NODES, lo, hi, log_s, c2)
    Nl = fp._lobe_rho(cphi, rho)
    NG = Nl * G
    dS_psi = (fp._lobe_cos_derivative(cphi, rho) * dcphi * G + Nl * dG) @ P
    dS = np.concatenate([(NG @ dP.T).T, ((fp._lobe_rho_derivative(cphi, rho) * G) @ P)[None], dS_psi[None]]) * fp.DU
    cols = [idx[f"weft_{n}"] for n in ("u_lo", "u_hi", "log_s", "c2", "rho", "psi")]
    ks = math.exp(x[idx["weft_log_ks_0"]])
    assert np.array_equal(J[:, 0, cols], (Phi * dS).T * ks)
    assert np.array_equal(J[:, 0, idx["weft_log_ks_0"]], Phi * (NG @ P * fp.DU * ks))


#: fit_prior(kinds=("staple", "staple")) on GOLDEN_TRUTH's 60 paper-protocol samples at 2 %
#: log noise (seed 5), as fitted before the valid-node geometry (commit 658eb9c).  The
#: fitted model's values on the samples are compared: θ itself has flat directions (k_d at
#: 1e-6 of the peak) where it moves freely without changing the fit.
GOLDEN_TRUTH = [math.log(0.02), math.log(0.5), -0.5, 0.6, math.log(math.radians(6)), -1.0, 0.3, math.radians(25),
                math.log(0.3), -0.4, 0.4, math.log(math.radians(8)), 0.0, 0.1, math.radians(30)]
GOLDEN_THETA = [-13.309492416304671, -0.8712644363837203, -0.3986741785350438, 0.45038152535499915,
                -2.6504395681915733, 1.9999948348742649, 0.2486954568426095, 0.46107767673461875,
                -1.2568537607606707, -0.6368951959122551, 0.6181396892166935, -2.3353928589637003,
                -1.0916773635050872, -0.045673856583227423, 0.7294028168048364]
GOLDEN_COST = 0.013420770368412353
#: The fit is the same sequence of floating-point operations as then, so on the build it
#: was recorded on (numpy, SciPy, one OpenBLAS thread, and the CPU features numpy dispatches
#: its SIMD loops to) its values agree to the last bit; 1e-12 leaves room only for a
#: libm/BLAS that rounds differently.  A change of the arithmetic shows far above it: a
#: 1-ulp change of the data moved these values by up to 1.8 % (docs/decisions.md).
GOLDEN_RTOL = 1e-12
#: Where a build was recorded, its own fit (θ, cost) is held to GOLDEN_RTOL there.  numpy
#: and SciPy are not pinned and numpy's exp/log loops differ by CPU (AVX-512 or AVX2), so
#: elsewhere the test checks the fit's quality instead: values and cost within
#: REBUILD_RTOL of the first record, above the 1.8 % a 1-ulp change moved them and far
#: below what a broken geometry gives.  The first record (commit 658eb9c) has no CPU
#: features: on an AVX2-only machine with the same numpy and SciPy the fit differs by 1.0 %
#: in values and 1.0 % in cost, so those versions alone do not make a build.
GOLDEN_BUILDS = [
    {"numpy": "2.4.6", "scipy": "1.17.1", "cpu": None, "theta": GOLDEN_THETA, "cost": GOLDEN_COST},
    {"numpy": "2.4.6", "scipy": "1.17.1",
     "cpu": "AVX AVX2 BMI BMI2 CX16 F16C FMA3 LAHF LZCNT MMX MOVBE POPCNT SSE SSE2 SSE3 SSE41 SSE42 SSSE3 VAES "
            "VPCLMULQDQ X86_V2 X86_V3",
     "theta": [-6.8944119520285305, -0.8986515574991395, -0.40774812470617117, 0.46000144990619324,
               -2.66339420802941, 1.9983094988193117, 0.2384342634128569, 0.4664859905110237, -1.277881343900259,
               -0.47605634172455913, 0.46597178182291477, -2.3981394084094845, 0.966096610554354,
               -0.0421176091854787, 0.7255777203392727],
     "cost": 0.013551419319615015},
]
REBUILD_RTOL = 0.05


def _build_key() -> dict:
    import scipy

    try:
        from numpy._core._multiarray_umath import __cpu_features__ as features
    except ImportError:  # numpy < 2
        from numpy.core._multiarray_umath import __cpu_features__ as features
    return {"numpy": np.__version__, "scipy": scipy.__version__,
            "cpu": " ".join(sorted(k for k, on in features.items() if on))}


def test_staple_fit_equals_the_fit_before():
    rng = np.random.default_rng(5)
    spec = PriorSpec(("staple", "staple"), 1)
    psi = np.repeat(np.radians([0, 45, 90, 135]), 15)
    ti = np.tile(np.radians(np.linspace(2, 88, 15)), 4)
    tr = np.pi / 2 - ti
    m = Measurement.in_plane(psi, ti, tr, np.ones((60, 1)))
    y = evaluate_batch(spec, np.array(GOLDEN_TRUTH)[None], m.wi, m.wr)[0] * np.exp(0.02 * rng.normal(size=(60, 1)))
    m = Measurement.in_plane(psi, ti, tr, y)
    prior = fit_prior(m, kinds=("staple", "staple"))
    key = _build_key()
    same = [g for g in GOLDEN_BUILDS if all(g[k] == key[k] for k in ("numpy", "scipy", "cpu"))]
    record, rtol = (same[0], GOLDEN_RTOL) if same else (GOLDEN_BUILDS[0], REBUILD_RTOL)
    golden = evaluate_batch(spec, np.array(record["theta"])[None], m.wi, m.wr)[0]
    np.testing.assert_allclose(prior(m.wi, m.wr), golden, rtol=rtol, atol=0)
    assert prior.report["variants"]["staple/staple"]["cost"] == pytest.approx(record["cost"], rel=rtol)
