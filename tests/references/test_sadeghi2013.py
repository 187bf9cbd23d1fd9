"""Tests of the Sadeghi et al. (2013) microcylinder cloth BRDF.

Reference numbers are the sanity checks of kesbrdf's implementation notes on the paper
(a numpy transcription of those notes, so they test an implementation *of the notes*; the
paper's text was not available; :mod:`kesbrdf.references.sadeghi2013` states what the
notes decide). Each test names the check ("§8 G": golden values, "§8 B": non-reciprocity).
"""

from __future__ import annotations

import numpy as np
import pytest

from kesbrdf.errors import KesbrdfError
from kesbrdf.geometry import spherical_to_cartesian
from kesbrdf.references.sadeghi2013 import (
    BLACK_SATIN_DYE_FACTOR,
    PRESET_NAMES,
    PRESETS,
    Fabric,
    Family,
    Sadeghi2013,
    black_satin,
    black_satin_fabric,
    fresnel_dielectric,
)

# Printed precision of the notes' tables: §8 G has 5 decimals, so its values are exact to
# half a unit in the last place (5e-6) plus float noise.
GOLDEN_ATOL = 6e-6
# §8 C, D and E print 3 decimals: half a unit (5e-4) plus the quadrature error of the
# 96 × 192 rule, measured below 1e-5 for these presets (grid 128 × 256 agrees to 1e-5).
TABLE_ATOL = 6e-4
# Exact symmetry: the kernel and the symmetrised BRDF are the same floating-point
# expressions with the two directions swapped, so they agree to a few ulps.
SYMMETRY_RTOL = 1e-12


def sph(theta_deg, phi_deg):
    return spherical_to_cartesian(np.radians(theta_deg), np.radians(phi_deg))


def white(name: str) -> Fabric:
    """Preset with A = 1 in both families (white furnace, §8 D)."""
    return PRESETS[name].with_albedo((1.0, 1.0, 1.0), (1.0, 1.0, 1.0))


# --- §8 G golden values -----------------------------------------------------------------

GOLDEN = [
    # preset, ω_i (θ°, φ°), ω_r (θ°, φ°), control-point f_r, arclength-64 f_r
    ("linen", (30, 180), (30, 0), (0.01785, 0.05539, 0.06791), (0.04300, 0.09435, 0.11146)),
    ("linen", (0, 0), (0, 0), (0.01664, 0.05338, 0.06563), (0.04090, 0.08829, 0.10408)),
    ("satin", (30, 180), (30, 0), (0.15247, 0.13322, 0.13109), (0.16499, 0.14162, 0.13903)),
    ("satin", (45, 200), (20, 90), (0.04223, 0.02936, 0.02793), (0.03612, 0.02522, 0.02401)),
    ("silk_shot", (45, 200), (20, 90), (0.17330, 0.21182, 0.13316), (0.14995, 0.15980, 0.10177)),
    ("silk_crepe", (0, 0), (0, 0), (0.03400, 0.03269, 0.00925), (0.04845, 0.04666, 0.01439)),
]


@pytest.mark.parametrize("preset, wi, wr, f_control, f_arclength", GOLDEN)
def test_golden_values_of_the_published_forward_model(preset, wi, wr, f_control, f_arclength):
    wi, wr = sph(*wi), sph(*wr)
    control = Sadeghi2013(preset, sampling="control_points", reciprocal=False)
    arclength = Sadeghi2013(preset, sampling="arclength", n_samples=64, reciprocal=False)
    np.testing.assert_allclose(control(wi, wr), f_control, rtol=0, atol=GOLDEN_ATOL)
    np.testing.assert_allclose(arclength(wi, wr), f_arclength, rtol=0, atol=GOLDEN_ATOL)


# --- §8 A, B: symmetry and (non-)reciprocity ---------------------------------------------


@pytest.mark.parametrize("sampling", ["control_points", "arclength"])
def test_per_tangent_kernel_is_symmetric(random_directions, sampling):
    wi, wr = random_directions(2000), random_directions(2000)
    for name in PRESET_NAMES:
        brdf = Sadeghi2013(name, sampling=sampling, n_samples=16)
        k_ir = brdf.kernel(wi, wr)
        k_ri = brdf.kernel(wr, wi)
        assert k_ir.shape == (brdf.alphas[0].size + brdf.alphas[1].size, 2000, 3)
        scale = np.max(np.abs(k_ir))
        assert np.max(np.abs(k_ir - k_ri)) <= SYMMETRY_RTOL * scale, name


# §8 B: the notes measure 5–95 % ranges of f(i,r)/f(r,i) of 0.36–2.8 (linen) and
# 0.30–3.4 (satin) with their own random-pair distribution; ours (uniform on the
# hemisphere, arclength 64) gives 0.57–1.78 and 0.37–2.68. The test asserts what must
# hold for any pair distribution: a median of 1, a clear spread, and the documented order
# of magnitude.
NONRECIPROCITY_MEDIAN = (0.9, 1.1)
NONRECIPROCITY_SPREAD = (0.8, 1.4)  # 5 % percentile below, 95 % percentile above
NONRECIPROCITY_BOUND = (0.2, 5.0)  # neither percentile beyond the notes' order of magnitude


@pytest.mark.parametrize("preset", ["linen", "satin"])
def test_published_model_is_not_reciprocal_within_documented_range(random_directions, preset):
    wi, wr = random_directions(4000), random_directions(4000)
    brdf = Sadeghi2013(preset, n_samples=32, reciprocal=False)
    forward, backward = brdf(wi, wr)[:, 1], brdf(wr, wi)[:, 1]
    keep = (forward > 0) & (backward > 0)
    assert keep.mean() > 0.95
    p5, p50, p95 = np.percentile(forward[keep] / backward[keep], [5, 50, 95])
    assert NONRECIPROCITY_MEDIAN[0] < p50 < NONRECIPROCITY_MEDIAN[1]
    assert p5 < NONRECIPROCITY_SPREAD[0] and p95 > NONRECIPROCITY_SPREAD[1]
    assert p5 > NONRECIPROCITY_BOUND[0] and p95 < NONRECIPROCITY_BOUND[1]


@pytest.mark.parametrize("preset", PRESET_NAMES)
def test_symmetrised_variant_is_exactly_reciprocal(random_directions, preset):
    wi, wr = random_directions(3000), random_directions(3000)
    brdf = Sadeghi2013(preset, n_samples=16)  # reciprocal=True is the default
    assert brdf.reciprocal
    f_ir, f_ri = brdf(wi, wr), brdf(wr, wi)
    np.testing.assert_allclose(f_ir, f_ri, rtol=SYMMETRY_RTOL, atol=0)
    published = Sadeghi2013(preset, n_samples=16, reciprocal=False)
    np.testing.assert_allclose(
        f_ir, 0.5 * (published(wi, wr) + published(wr, wi)), rtol=SYMMETRY_RTOL, atol=1e-300
    )


# --- §8 C: Q at normal view -----------------------------------------------------------------

Q_NORMAL_VIEW = {  # preset: (control points, arclength N = 64)
    "linen": (0.938, 0.979),
    "silk_crepe": (0.864, 0.894),
    "satin": (0.921, 0.946),
    "satin_back": (0.954, 0.952),
    "silk_shot": (0.919, 0.946),
    "velvet": (0.304, 0.316),
}


@pytest.mark.parametrize("preset", PRESET_NAMES)
def test_Q_at_normal_view(preset):
    q_control, q_arclength = Q_NORMAL_VIEW[preset]
    up = np.array([0.0, 0.0, 1.0])
    assert Sadeghi2013(preset, sampling="control_points").Q(up) == pytest.approx(q_control, abs=TABLE_ATOL)
    assert Sadeghi2013(preset, n_samples=64).Q(up) == pytest.approx(q_arclength, abs=TABLE_ATOL)
    # at normal view P = cos α, so Q = Σ a_j mean(cos α) + gap (§8 C)
    brdf = Sadeghi2013(preset, n_samples=64)
    gap = 1.0 - brdf.fabric.warp.a - brdf.fabric.weft.a
    expected = sum(f.a * np.cos(al).mean() for f, al in zip(brdf.fabric.families, brdf.alphas)) + gap
    assert brdf.Q(up) == pytest.approx(expected, rel=1e-14)


# --- §8 D, E: energy ------------------------------------------------------------------------

ALBEDO_GEOMETRIES = [(0, 0), (30, 0), (30, 90), (60, 0), (60, 90), (80, 0), (80, 90)]
WHITE_FURNACE = {  # §8 D, control points, published forward model (θ_r°, φ_r°) as above
    "linen": (0.818, 0.807, 0.807, 0.681, 0.681, 0.505, 0.505),
    "silk_crepe": (1.348, 1.309, 1.271, 1.187, 0.938, 0.954, 0.449),
    "satin": (1.667, 1.538, 1.525, 1.438, 1.009, 1.197, 0.398),
    "satin_back": (1.542, 1.394, 1.498, 1.118, 1.222, 0.667, 0.638),
    "silk_shot": (1.677, 1.602, 1.506, 1.419, 0.956, 1.172, 0.358),
    "velvet": (0.690, 0.811, 0.754, 0.815, 0.745, 0.827, 0.694),
}
# §8 D: "arclength sampling (N = 32) is within ±5 % of these, except linen at θ_r = 60°
# (+14 %) and velvet". Checked with a 6 % band for the quadrature and the notes' rounding.
ARCLENGTH_BAND = 0.06


@pytest.mark.parametrize("preset", PRESET_NAMES)
def test_white_furnace_albedo_table(albedo, preset):
    brdf = Sadeghi2013(white(preset), sampling="control_points", reciprocal=False)
    rho = np.array([albedo(brdf, sph(*g))[0] for g in ALBEDO_GEOMETRIES])
    np.testing.assert_allclose(rho, WHITE_FURNACE[preset], rtol=0, atol=TABLE_ATOL)
    # the published model is *not* energy-bounded at A = 1
    if preset in ("silk_crepe", "satin", "satin_back", "silk_shot"):
        assert rho[0] > 1.3


@pytest.mark.parametrize("preset", ["linen", "satin", "silk_shot"])
def test_white_furnace_albedo_arclength_close_to_control_points(albedo, preset):
    brdf = Sadeghi2013(white(preset), n_samples=32, reciprocal=False)
    for geometry, reference in zip(ALBEDO_GEOMETRIES, WHITE_FURNACE[preset]):
        if preset == "linen" and geometry[0] == 60:
            continue  # the notes' documented exception (0.775, +14 %)
        rho = albedo(brdf, sph(*geometry))[0]
        assert abs(rho / reference - 1.0) < ARCLENGTH_BAND, (geometry, rho, reference)


REAL_ALBEDO_NORMAL_VIEW = {  # §8 E, control points, published forward model
    "linen": (0.108, 0.244, 0.289),
    "silk_crepe": (0.226, 0.217, 0.068),
    "satin": (0.214, 0.169, 0.164),
    "satin_back": (0.237, 0.168, 0.161),
    "silk_shot": (0.246, 0.344, 0.196),
    "velvet": (0.023, 0.016, 0.012),
}
# Largest albedo the real presets reach over the view grid below: 0.353 (silk shot, green,
# published form; 0.341 symmetrised).
# The bound asserted is the physical one, 1, with no slack needed.
VIEW_GRID = [(t, p) for t in (0, 30, 60, 80) for p in (0, 45, 90, 135, 180, 270)]


@pytest.mark.parametrize("preset", PRESET_NAMES)
def test_real_presets_albedo_table_at_normal_view(albedo, preset):
    brdf = Sadeghi2013(preset, sampling="control_points", reciprocal=False)
    np.testing.assert_allclose(
        albedo(brdf, sph(0, 0)), REAL_ALBEDO_NORMAL_VIEW[preset], rtol=0, atol=TABLE_ATOL
    )


@pytest.mark.parametrize("reciprocal", [False, True])
@pytest.mark.parametrize("preset", PRESET_NAMES)
def test_real_presets_conserve_energy(albedo, preset, reciprocal):
    brdf = Sadeghi2013(preset, n_samples=16, reciprocal=reciprocal)
    for geometry in VIEW_GRID:
        rho = albedo(brdf, sph(*geometry), n_theta=64, n_phi=128)
        assert np.all(rho > 0) and np.all(rho <= 1.0), (geometry, rho)


# --- §8 F: the satin highlight ------------------------------------------------------------

PEAK_POSITION_TOL_DEG = 3.0  # scan step 1°, and the notes quote peaks to ±1°


def local_maxima(x, f):
    inner = (f[1:-1] > f[:-2]) & (f[1:-1] >= f[2:])
    return x[1:-1][inner], f[1:-1][inner]


def in_plane_scan(brdf, psi_deg, theta_i_deg=30.0, step=1.0):
    """f_r (green) with the light at θ_i in the plane ψ and the viewer scanned through it.

    Signed θ_r: positive on the far side from the light (azimuth ψ), negative on the
    light's side (azimuth ψ + 180°).
    """
    theta = np.arange(-89.0, 89.0 + step / 2, step)
    wi = sph(theta_i_deg, psi_deg + 180.0)
    wr = sph(np.abs(theta), np.where(theta >= 0, psi_deg, psi_deg + 180.0))
    return theta, brdf(wi, wr)[:, 1]


def test_satin_highlight_is_split_along_the_warp_floats():
    """§8 F: a segment tilted by α moves the mirror peak to 30° − 2α (warp plane)."""
    brdf = Sadeghi2013("satin", n_samples=64, reciprocal=False)
    theta, f = in_plane_scan(brdf, psi_deg=0.0)
    peaks, values = local_maxima(theta, f)
    # the flat float (α = 0) and the tilted ends α = +32° (30 − 64 = −34°)
    for expected, level in ((30.0, 0.141), (-33.0, 0.091)):
        k = np.argmin(np.abs(peaks - expected))
        assert abs(peaks[k] - expected) <= PEAK_POSITION_TOL_DEG
        assert values[k] == pytest.approx(level, abs=2e-3)
    # α = −32° would reflect to 94°: a rise toward grazing (0.143 at +87°)
    assert f[theta == 87.0][0] == pytest.approx(0.143, abs=2e-3)
    # deep dips between the peaks (≈ 0.024)
    dip = f[(theta > -30) & (theta < 20)].min()
    assert dip < 0.2 * f.max()


def test_satin_weft_plane_response_is_broad():
    """§8 F: in the weft plane the response is the smooth, broad cos(φ_d/2) lobe.

    The notes' numbers (0.113 near −25°, 0.008 at +87°) are reproduced by control-point
    sampling; with arclength sampling they are 0.124 and 0.011.
    """
    brdf = Sadeghi2013("satin", sampling="control_points", reciprocal=False)
    theta, f = in_plane_scan(brdf, psi_deg=90.0)
    assert f[theta == -25.0][0] == pytest.approx(0.113, abs=1e-3)
    assert f[theta == 87.0][0] == pytest.approx(0.008, abs=1e-3)
    # one broad maximum on the back-scatter side, no narrow highlight
    peaks, _ = local_maxima(theta, f)
    assert peaks.size == 1 and -40.0 < peaks[0] < 0.0
    assert np.all(f[np.abs(theta) <= 60] > 0.4 * f.max())


def half_max_width(x, f):
    """Width of the contiguous region around the maximum where f ≥ max/2."""
    k = np.argmax(f)
    above = f >= 0.5 * f[k]
    lo = k
    while lo > 0 and above[lo - 1]:
        lo -= 1
    hi = k
    while hi < f.size - 1 and above[hi + 1]:
        hi += 1
    return x[hi] - x[lo]


# The satin's main highlight (flat warp floats, light at 30° in the warp plane) is about
# 12–17° wide along the warp and about 120–140° wide across it; 5× is a safe floor.
STRETCH_RATIO_MIN = 5.0


@pytest.mark.parametrize("reciprocal", [False, True])
def test_satin_highlight_is_stretched_across_the_warp(reciprocal):
    """The issue's check: the highlight of the warp floats is a streak across the warp.

    A cylinder along x reflects a ray into a cone around x. So for a light in the warp
    plane, the highlight is narrow when the view moves along the warp (x–z plane) and
    long when it moves around the warp axis (rotation of the mirror direction about x).
    """
    brdf = Sadeghi2013("satin", reciprocal=reciprocal)
    wi = sph(30.0, 180.0)
    theta = np.arange(0.0, 60.01, 0.25)
    along = brdf(wi, sph(theta, 0.0))[:, 1]
    beta = np.radians(np.arange(-85.0, 85.01, 0.25))
    mirror_x, mirror_z = 0.5, np.sqrt(0.75)
    across_dirs = np.stack([np.full_like(beta, mirror_x), mirror_z * np.sin(beta), mirror_z * np.cos(beta)], -1)
    across = brdf(wi, across_dirs)[:, 1]
    assert theta[np.argmax(along)] == pytest.approx(30.0, abs=0.5)
    assert np.degrees(beta[np.argmax(across)]) == pytest.approx(0.0, abs=0.5)
    width_along = half_max_width(theta, along)
    width_across = half_max_width(np.degrees(beta), across)
    assert width_across > STRETCH_RATIO_MIN * width_along
    # the same streak with the fabric turned by 90°: swap warp and weft → along y
    turned = Sadeghi2013(
        Fabric("satin_turned", warp=PRESETS["satin"].weft, weft=PRESETS["satin"].warp),
        reciprocal=reciprocal,
    )
    rot = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # +90° about z
    np.testing.assert_allclose(
        turned(wi @ rot.T, across_dirs @ rot.T)[:, 1], across, rtol=1e-12
    )


# --- edges: broadcasting, horizon, NaN, validation -----------------------------------------


def test_broadcasting_matches_pairwise_evaluation(random_directions):
    brdf = Sadeghi2013("silk_shot", n_samples=8)
    wi = random_directions(5)[:, None, :]
    wr = random_directions(4)[None, :, :]
    f = brdf(wi, wr)
    assert f.shape == (5, 4, 3)
    for a in range(5):
        for b in range(4):
            np.testing.assert_allclose(f[a, b], brdf(wi[a, 0], wr[0, b]), rtol=1e-14)
    assert brdf(wi[0, 0], wr[0, 0]).shape == (3,)


def test_below_horizon_gives_zero():
    brdf = Sadeghi2013("linen")
    up = sph(30, 10)
    down = np.array([0.3, 0.2, -0.5]) / np.linalg.norm([0.3, 0.2, -0.5])
    grazing = np.array([1.0, 0.0, 0.0])
    for wi, wr in ((down, up), (up, down), (grazing, up), (up, grazing), (down, down)):
        assert np.all(brdf(wi, wr) == 0.0)


def test_nan_in_gives_nan_out():
    brdf = Sadeghi2013("satin", n_samples=8)
    wi = np.array([[np.nan, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    wr = np.array([[0.0, 0.0, 1.0], [0.0, np.nan, 1.0], [0.0, 0.0, 1.0]])
    f = brdf(wi, wr)
    assert np.all(np.isnan(f[:2])) and np.all(np.isfinite(f[2]))


def test_arclength_samples_follow_the_tangent_curve():
    linen = PRESETS["linen"].warp
    np.testing.assert_allclose(np.degrees(linen.tangent_offsets(2)), [-12.5, 12.5])
    # velvet weft: −90 → −55, jump, 55 → 90 (a zero-length segment is a jump)
    velvet = PRESETS["velvet"].weft
    np.testing.assert_allclose(np.degrees(velvet.tangent_offsets(4)), [-81.25, -63.75, 63.75, 81.25])
    np.testing.assert_allclose(
        np.degrees(velvet.tangent_offsets(99, "control_points")), [-90, -55, 55, 90]
    )
    # satin warp: the flat float (α = 0) is 2 of the 9.98 length units, the two ±32°
    # stretches 1.33 each
    satin = np.degrees(PRESETS["satin"].warp.tangent_offsets(998))
    assert np.mean(np.abs(satin) < 1e-9) == pytest.approx(2.0 / 9.98, abs=2e-3)
    assert np.mean(np.abs(np.abs(satin) - 32.0) < 1e-9) == pytest.approx(2.66 / 9.98, abs=2e-3)


def test_user_defined_fabric_matches_preset():
    """A Fabric built from Table II numbers in degrees reproduces the preset."""
    family = Family.from_deg(
        eta=1.46, A=(0.06, 0.24, 0.3), kd=0.3, gamma_s_deg=12, gamma_v_deg=24,
        a=0.33, offsets_deg=(-25, 25), lengths=(1,),
    )
    mine = Sadeghi2013(Fabric("my_linen", warp=family, weft=family), reciprocal=False)
    wi, wr = sph(30, 180), sph(30, 0)
    np.testing.assert_allclose(mine(wi, wr), [0.04300, 0.09435, 0.11146], atol=GOLDEN_ATOL * 20)
    # n_samples=32 vs the golden 64: linen converges to within 1e-4 here
    np.testing.assert_allclose(
        mine(wi, wr), Sadeghi2013("linen", reciprocal=False)(wi, wr), rtol=1e-14
    )


@pytest.mark.parametrize(
    "make",
    [
        lambda: Sadeghi2013("denim"),
        lambda: Sadeghi2013("satin", sampling="random"),
        lambda: Sadeghi2013("satin", n_samples=0),
        lambda: Family.from_deg(eta=0.9, A=(1, 1, 1), kd=0.1, gamma_s_deg=5, gamma_v_deg=10,
                                a=0.5, offsets_deg=(0, 0), lengths=(1,)),
        lambda: Family.from_deg(eta=1.5, A=(1, 1, 1), kd=0.1, gamma_s_deg=5, gamma_v_deg=10,
                                a=0.5, offsets_deg=(0, 10, 0), lengths=(1,)),
        lambda: Fabric("overfull", warp=PRESETS["satin"].warp, weft=PRESETS["satin_back"].warp),
    ],
)
def test_invalid_parameters_raise_kesbrdf_error(make):
    with pytest.raises(KesbrdfError, match="expected"):
        make()


def test_unknown_preset_message_lists_valid_names():
    with pytest.raises(KesbrdfError) as info:
        Sadeghi2013("denim")
    message = str(info.value)
    assert "\n" not in message and "'denim'" in message
    assert all(name in message for name in PRESET_NAMES)


def test_bad_direction_shape_raises():
    with pytest.raises(KesbrdfError, match=r"\(\.\.\., 3\)"):
        Sadeghi2013("linen")(np.zeros((4, 2)), np.zeros((4, 3)))


def test_fresnel_dielectric_limits():
    assert fresnel_dielectric(1.0, 1.5) == pytest.approx(0.04)
    assert fresnel_dielectric(0.0, 1.5) == pytest.approx(1.0)


# --- black satin --------------------------------------------------------------------------

# Documented in black_satin_fabric: body (volume) albedo ≈ 0.25 × 0.072 ≈ 1.8 % at normal view.
BLACK_BODY_ALBEDO = (0.012, 0.025)


def test_black_satin_keeps_the_sheen_and_loses_the_body(albedo):
    kwargs = dict(sampling="control_points", reciprocal=False)
    lit = Sadeghi2013("satin", **kwargs)
    black = black_satin(**kwargs)
    sheen_only = Sadeghi2013(PRESETS["satin"].with_albedo((0, 0, 0), (0, 0, 0)), **kwargs)
    assert black.fabric.name == "black_satin"
    assert BLACK_SATIN_DYE_FACTOR == 0.25
    # neutral, and the tangent curves and surface parameters are the satin's
    for fam_black, fam_lit in zip(black.fabric.families, lit.fabric.families):
        assert fam_black.A[0] == fam_black.A[1] == fam_black.A[2]
        assert (fam_black.eta, fam_black.gamma_s, fam_black.offsets) == (
            fam_lit.eta, fam_lit.gamma_s, fam_lit.offsets)
    up = sph(0, 0)
    rho_black, rho_lit, rho_sheen = albedo(black, up), albedo(lit, up), albedo(sheen_only, up)
    body = rho_black - rho_sheen
    assert np.all((body > BLACK_BODY_ALBEDO[0]) & (body < BLACK_BODY_ALBEDO[1]))
    np.testing.assert_allclose(body, body[0], rtol=1e-12)  # achromatic
    assert np.all(rho_black < rho_lit)
    # the highlight (mirror of the flat floats) keeps almost all of its height
    wi, wr = sph(30, 180), sph(30, 0)
    assert np.all(black(wi, wr) > 0.85 * lit(wi, wr).min())
    assert black_satin_fabric(0.0).warp.A == (0.0, 0.0, 0.0)


def test_params_record_is_json_and_rebuilds_the_fabric():
    import json

    brdf = black_satin(n_samples=16)
    record = json.loads(json.dumps(brdf.params()))
    assert record["reference"] == "sadeghi2013" and record["fabric"] == "black_satin"
    assert record["reciprocal"] is True and record["n_samples"] == 16
    warp = Family.from_deg(**{k: v for k, v in record["warp"].items()})
    assert warp.offsets == pytest.approx(brdf.fabric.warp.offsets, abs=1e-15)
    assert warp.A == brdf.fabric.warp.A
