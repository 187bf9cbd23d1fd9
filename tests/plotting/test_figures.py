"""kesbrdf.plotting.figures: plot_* draw exactly the arrays given; figure_* reproduce
the model's in-plane round trip, close the polar curve and zero the difference map when
model == reference."""

import numpy as np
import pytest

from kesbrdf.errors import KesbrdfError
from kesbrdf.measure.measurement import Measurement
from kesbrdf.plotting import figures as F

#: The model reproduces every in-plane sample to round-off (docs/method.md, "From the table to a BRDF"); the curves are
#: evaluated at exactly the measured γ (1° grid), so only float round-off remains.
ROUND_TRIP_RTOL = 1e-9
#: Fig. 5 recomputes lookup() exactly as the figure does: only product round-off.
SAME_MATH_RTOL = 1e-12
#: Equal-area check: pixel counting on a 201² grid resolves areas to ~1 % (edge pixels).
AREA_TOL = 0.02


def _lines(ax, gid):
    return [ln for ln in ax.get_lines() if ln.get_gid() == gid]


# -- plot_* on synthetic arrays ----------------------------------------------------------
def test_rho_vs_gamma_draws_the_given_arrays(fig, rng):
    ax = fig.add_subplot()
    psi = np.array([0.0, 45.0, 90.0])
    gamma = np.linspace(-84, 84, 29)
    rho = rng.uniform(0.1, 1.0, (3, 29))
    rho[1, 5] = np.nan  # a missing sample is skipped, not drawn
    mg = np.linspace(-84, 84, 50)
    mr = rng.uniform(0.1, 1.0, (3, 50))
    F.plot_rho_vs_gamma(ax, psi, gamma, rho, model_gamma_deg=mg, model_rho=mr)
    measured, model = _lines(ax, "measured"), _lines(ax, "model")
    assert len(measured) == len(model) == 3
    for p in range(3):
        keep = np.isfinite(rho[p])
        np.testing.assert_array_equal(measured[p].get_xdata(), gamma[keep])
        np.testing.assert_array_equal(measured[p].get_ydata(), rho[p][keep])
        np.testing.assert_array_equal(model[p].get_ydata(), mr[p])
    assert len(measured[1].get_xdata()) == 28
    assert r"\gamma" in ax.get_xlabel() and "(°)" in ax.get_xlabel()
    assert "1/sr" in ax.get_ylabel()


def test_rho_vs_gamma_model_only(fig):
    ax = fig.add_subplot()
    F.plot_rho_vs_gamma(ax, [0, 90], model_gamma_deg=[0, 1], model_rho=[[1, 2], [3, 4]])
    assert len(_lines(ax, "measured")) == 0 and len(_lines(ax, "model")) == 2


def test_rho_3d_needs_3d_axes(fig):
    with pytest.raises(ValueError, match="3d"):
        F.plot_rho_3d(fig.add_subplot(), [0.0])


def test_rho_3d_lines_and_surface(fig, rng):
    ax = fig.add_subplot(projection="3d")
    rho = rng.uniform(size=(4, 7))
    F.plot_rho_3d(ax, [0, 45, 90, 135], np.linspace(-60, 60, 7), rho,
                  surface_psi_deg=np.linspace(0, 180, 5), surface_gamma_deg=np.linspace(-60, 60, 9),
                  surface_rho=rng.uniform(size=(5, 9)))
    lines = _lines(ax, "measured")
    assert len(lines) == 4
    xs, ys, zs = lines[2].get_data_3d()
    np.testing.assert_array_equal(xs, 90.0)
    np.testing.assert_array_equal(zs, rho[2])
    assert [c for c in ax.collections if c.get_gid() == "model"]
    assert r"\psi" in ax.get_xlabel() and "1/sr" in ax.get_zlabel()


def test_polar_curve_closes(fig):
    ax = fig.add_subplot(projection="polar")
    phi = np.arange(12) * (2 * np.pi / 12)
    rho = 1.0 + 0.5 * np.cos(2 * phi)
    F.plot_polar_rho(ax, phi, rho, measured_phi=np.radians([90, 0, 270, 180]), measured_rho=[1, 2, 3, 4])
    (kes,) = _lines(ax, "kes")
    x, y = np.asarray(kes.get_xdata()), np.asarray(kes.get_ydata())
    assert x.size == 13 and x[-1] == x[0] and y[-1] == y[0]
    np.testing.assert_array_equal(y[:-1], rho)
    (meas,) = _lines(ax, "measured")
    # sorted by azimuth and closed: 0°, 90°, 180°, 270°, 0°
    np.testing.assert_allclose(np.degrees(meas.get_xdata()), [0, 90, 180, 270, 0])
    np.testing.assert_array_equal(meas.get_ydata(), [2, 1, 4, 3, 2])


def test_polar_needs_polar_axes(fig):
    with pytest.raises(ValueError, match="polar"):
        F.plot_polar_rho(fig.add_subplot(), [0.0], [1.0])


def test_spherical_projection_one_curve_per_gamma(fig, rng):
    ax = fig.add_subplot()
    h, v = rng.normal(size=(2, 5, 30))
    F.plot_spherical_projection(ax, h, v, gamma_deg=np.arange(5) * 12.0, xlabel="y = weft (1/sr)", ylabel="x")
    curves = _lines(ax, "gamma-curve")
    assert len(curves) == 5
    np.testing.assert_array_equal(curves[3].get_xdata(), h[3])
    np.testing.assert_array_equal(curves[3].get_ydata(), v[3])


def test_hemisphere_image_is_the_input(fig, rng):
    ax = fig.add_subplot()
    values = rng.uniform(0.1, 1, (9, 9))
    values[0, 0] = np.nan
    F.plot_hemisphere(ax, values, scale="log", title="t")
    (im,) = [i for i in ax.images if i.get_gid() == "hemisphere"]
    arr = np.ma.filled(im.get_array().astype(float), np.nan)
    np.testing.assert_array_equal(arr[1:, 1:], values[1:, 1:])
    assert len(fig.axes) == 2  # the map and its colour bar


def test_hemisphere_difference_is_symmetric_and_zero_safe(fig):
    ax = fig.add_subplot()
    diff = np.array([[-0.2, 0.1], [0.0, np.nan]])
    F.plot_hemisphere(ax, diff, diverging=True)
    assert ax.images[0].get_clim() == (-0.2, 0.2)
    ax2 = fig.add_subplot(2, 1, 2)
    F.plot_hemisphere(ax2, np.zeros((3, 3)), diverging=True)  # an exact match still draws
    lo, hi = ax2.images[0].get_clim()
    assert lo == -hi and hi > 0


def test_albedo_flags_cells_above_one(fig):
    ax = fig.add_subplot()
    albedo = np.array([[0.5, 1.2], [0.9, 1.01]])
    F.plot_albedo(ax, [0, 40], [0, 90], albedo)
    (flags,) = _lines(ax, "flag")
    assert len(flags.get_xdata()) == 2
    np.testing.assert_array_equal(sorted(zip(flags.get_xdata(), flags.get_ydata())), [(90, 0), (90, 40)])


def test_select_channel():
    v = np.array([[1.0, 2.0, 6.0]])
    assert F.select_channel(v, "RGB", None)[0].tolist() == [3.0]
    assert F.select_channel(v, "RGB", "B") == (pytest.approx([6.0]), "B")
    assert F.select_channel(v, "RGB", "1")[1] == "G"
    assert F.select_channel(v[:, :1], ("value",), None)[1] == "value"
    with pytest.raises(KesbrdfError, match=r"expected a channel in \['R', 'G', 'B'\], got 'X'"):
        F.select_channel(v, "RGB", "X")
    with pytest.raises(KesbrdfError, match="index"):
        F.select_channel(v, "RGB", 3)


def test_hemisphere_grid_equal_area():
    g = F.hemisphere_grid(201, "equal-area")
    inside = g["inside"]
    # solid angle of θ < 60° is 2π(1 − cos 60°) = half the hemisphere
    frac = np.count_nonzero(inside & (g["theta"] < np.radians(60))) / np.count_nonzero(inside)
    assert frac == pytest.approx(0.5, abs=AREA_TOL)
    assert g["theta"][100, 100] == 0.0
    assert np.degrees(g["theta"][100, -1]) == pytest.approx(90.0)
    lin = F.hemisphere_grid(201, "theta-linear")
    assert np.degrees(lin["theta"][100, 150]) == pytest.approx(45.0)
    with pytest.raises(KesbrdfError, match="projection"):
        F.hemisphere_grid(5, "mercator")


def test_measured_in_plane_groups_and_pads():
    psi = np.radians([90, 0, 0, 0, 90])
    ti = np.radians([30, 60, 30, 45, 60])
    tr = np.radians([60, 30, 60, 45, 30])
    m = Measurement.in_plane(psi, ti, tr, np.arange(1.0, 6.0))
    d = F.measured_in_plane(m)
    assert d["psi_deg"].tolist() == [0.0, 90.0]
    np.testing.assert_allclose(d["gamma_deg"][0], [-30, 0, 30])
    np.testing.assert_allclose(d["gamma_deg"][1, :2], [-30, 30])
    assert np.isnan(d["gamma_deg"][1, 2]) and np.isnan(d["q"][1, 2])
    # q = f_r sqrt(cos θi cos θr): sample 3 (ψ=0, γ=+30) has f_r = 3
    assert d["q"][0, 2] == pytest.approx(3.0 * np.sqrt(np.cos(ti[2]) * np.cos(tr[2])))


def test_measured_in_plane_needs_in_plane_rows():
    m = Measurement(theta_i=[0.1], phi_i=[0.0], theta_r=[0.2], phi_r=[1.0], values=[1.0], source="x.csv")
    with pytest.raises(KesbrdfError, match="x.csv: expected in-plane samples"):
        F.measured_in_plane(m)


# -- figure_* on a fitted model ---------------------------------------------------------
def test_figure_3a_model_passes_through_measured_points(satin_model, satin_measurement):
    fig = F.figure_3a(satin_model, satin_measurement)
    ax = fig.axes[0]
    measured, model = _lines(ax, "measured"), _lines(ax, "model")
    assert len(measured) == len(model) == 4
    for mline, cline in zip(measured, model):
        gx, gy = np.asarray(mline.get_xdata()), np.asarray(mline.get_ydata())
        cx, cy = np.asarray(cline.get_xdata()), np.asarray(cline.get_ydata())
        idx = np.searchsorted(cx, gx - 1e-9)
        np.testing.assert_allclose(cx[idx], gx, atol=1e-9)
        np.testing.assert_allclose(cy[idx], gy, rtol=ROUND_TRIP_RTOL)
    prov = fig.kesbrdf_provenance
    assert prov["input_sha256"] == satin_model.input_info.get("sha256")
    assert prov["parameters"]["figure"] == "3a"


def test_figure_3a_measurement_only(satin_measurement):
    fig = F.figure_3a(measurement=satin_measurement)
    assert len(_lines(fig.axes[0], "measured")) == 4 and not _lines(fig.axes[0], "model")
    assert fig.kesbrdf_provenance["input_sha256"] == satin_measurement.sha256


def test_figure_3_needs_an_input():
    with pytest.raises(KesbrdfError, match="expected a model or a measurement"):
        F.figure_3a()


def test_figure_3b_has_surface_and_lines(satin_model, satin_measurement):
    fig = F.figure_3b(satin_model, satin_measurement, n_gamma=9, n_psi=5)
    ax = fig.axes[0]
    assert ax.name == "3d" and len(_lines(ax, "measured")) == 4
    assert [c for c in ax.collections if c.get_gid() == "model"]


def test_figure_4_polar_kes_meets_measured(satin_model, satin_measurement):
    fig = F.figure_4(satin_model, satin_measurement, gamma_deg=(-60.0, 0.0))
    polar = [a for a in fig.axes if a.name == "polar"]
    assert len(polar) == 2
    for ax in polar:
        (kes,) = _lines(ax, "kes")
        (meas,) = _lines(ax, "measured")
        x, y = np.asarray(kes.get_xdata()), np.asarray(kes.get_ydata())
        assert x[0] == x[-1] and y[0] == y[-1]  # closed curve
        mx, my = np.asarray(meas.get_xdata())[:-1], np.asarray(meas.get_ydata())[:-1]
        assert mx.size == 8  # ψ and ψ + 180° for the four orientations
        idx = np.rint(np.degrees(mx)).astype(int) % 360  # KES curve is on a 1° grid
        np.testing.assert_allclose(y[idx], my, rtol=ROUND_TRIP_RTOL)


def test_figure_4_needs_a_model(satin_measurement):
    with pytest.raises(KesbrdfError, match="figure 4: expected a model"):
        F.figure_4(measurement=satin_measurement)


def test_figure_5_radius_is_the_table(satin_model):
    from kesbrdf.models.brdf import lookup

    fig = F.figure_5(satin_model, gamma_deg=[0.0, 12.0, 24.0], n_phi=37)
    axes = fig.axes
    assert len(axes) == 3
    assert "weft" in axes[0].get_xlabel() and "warp" in axes[0].get_ylabel()
    assert "specular" in axes[1].get_ylabel() and "warp" in axes[2].get_xlabel()
    curves = _lines(axes[2], "gamma-curve")  # warp vs specular
    assert len(curves) == 3
    phi = np.linspace(0, 2 * np.pi, 37)
    q = lookup(satin_model, phi, np.radians(12.0))[..., 0]
    np.testing.assert_allclose(curves[1].get_ydata(), q * np.cos(np.radians(12.0)), rtol=SAME_MATH_RTOL)
    np.testing.assert_allclose(curves[1].get_xdata(), q * np.sin(np.radians(12.0)) * np.cos(phi), rtol=SAME_MATH_RTOL,
                               atol=SAME_MATH_RTOL * np.max(q))


def test_figure_5_normalised_and_domain(satin_model):
    fig = F.figure_5(satin_model, gamma_deg=[0.0], normalise=True, n_phi=13)
    (c,) = _lines(fig.axes[1], "gamma-curve")
    assert np.max(c.get_ydata()) == pytest.approx(1.0)
    with pytest.raises(KesbrdfError, match="γ ≥ 0"):
        F.figure_5(satin_model, gamma_deg=[-10.0])


def test_figure_6_difference_is_zero_for_the_model_itself(satin_model):
    from kesbrdf.models.brdf import evaluate

    def same(wi, wr):
        return evaluate(satin_model, wi, wr)

    fig = F.figure_6(satin_model, reference=same, n=31)
    assert len(fig.kesbrdf_maps) == 2
    for maps in fig.kesbrdf_maps:
        diff = maps["difference"]
        assert np.isfinite(diff).sum() > 0.5 * diff.size
        assert np.nanmax(np.abs(diff)) == 0.0
    images = [ax.images[0] for ax in fig.axes if ax.images]
    assert len(images) == 6  # 2 lights × (model, reference, difference)


def test_figure_6_against_reference_differs(satin_model, satin_ref, satin_measurement):
    fig = F.figure_6(satin_model, satin_measurement, satin_ref, n=31, lights_deg=[(30.0, 90.0)],
                     difference="relative", projection="theta-linear")
    maps = fig.kesbrdf_maps[0]
    # the map is the reference itself where it is shown
    inside = np.isfinite(maps["reference"])
    assert inside.sum() > 0.7 * inside.size
    assert np.nanmax(np.abs(maps["difference"])) > 0
    assert fig.kesbrdf_provenance["parameters"]["lights_deg"] == [[30.0, 90.0]]


def test_figure_6_model_only_and_rgb_channel(rgb_model):
    fig = F.figure_6(rgb_model, n=15, channel="G", lights_deg=[(30.0, 45.0)])
    assert len([a for a in fig.axes if a.images]) == 1
    assert fig.kesbrdf_provenance["parameters"]["channel"] == "G"


def test_figure_albedo_from_diagnostics_dict():
    diag = {"albedo": {"theta_i_deg": [0, 40], "phi_i_deg": [0, 90],
                       "values": [[[0.5, 0.5], [1.5, 1.5]], [[0.2, 0.2], [0.3, 0.3]]]}}
    fig = F.figure_albedo(diagnostics=diag)
    (flags,) = _lines(fig.axes[0], "flag")
    assert len(flags.get_xdata()) == 1
    with pytest.raises(KesbrdfError, match="albedo grid"):
        F.figure_albedo(diagnostics={"reciprocity_error": 0.0})


def test_make_figure_names():
    with pytest.raises(KesbrdfError, match="expected a figure in 3a, 3b, 4, 5, 6, albedo, got '7'"):
        F.make_figure("7")


def _general_samples(brdf_fn, theta_i_deg, phi_i_deg, rng, k=25):
    """Out-of-plane samples at one light over random viewing directions."""
    theta_r = np.arccos(rng.uniform(0.1, 1.0, k))
    phi_r = rng.uniform(0, 2 * np.pi, k)
    theta_i = np.full(k, np.radians(theta_i_deg))
    phi_i = np.full(k, np.radians(phi_i_deg))
    from kesbrdf.geometry import spherical_to_cartesian

    values = brdf_fn(spherical_to_cartesian(theta_i, phi_i), spherical_to_cartesian(theta_r, phi_r))
    return Measurement(theta_i=theta_i, phi_i=phi_i, theta_r=theta_r, phi_r=phi_r, values=values,
                       psi=np.full(k, np.nan))


def test_figure_6_measured_points_at_the_light(satin_model, rng):
    from kesbrdf.models.brdf import evaluate

    m = _general_samples(lambda wi, wr: evaluate(satin_model, wi, wr), 30.0, 90.0, rng)
    fig = F.figure_6(satin_model, m, n=21)
    first, second = fig.kesbrdf_maps
    u, v, f_meas, f_pred = first["measured"]
    assert u.size == 25 and second["measured"] is None  # only the (30°, 90°) light has samples
    np.testing.assert_array_equal(f_meas, m.values[:, 0])
    np.testing.assert_allclose(f_pred, f_meas, rtol=ROUND_TRIP_RTOL)
    # second row: no truth for the (30°, 45°) light, but the figure keeps three columns
    axes = [a for a in fig.axes if a.images or a.collections]
    dots = [c for a in axes for c in a.collections if c.get_gid() == "points"]
    assert len(dots) == 2  # measured dots and their difference dots (row 1)
    diff_dots = np.asarray(dots[1].get_array(), float)
    assert np.nanmax(np.abs(diff_dots)) < ROUND_TRIP_RTOL  # log10(1 + ε) < ε; model == "measured": zero difference
    no_data = [t for a in fig.axes for t in a.texts if t.get_gid() == "no-data"]
    assert len(no_data) == 2  # row 2: measured and difference panels say so
    # the dots sit at the samples' viewing directions (equal-area radius)
    r = np.hypot(u, v)
    np.testing.assert_allclose(r, np.sqrt(2) * np.sin(m.theta_r / 2), rtol=SAME_MATH_RTOL)
