"""The paper's figures (Takeda et al., Fig. 3–6), made from any model or measurement.

Three modules (STYLE "Plots, CLI, renders"): drawing (:mod:`kesbrdf.plotting.drawing`),
sampling (:mod:`kesbrdf.plotting.sampling`) and this one, the figure assembly, which
re-exports the other two:

* ``plot_<what>(ax, ...) -> Axes`` draw **computed arrays** on one axes; they do no
  model math and label every axis with its symbol and unit.
* ``figure_<n>(model=..., measurement=..., reference=...) -> Figure`` compute those
  arrays through the core API (:func:`kesbrdf.models.brdf.evaluate`,
  :func:`kesbrdf.models.brdf.lookup`, :class:`kesbrdf.measure.measurement.Measurement`) and return a
  pyplot-free :class:`matplotlib.figure.Figure` carrying its provenance
  (see :mod:`kesbrdf.plotting.save`).

The plotted quantity ("ρ" in the paper) is the KES quantity of the model,

.. math:: q = f_r \\sqrt{\\cos\\theta_i \\cos\\theta_r}   \\quad\\text{(paper eq. 3)}

in 1/sr.  Model curves in Fig. 3 and 4 are the model evaluated (``deviation`` mapping
by default) at the in-plane geometry of the paper's protocol, θ_i = 45° − γ/2,
θ_r = 45° + γ/2 at orientation ψ, converted to q: they include the body term and pass
through every measured in-plane sample of that protocol (docs/method.md, "From the table to a BRDF": round trip).  Fig. 5
plots the model's table itself, ``lookup(model.table_view(), φ, γ)``: the lobe q without the body
(every kind has one: a kind without a (φ, γ) table is tabulated through ``evaluate``).

Orientation and azimuth (docs/method.md, "Conventions"): in Fig. 3 and Fig. 4 the angle is the
orientation ψ of the plane of incidence (viewer azimuth).  For γ ≥ 0 it is the
deviation azimuth φ; for γ < 0 the deviation points the other way, φ = ψ + π, which is
the paper's "negative γ means azimuth φ + π".
"""

from __future__ import annotations

import numpy as np

from kesbrdf.errors import KesbrdfError, validate_choice
from kesbrdf.plotting._mpl import new_figure
from kesbrdf.plotting.drawing import (  # noqa: F401  (re-exported)
    Q_LABEL,
    FR_LABEL,
    plot_rho_vs_gamma,
    plot_rho_3d,
    plot_polar_rho,
    plot_spherical_projection,
    plot_hemisphere,
    plot_albedo,
)
from kesbrdf.plotting.sampling import (  # noqa: F401  (re-exported)
    PAPER_PSI_DEG,
    PSI_TOL_DEG,
    GAMMA_TOL_DEG,
    LIGHT_TOL_DEG,
    GAMMA_LIMIT_DEG,
    select_channel,
    measured_in_plane,
    model_in_plane,
    hemisphere_grid,
    disk_positions,
    disk_position,
    require_input,
    curve_gamma_max,
    channels_of,
    orientations_deg,
    measured_at_gamma,
    difference_map,
    measured_at_light,
    albedo_grid,
)
from kesbrdf.plotting.save import attach_provenance, provenance

__all__ = [
    "Q_LABEL",
    "FIGURES",
    "plot_rho_vs_gamma",
    "plot_rho_3d",
    "plot_polar_rho",
    "plot_spherical_projection",
    "plot_hemisphere",
    "plot_albedo",
    "hemisphere_grid",
    "measured_in_plane",
    "measured_at_light",
    "model_in_plane",
    "select_channel",
    "figure_3a",
    "figure_3b",
    "figure_4",
    "figure_5",
    "figure_6",
    "figure_albedo",
    "make_figure",
]


def _fig3_data(model, measurement, channel, mapping, n_gamma):
    if model is None and measurement is None:
        raise KesbrdfError("figure 3: expected a model or a measurement, got neither")
    measured = measured_in_plane(measurement, channel) if measurement is not None else None
    psi_deg = orientations_deg(measured)
    label = measured["label"] if measured else None
    curve = None
    if model is not None:
        gmax = curve_gamma_max(model)
        gamma = np.linspace(-gmax, gmax, n_gamma)
        q = model_in_plane(model, np.radians(psi_deg)[:, None], gamma[None, :], mapping)
        q, label = select_channel(q, channels_of(model), channel)
        curve = (np.degrees(gamma), q)
    return measured, psi_deg, curve, label


def figure_3a(model=None, measurement=None, reference=None, *, channel=None, mapping=None,
              n_gamma: int = 169, logy: bool = False, figsize=(7.0, 4.6)):
    """Paper Fig. 3a: q against signed γ per orientation, measured points and model curves.

    Parameters
    ----------
    model : Model, optional
    measurement : Measurement, optional
        At least one of the two.
    reference : ignored
        Accepted so every ``figure_*`` takes the same inputs.
    channel : int, str or None
        See :func:`select_channel`.
    mapping : str
        Mapping used to evaluate the model at the in-plane geometry.
    n_gamma : int
        Points per model curve over [−γ_max, γ_max].
    logy : bool
        Logarithmic q axis.

    Returns
    -------
    Figure
    """
    measured, psi_deg, curve, label = _fig3_data(model, measurement, channel, mapping, n_gamma)
    fig = new_figure(figsize)
    ax = fig.add_subplot()
    plot_rho_vs_gamma(
        ax,
        psi_deg,
        None if measured is None else measured["gamma_deg"],
        None if measured is None else measured["q"],
        model_gamma_deg=None if curve is None else curve[0],
        model_rho=None if curve is None else curve[1],
        logy=logy,
        title=f"Fig. 3a  q vs γ per orientation ({label})",
        **({} if model is None else {"model_label": f"{model.kind} model"}),
    )
    return attach_provenance(fig, provenance(model, measurement, figure="3a", channel=label,
                                             mapping=mapping, psi_deg=psi_deg, logy=logy))


def figure_3b(model=None, measurement=None, reference=None, *, channel=None, mapping=None,
              n_gamma: int = 85, n_psi: int = 37, figsize=(7.0, 5.6)):
    """Paper Fig. 3b: the 3-D view, measured lines over the model surface q(ψ, γ).

    The model surface spans ψ ∈ [0°, 180°] and signed γ ∈ [−γ_max, γ_max] (``n_psi`` ×
    ``n_gamma`` points).  Other parameters as :func:`figure_3a`.

    Returns
    -------
    Figure
    """
    measured, psi_deg, _, label = _fig3_data(model, measurement, channel, mapping, 2)
    surface = {}
    if model is not None:
        gmax = curve_gamma_max(model)
        s_psi = np.linspace(0.0, 180.0, n_psi)
        s_gamma = np.linspace(-gmax, gmax, n_gamma)
        q = model_in_plane(model, np.radians(s_psi)[:, None], s_gamma[None, :], mapping)
        q, label = select_channel(q, channels_of(model), channel)
        surface = dict(surface_psi_deg=s_psi, surface_gamma_deg=np.degrees(s_gamma), surface_rho=q)
    fig = new_figure(figsize)
    ax = fig.add_subplot(projection="3d")
    plot_rho_3d(
        ax,
        psi_deg,
        None if measured is None else measured["gamma_deg"],
        None if measured is None else measured["q"],
        title=f"Fig. 3b  q over (ψ, γ) ({label})",
        **surface,
    )
    return attach_provenance(fig, provenance(model, measurement, figure="3b", channel=label, mapping=mapping))


def figure_4(model=None, measurement=None, reference=None, *, gamma_deg=(-60.0, 0.0), channel=None,
             mapping=None, n_phi: int = 360, figsize=None):
    """Paper Fig. 4: polar plots of q over the orientation at chosen signed γ.

    The KES curve is the model at the in-plane geometry of orientation ψ ∈ [0, 2π)
    with signed γ (for γ < 0 this reads the model's table at deviation azimuth ψ + π);
    measured points are the samples at ψ (with γ) and at ψ + π (the sample at ψ with
    −γ), eight per circle for the paper's protocol.

    Parameters
    ----------
    gamma_deg : sequence of float
        Signed γ of each panel, degrees (paper: −60° and 0°).
    n_phi : int
        Points per curve.

    Returns
    -------
    Figure
    """
    require_input(model, "model", "4")
    gamma_deg = np.atleast_1d(np.asarray(gamma_deg, float))
    measured = measured_in_plane(measurement, channel) if measurement is not None else None
    phi = np.arange(n_phi) * (2 * np.pi / n_phi)
    q = model_in_plane(model, phi[None, :], np.radians(gamma_deg)[:, None], mapping)
    q, label = select_channel(q, channels_of(model), channel)
    fig = new_figure(figsize or (4.2 * len(gamma_deg), 4.6))
    for k, g in enumerate(gamma_deg):
        ax = fig.add_subplot(1, len(gamma_deg), k + 1, projection="polar")
        mphi = mrho = None
        if measured is not None:
            mphi, mrho = measured_at_gamma(measured, g)
        plot_polar_rho(ax, phi, q[k], measured_phi=mphi, measured_rho=mrho, gamma_deg=g,
                       title=rf"Fig. 4  $\gamma$ = {g:g}° ({label})", model_label=model.kind)
    return attach_provenance(fig, provenance(model, measurement, figure="4", channel=label,
                                             mapping=mapping, gamma_deg=gamma_deg))


def figure_5(model=None, measurement=None, reference=None, *, gamma_deg=None, channel=None,
             normalise: bool = False, n_phi: int = 181, figsize=(12.0, 4.4)):
    """Paper Fig. 5: the spherical model in three projections.

    Each curve is one γ: the point at angle γ from the mirror direction z, azimuth φ
    from the warp x toward the weft y, at radius ρ = ``lookup(model.table_view(), φ, γ)``
    (the tabulated lobe q, 1/sr, without the body term; a kind without a (φ, γ) table is
    tabulated through its evaluation, :func:`kesbrdf.models.table.tabulate`), i.e.
    (x, y, z) = ρ·(sin γ cos φ, sin γ sin φ, cos γ).  Panels follow the paper's
    caption: (a) weft (horizontal) vs warp, (b) weft vs specular, (c) warp vs specular.

    Parameters
    ----------
    gamma_deg : sequence of float, optional
        γ ≥ 0 of the curves; default 0° to γ_max in steps of 12°.
    normalise : bool
        Divide each curve by its largest radius (shape only; the axes are then
        dimensionless).

    Returns
    -------
    Figure
    """
    from kesbrdf.models import brdf

    table = require_input(model, "model", "5").table_view()
    if gamma_deg is None:
        gamma_deg = np.arange(0.0, np.degrees(np.max(table.gamma_grid)) + 1e-9, 12.0)
    gamma_deg = np.atleast_1d(np.asarray(gamma_deg, float))
    if np.any(gamma_deg < 0):
        raise KesbrdfError(f"figure 5: expected γ ≥ 0 (the model's domain), got {gamma_deg.min():g}°")
    phi = np.linspace(0.0, 2 * np.pi, n_phi)
    gamma = np.radians(gamma_deg)
    rho = np.asarray(brdf.lookup(table, phi[None, :], gamma[:, None]), float)
    rho, label = select_channel(rho, channels_of(model), channel)
    if normalise:
        peak = np.max(np.abs(rho), axis=1, keepdims=True)
        rho = rho / np.where(peak > 0, peak, 1.0)
    x = rho * np.sin(gamma)[:, None] * np.cos(phi)
    y = rho * np.sin(gamma)[:, None] * np.sin(phi)
    z = rho * np.cos(gamma)[:, None]
    unit = "(normalised)" if normalise else "(1/sr)"
    fig = new_figure(figsize)
    panels = (
        (y, x, f"y = weft {unit}", f"x = warp {unit}", "(a) warp–weft plane"),
        (y, z, f"y = weft {unit}", f"z = specular {unit}", "(b) weft vs specular"),
        (x, z, f"x = warp {unit}", f"z = specular {unit}", "(c) warp vs specular"),
    )
    for k, (h, v, xl, yl, title) in enumerate(panels):
        ax = fig.add_subplot(1, 3, k + 1)
        plot_spherical_projection(ax, h, v, gamma_deg=gamma_deg, xlabel=xl, ylabel=yl, title=title)
    what = "lobe q" if model.has_table else f"lobe q tabulated from the {model.kind} model"
    fig.suptitle(f"Fig. 5  spherical model, radius = {what} ({label})")
    return attach_provenance(fig, provenance(model, measurement, figure="5", channel=label,
                                             gamma_deg=gamma_deg, normalise=normalise))


def figure_6(model=None, measurement=None, reference=None, *, lights_deg=((30.0, 90.0), (30.0, 45.0)),
             mapping=None, channel=None, n: int = 121, projection: str = "equal-area",
             difference: str = "log", scale: str = "log", figsize=None):
    """Paper Fig. 6: hemispherical maps of f_r over the viewing hemisphere for fixed lights.

    One row per light: the model (:func:`kesbrdf.models.brdf.evaluate` with ``mapping``), the
    truth and their difference.  The truth is the reference map when a reference
    (any callable ``f(wi, wr) -> (..., C)``) is given; measured samples whose light is
    within :data:`LIGHT_TOL_DEG` of the row's light are drawn on it as dots (or alone,
    without a reference), and the difference then shows them too.

    Parameters
    ----------
    reference : callable, optional
        Analytic or tabulated BRDF; without it and without measured samples at the
        light only the model column is drawn.
    measurement : Measurement, optional
        Samples at the light directions (out-of-plane data), if any.
    lights_deg : sequence of (θ_i, φ_i)
        Light directions, degrees (paper: (30, 90) and (30, 45)).
    n : int
        Pixels per side of each map.
    projection : {"equal-area", "theta-linear"}
        See :func:`hemisphere_grid`.
    difference : {"log", "relative"}
        ``log``: log10(model / truth); ``relative``: (model − truth) / truth.  Pixels
        where the truth is ≤ 0 (or the model ≤ 0 for ``log``) are blank.
    scale : {"log", "linear"}
        Colour scale of the f_r maps (shared by model and truth in a row).

    Returns
    -------
    Figure
        ``fig.kesbrdf_maps`` holds, per light, the arrays drawn: ``model``,
        ``reference``, ``difference`` (n, n) and ``measured`` (u, v, f_r, model) or None.
    """
    if model is not None:
        mapping = model.check_mapping(mapping)  # None: the model's own (for kes the mapping it records)
    from kesbrdf.models import brdf
    from kesbrdf.geometry import spherical_to_cartesian

    require_input(model, "model", "6")
    validate_choice("figure 6 difference", difference, ("log", "relative"))
    grid = hemisphere_grid(n, projection)
    inside = grid["inside"]
    wr = spherical_to_cartesian(grid["theta"][inside], grid["phi"][inside])
    lights = np.atleast_2d(np.asarray(lights_deg, float))
    model_channels = channels_of(model)

    rows = []
    for theta_i_deg, phi_i_deg in lights:
        theta_i, phi_i = np.radians(theta_i_deg), np.radians(phi_i_deg)
        wi = spherical_to_cartesian(theta_i, phi_i)
        model_img = np.full(inside.shape, np.nan)
        f_model = np.asarray(brdf.evaluate(model, wi, wr, mapping=mapping), float)
        model_img[inside], label = select_channel(f_model, model_channels, channel)
        ref_img = None
        if reference is not None:
            ref_img = np.full(inside.shape, np.nan)
            f_ref = np.asarray(reference(np.broadcast_to(wi, wr.shape), wr), float)
            ref_channels = tuple(getattr(reference, "channels", model_channels))
            ref_channel = channel if not isinstance(channel, str) or channel in ref_channels else None
            ref_img[inside], _ = select_channel(f_ref, ref_channels, ref_channel)
        measured = None
        if measurement is not None:
            sel = measured_at_light(measurement, theta_i, phi_i)
            if sel.any():
                sub = measurement.subset(sel)
                u, v = disk_positions(sub.theta_r, sub.phi_r, projection)
                f_meas, _ = select_channel(sub.values, sub.channels,
                                           channel if not isinstance(channel, str) or channel in sub.channels else None)
                f_pred, _ = select_channel(np.asarray(brdf.evaluate(model, sub.wi, sub.wr, mapping=mapping), float),
                                           model_channels, channel)
                measured = (u, v, f_meas, f_pred)
        diff = None if ref_img is None else difference_map(model_img, ref_img, difference)
        rows.append({"light": (theta_i_deg, phi_i_deg), "model": model_img, "reference": ref_img,
                     "difference": diff, "measured": measured})

    has_truth = any(r["reference"] is not None or r["measured"] is not None for r in rows)
    n_cols = 3 if has_truth else 1
    fig = new_figure(figsize or (4.2 * n_cols, 3.7 * len(lights)))
    diff_label = r"$\log_{10}$(model / truth)" if difference == "log" else "(model − truth) / truth"
    for k, row in enumerate(rows):
        theta_i_deg, phi_i_deg = row["light"]
        measured = row["measured"]
        pieces = [row["model"], row["reference"]] + ([] if measured is None else [measured[2]])
        finite = np.concatenate([np.ravel(p)[np.isfinite(np.ravel(p))] for p in pieces if p is not None])
        positive = finite[finite > 0]
        vmax = float(positive.max()) if positive.size else 1.0
        mirror = disk_position(np.radians(theta_i_deg), np.radians(phi_i_deg) + np.pi, projection)
        light_text = rf"$\theta_i$ = {theta_i_deg:g}°, $\phi_i$ = {phi_i_deg:g}°"
        common = dict(extent=grid["extent"], marks={"mirror": mirror})
        ax = fig.add_subplot(len(rows), n_cols, k * n_cols + 1)
        plot_hemisphere(ax, row["model"], scale=scale, vmax=vmax, vmin=None if scale == "log" else 0.0,
                        label=f"$f_r$ {label} (1/sr)", title=f"model ({model.kind}, {mapping})\n{light_text}",
                        projection_label=grid["label"], **common)
        if n_cols == 1:
            continue
        points = None if measured is None else measured[:3]
        truth_name = "reference" if row["reference"] is not None else "measured"
        if row["reference"] is not None and measured is not None:
            truth_name = "reference, measured dots"
        ax = fig.add_subplot(len(rows), n_cols, k * n_cols + 2)
        plot_hemisphere(ax, row["reference"], scale=scale, vmax=vmax, vmin=None if scale == "log" else 0.0,
                        label=f"$f_r$ {label} (1/sr)", title=f"{truth_name}\n{light_text}", points=points, **common)
        diff_points = None
        if measured is not None:
            diff_points = (measured[0], measured[1], difference_map(measured[3], measured[2], difference))
        ax = fig.add_subplot(len(rows), n_cols, k * n_cols + 3)
        plot_hemisphere(ax, row["difference"], diverging=True, label=diff_label,
                        title=f"difference\n{light_text}", points=diff_points, **common)
    fig.suptitle(f"Fig. 6  hemispherical maps of $f_r$ ({label})")
    fig.kesbrdf_maps = [{k: r[k] for k in ("model", "reference", "difference", "measured")} for r in rows]
    return attach_provenance(fig, provenance(model, measurement, reference, figure="6", channel=label,
                                             mapping=mapping, lights_deg=lights, projection=projection,
                                             difference=difference, n=n))


def figure_albedo(model=None, measurement=None, reference=None, *, diagnostics=None, figsize=(6.0, 4.4)):
    """Directional albedo over incident directions from :func:`kesbrdf.validate.diagnostics.diagnose`.

    Parameters
    ----------
    diagnostics : dict, optional
        Needs ``albedo`` as a dict with ``theta_i_deg`` (T,), ``phi_i_deg`` (P,) and
        ``albedo`` (T, P) or (T, P, C) (channels averaged); computed from ``model``
        when not given.

    Returns
    -------
    Figure
    """
    if diagnostics is None:
        from kesbrdf.validate.diagnostics import diagnose

        diagnostics = diagnose(require_input(model, "model", "albedo"))
    grid = albedo_grid(diagnostics)
    if grid is None:
        raise KesbrdfError("albedo figure: expected diagnostics with an albedo grid, got none")
    theta_i_deg, phi_i_deg, albedo = grid
    fig = new_figure(figsize)
    ax = fig.add_subplot()
    plot_albedo(ax, theta_i_deg, phi_i_deg, albedo, title="directional albedo (white furnace: ≤ 1)")
    return attach_provenance(fig, provenance(model, measurement, figure="albedo"))


#: Figure name -> builder; every builder takes ``model=, measurement=, reference=``.
FIGURES = {
    "3a": figure_3a,
    "3b": figure_3b,
    "4": figure_4,
    "5": figure_5,
    "6": figure_6,
}


def make_figure(name: str, model=None, measurement=None, reference=None, **kwargs):
    """Build figure ``name`` (one of :data:`FIGURES` or ``"albedo"``)."""
    builders = dict(FIGURES, albedo=figure_albedo)
    if name not in builders:
        raise KesbrdfError(f"expected a figure in {', '.join(builders)}, got {name!r}")
    if model is not None:
        if name in ("3a", "3b", "4", "6"):  # the figures that evaluate the model
            kwargs["mapping"] = model.check_mapping(kwargs.get("mapping"))
    return builders[name](model=model, measurement=measurement, reference=reference, **kwargs)

