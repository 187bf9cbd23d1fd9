"""The paper's figures (Takeda et al., Fig. 3–6), made from any model or measurement.

Two layers (STYLE "Plots, CLI, renders"):

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
from kesbrdf.measure.measurement import PAPER_ORIENTATIONS_DEG
from kesbrdf.plotting._mpl import new_figure, require_matplotlib
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

#: Axis label of the plotted KES quantity (paper eq. 3 normalisation).
Q_LABEL = r"$q = f_r\,\sqrt{\cos\theta_i\cos\theta_r}$ (1/sr)"
#: Axis label of the BRDF.
FR_LABEL = r"$f_r$ (1/sr)"
#: The paper's orientations, degrees.
PAPER_PSI_DEG = PAPER_ORIENTATIONS_DEG
#: Two in-plane samples belong to the same orientation when their ψ differ by less
#: than this (degrees); files store ψ with at most a few decimals.
PSI_TOL_DEG = 1e-3
#: A sample is "at" a requested γ when within this many degrees (the protocol's γ
#: step is 6°, so half a degree picks exactly one sample per orientation).
GAMMA_TOL_DEG = 0.5
#: A measured sample belongs to a Fig. 6 light when its light direction is within this
#: angle (degrees) of it; goniometers position to a fraction of a degree.
LIGHT_TOL_DEG = 1.0
#: Largest |γ| drawn for a model curve: at |γ| = 90° the paper geometry is grazing.
GAMMA_LIMIT_DEG = 89.0


def _colour(i: int):
    return f"C{i % 10}"


#: Marker and dash per orientation, so that coinciding curves (a fabric symmetric
#: under φ → π − φ has ψ = 45° on top of 135°) stay visible.
_MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*")
_DASHES = ("-", "--", "-.", ":")


# --------------------------------------------------------------------------------------
# plot_* : arrays in, artists out, no model math
# --------------------------------------------------------------------------------------
def plot_rho_vs_gamma(
    ax,
    psi_deg,
    gamma_deg=None,
    rho=None,
    *,
    model_gamma_deg=None,
    model_rho=None,
    ylabel: str = Q_LABEL,
    logy: bool = False,
    title: str | None = None,
):
    """Paper Fig. 3a: ρ against signed γ, one colour per orientation ψ.

    Parameters
    ----------
    ax : matplotlib Axes
    psi_deg : array_like, shape (P,)
        Orientations, degrees (legend only).
    gamma_deg, rho : array_like, shape (P, N) (``gamma_deg`` may be (N,)), optional
        Measured points; NaN entries are skipped.  One marker line per orientation
        (``gid="measured"``).
    model_gamma_deg : array_like, shape (M,), optional
    model_rho : array_like, shape (P, M), optional
        Model curves, one solid line per orientation (``gid="model"``).
    ylabel : str
        Label of the plotted quantity with its unit.
    logy : bool
        Logarithmic ρ axis.

    Returns
    -------
    Axes
    """
    psi_deg = np.atleast_1d(np.asarray(psi_deg, float))
    for p, psi in enumerate(psi_deg):
        colour = _colour(p)
        if rho is not None:
            r = np.atleast_2d(np.asarray(rho, float))[p]
            g = np.broadcast_to(np.asarray(gamma_deg, float), np.shape(np.atleast_2d(rho)))[p]
            keep = np.isfinite(r) & np.isfinite(g)
            ax.plot(g[keep], r[keep], _MARKERS[p % len(_MARKERS)], ms=3.5 + 1.2 * (p % 2), mfc="none" if p % 2 else colour,
                    color=colour, label=f"ψ = {psi:g}° measured", gid="measured")
        if model_rho is not None:
            ax.plot(
                np.asarray(model_gamma_deg, float),
                np.atleast_2d(np.asarray(model_rho, float))[p],
                _DASHES[p % len(_DASHES)],
                lw=1.4,
                color=colour,
                label=f"ψ = {psi:g}° KES model",
                gid="model",
            )
    ax.set_xlabel(r"$\gamma = \theta_r - \theta_i$ (°)")
    ax.set_ylabel(ylabel)
    if logy:
        ax.set_yscale("log")
    ax.axvline(0.0, color="0.7", lw=0.8, zorder=0)
    ax.grid(True, alpha=0.3)
    if len(psi_deg):
        ax.legend(fontsize="small")
    if title:
        ax.set_title(title)
    return ax


def plot_rho_3d(
    ax,
    psi_deg,
    gamma_deg=None,
    rho=None,
    *,
    surface_psi_deg=None,
    surface_gamma_deg=None,
    surface_rho=None,
    zlabel: str = Q_LABEL,
    title: str | None = None,
):
    """Paper Fig. 3b: ρ over (ψ, γ) in 3-D.

    Parameters
    ----------
    ax : Axes3D
        Made with ``projection="3d"``.
    psi_deg : array_like, shape (P,)
        Orientation of each measured line, degrees.
    gamma_deg, rho : array_like, shape (P, N) (``gamma_deg`` may be (N,)), optional
        Measured lines at constant ψ (``gid="measured"``); NaN skipped.
    surface_psi_deg : (A,), surface_gamma_deg : (B,), surface_rho : (A, B), optional
        Model surface ρ(ψ, γ) (``gid="model"``).

    Returns
    -------
    Axes3D
    """
    if getattr(ax, "name", "") != "3d":
        raise ValueError(f"expected an axes with projection='3d', got {getattr(ax, 'name', ax)!r}")
    psi_deg = np.atleast_1d(np.asarray(psi_deg, float))
    if surface_rho is not None:
        P, G = np.meshgrid(
            np.asarray(surface_psi_deg, float), np.asarray(surface_gamma_deg, float), indexing="ij"
        )
        surf = ax.plot_surface(P, G, np.asarray(surface_rho, float), cmap="viridis", alpha=0.55, linewidth=0)
        surf.set_gid("model")
    if rho is not None:
        rho2 = np.atleast_2d(np.asarray(rho, float))
        g2 = np.broadcast_to(np.asarray(gamma_deg, float), rho2.shape)
        for p, psi in enumerate(psi_deg):
            keep = np.isfinite(rho2[p]) & np.isfinite(g2[p])
            ax.plot(
                np.full(keep.sum(), psi),
                g2[p][keep],
                rho2[p][keep],
                "o-",
                ms=2.5,
                lw=1.0,
                color=_colour(p),
                label=f"ψ = {psi:g}° measured",
                gid="measured",
            )
        ax.legend(fontsize="small")
    ax.set_xlabel(r"$\psi$ (°)")
    ax.set_ylabel(r"$\gamma$ (°)")
    ax.set_zlabel(zlabel)
    if title:
        ax.set_title(title)
    return ax


def _close(a):
    a = np.asarray(a, float)
    return np.concatenate([a, a[..., :1]], axis=-1)


def plot_polar_rho(
    ax,
    phi,
    rho,
    *,
    measured_phi=None,
    measured_rho=None,
    gamma_deg: float | None = None,
    rlabel: str = Q_LABEL,
    title: str | None = None,
):
    """Paper Fig. 4: ρ over the azimuth at one γ; KES solid, measured dashed.

    Parameters
    ----------
    ax : PolarAxes
        Made with ``projection="polar"``; angle 0 = warp (x), counter-clockwise.
    phi : array_like, shape (M,)
        Azimuths, radians, increasing over one turn (without the closing 2π point:
        the curve is closed here, ``gid="kes"``).
    rho : array_like, shape (M,)
    measured_phi, measured_rho : array_like, shape (K,), optional
        Measured points, drawn as a closed dashed polygon with markers in order of
        azimuth (``gid="measured"``).
    gamma_deg : float, optional
        Used in the title.

    Returns
    -------
    PolarAxes
    """
    if getattr(ax, "name", "") != "polar":
        raise ValueError(f"expected an axes with projection='polar', got {getattr(ax, 'name', ax)!r}")
    phi = np.asarray(phi, float)
    rho = np.asarray(rho, float)
    ax.plot(_close(phi), _close(rho), "-", lw=1.5, color="C0", label="KES", gid="kes")
    if measured_rho is not None:
        mp = np.mod(np.asarray(measured_phi, float), 2 * np.pi)
        mr = np.asarray(measured_rho, float)
        order = np.argsort(mp, kind="stable")
        ax.plot(_close(mp[order]), _close(mr[order]), "o--", ms=4, lw=1.0, color="C3", label="measured", gid="measured")
    require_matplotlib()
    from matplotlib.ticker import MaxNLocator

    ax.yaxis.set_major_locator(MaxNLocator(4))
    ax.tick_params(axis="y", labelsize="x-small")
    ax.set_rlabel_position(22.5)
    ax.set_xlabel(r"$\phi$ (°, 0 = warp); radius " + rlabel, fontsize="small")
    ax.legend(fontsize="small", loc="upper right", bbox_to_anchor=(1.15, 1.1))
    if title is None and gamma_deg is not None:
        title = rf"$\gamma$ = {gamma_deg:g}°"
    if title:
        ax.set_title(title)
    return ax


def plot_spherical_projection(
    ax,
    horizontal,
    vertical,
    *,
    gamma_deg=None,
    xlabel: str,
    ylabel: str,
    title: str | None = None,
):
    """One projection of the paper's spherical model (Fig. 5).

    Parameters
    ----------
    ax : Axes
    horizontal, vertical : array_like, shape (G, M)
        Coordinates (1/sr) of one closed curve per γ.
    gamma_deg : array_like, shape (G,), optional
        γ of each curve, for the legend.
    xlabel, ylabel : str
        Axis names with unit, e.g. ``"y = weft (1/sr)"``.

    Returns
    -------
    Axes
    """
    require_matplotlib()
    from matplotlib import colormaps

    h = np.atleast_2d(np.asarray(horizontal, float))
    v = np.atleast_2d(np.asarray(vertical, float))
    cmap = colormaps["viridis"]
    n = h.shape[0]
    for k in range(n):
        label = None if gamma_deg is None else rf"$\gamma$ = {np.asarray(gamma_deg)[k]:g}°"
        ax.plot(h[k], v[k], "-", lw=1.1, color=cmap(k / max(n - 1, 1)), label=label, gid="gamma-curve")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(True, alpha=0.3)
    if gamma_deg is not None and n <= 10:
        ax.legend(fontsize="x-small")
    if title:
        ax.set_title(title, fontsize="medium")
    return ax


def plot_hemisphere(
    ax,
    values,
    *,
    extent=(-1.0, 1.0, -1.0, 1.0),
    scale: str = "linear",
    vmin: float | None = None,
    vmax: float | None = None,
    diverging: bool = False,
    label: str = FR_LABEL,
    title: str | None = None,
    marks: dict | None = None,
    colorbar: bool = True,
    projection_label: str = "",
    points=None,
):
    """A map over the viewing hemisphere projected on the unit disk (paper Fig. 6).

    Parameters
    ----------
    ax : Axes
    values : array_like, shape (H, W)
        Pixel values (row 0 at the bottom, i.e. most negative y); NaN outside the disk.
    extent : 4-tuple
        ``(left, right, bottom, top)`` of the pixel grid in disk coordinates.
    scale : {"linear", "log"}
        Colour scale (``log`` masks values ≤ 0).
    vmin, vmax : float, optional
        Colour limits; for ``diverging`` maps the limits are ±``vmax`` (default the
        largest |value|), so zero sits at the centre of the colour map.
    diverging : bool
        Use a diverging colour map (``RdBu_r``) for differences.
    marks : dict of str -> (u, v), optional
        Named points drawn as crosses (e.g. the mirror direction of the light).
    projection_label : str
        Appended to the axis labels (how the disk radius maps to θ_r).
    points : (u, v, values) of array_like (K,), optional
        Scattered samples (e.g. measured directions) drawn with the same colour scale
        (``gid="points"``).  ``values`` (the image) may then be None.

    Returns
    -------
    Axes
        The image is ``ax.images[0]`` with ``gid="hemisphere"``.
    """
    require_matplotlib()
    from matplotlib.colors import LogNorm, Normalize
    from matplotlib.patches import Circle

    pts = None if points is None else [np.asarray(a, float).reshape(-1) for a in points]
    pieces = [] if values is None else [np.asarray(values, float).ravel()]
    if pts is not None:
        pieces.append(pts[2])
    every = np.concatenate(pieces) if pieces else np.empty(0)
    finite = every[np.isfinite(every)]
    if diverging:
        lim = vmax if vmax is not None else (float(np.max(np.abs(finite))) if finite.size else 0.0)
        lim = lim if lim > 0 else 1e-12  # an all-zero difference still gets a valid scale
        norm, cmap = Normalize(-lim, lim), "RdBu_r"
    elif scale == "log":
        pos = finite[finite > 0]
        hi = vmax if vmax is not None else (float(pos.max()) if pos.size else 1.0)
        lo = vmin if vmin is not None else hi * 1e-3
        norm, cmap = LogNorm(lo, hi, clip=True), "magma"
    elif scale == "linear":
        norm, cmap = Normalize(vmin, vmax), "magma"
    else:
        validate_choice("scale", scale, ("linear", "log"))
    mappable = None
    if values is not None:
        mappable = ax.imshow(np.asarray(values, float), origin="lower", extent=extent, norm=norm, cmap=cmap,
                             interpolation="nearest")
        mappable.set_gid("hemisphere")
    if pts is not None:
        sc = ax.scatter(pts[0], pts[1], c=pts[2], norm=norm, cmap=cmap, s=22, edgecolors="0.3", linewidths=0.4)
        sc.set_gid("points")
        mappable = mappable or sc
    if mappable is None:
        ax.text(0.0, 0.0, "no data", ha="center", va="center", color="0.4", gid="no-data")
    ax.add_patch(Circle((0, 0), 1.0, fill=False, color="0.3", lw=0.8))
    ax.annotate("", xy=(1.12, 0), xytext=(0, 0), arrowprops=dict(arrowstyle="->", color="0.2", lw=1.0))
    ax.text(1.13, 0.04, "warp", fontsize="x-small", ha="left", va="bottom")
    ax.annotate("", xy=(0, 1.12), xytext=(0, 0), arrowprops=dict(arrowstyle="->", color="0.5", lw=0.8))
    ax.text(0.04, 1.13, "weft", fontsize="x-small", ha="left", va="bottom")
    for name, (u, v) in (marks or {}).items():
        ax.plot([u], [v], "+", color="cyan", ms=9, mew=1.5, gid="mark")
        ax.text(u + 0.05, v + 0.05, name, color="cyan", fontsize="x-small")
    ax.set_xlim(-1.25, 1.25)
    ax.set_ylim(-1.25, 1.25)
    ax.set_aspect("equal")
    suffix = f" {projection_label}" if projection_label else ""
    ax.set_xlabel(r"$x$ (warp)" + suffix, fontsize="small")
    ax.set_ylabel(r"$y$ (weft)" + suffix, fontsize="small")
    if colorbar and mappable is not None:
        ax.figure.colorbar(mappable, ax=ax, label=label, shrink=0.8)
    if title:
        ax.set_title(title, fontsize="medium")
    return ax


def plot_albedo(ax, theta_i_deg, phi_i_deg, albedo, *, title: str | None = None, limit: float = 1.0):
    """Directional albedo over incident directions, with values above ``limit`` flagged.

    Parameters
    ----------
    ax : Axes
    theta_i_deg : array_like, shape (T,)
    phi_i_deg : array_like, shape (P,)
    albedo : array_like, shape (T, P)
        ∫ f_r cos θ_r dω_r for each incident direction (dimensionless).
    limit : float
        Energy conservation bound (white-furnace check): cells above it get a red ×
        (``gid="flag"``).

    Returns
    -------
    Axes
    """
    require_matplotlib()
    from matplotlib.colors import Normalize

    t = np.asarray(theta_i_deg, float)
    p = np.asarray(phi_i_deg, float)
    a = np.asarray(albedo, float).reshape(t.size, p.size)
    hi = max(limit, float(np.nanmax(a)) if np.isfinite(a).any() else limit)
    mesh = ax.pcolormesh(p, t, a, shading="nearest", cmap="viridis", norm=Normalize(0.0, hi))
    mesh.set_gid("albedo")
    over = a > limit
    if over.any():
        P, T = np.meshgrid(p, t)
        ax.plot(P[over], T[over], "x", color="red", ms=6, mew=1.5, gid="flag", label=f"albedo > {limit:g}")
        ax.legend(fontsize="small")
    ax.figure.colorbar(mesh, ax=ax, label="directional albedo (1)")
    ax.set_xlabel(r"$\phi_i$ (°)")
    ax.set_ylabel(r"$\theta_i$ (°)")
    if title:
        ax.set_title(title)
    return ax


# --------------------------------------------------------------------------------------
# data preparation: measurements, channels, geometry grids
# --------------------------------------------------------------------------------------
def select_channel(values, channels, channel=None) -> tuple[np.ndarray, str]:
    """Pick one channel from ``values`` (..., C).

    Parameters
    ----------
    values : array_like, shape (..., C)
    channels : sequence of str
        Channel names of the last axis.
    channel : int, str or None
        Index or name; ``None`` takes the only channel, or the mean over channels.

    Returns
    -------
    (ndarray (...), str)
        The values and a label for them.

    >>> v, name = select_channel(np.array([[1.0, 3.0]]), ("R", "G"))
    >>> v.tolist(), name
    ([2.0], 'mean(R, G)')
    """
    values = np.asarray(values, float)
    channels = tuple(channels)
    if channel is None:
        if values.shape[-1] == 1:
            return values[..., 0], channels[0]
        return values.mean(axis=-1), f"mean({', '.join(channels)})"
    if isinstance(channel, str):
        if channel in channels:
            return values[..., channels.index(channel)], channel
        if channel.lstrip("-").isdigit():
            channel = int(channel)
        else:
            raise KesbrdfError(f"expected a channel in {list(channels)}, got {channel!r}")
    index = int(channel)
    if not -len(channels) <= index < len(channels):
        raise KesbrdfError(f"expected a channel index below {len(channels)}, got {index}")
    return values[..., index], channels[index]


def measured_in_plane(measurement, channel=None, paper_line: str | bool = "auto") -> dict:
    """The in-plane samples of a measurement grouped by orientation, as q over signed γ.

    Parameters
    ----------
    measurement : Measurement
    channel : int, str or None
        See :func:`select_channel`.
    paper_line : "auto", True or False
        Keep only samples on the paper's line θ_i + θ_r = 90° (``True``), all in-plane
        samples (``False``), or the paper line when the data has any (``"auto"``).

    Returns
    -------
    dict
        ``psi_deg`` (P,), ``gamma_deg`` (P, N) and ``q`` (P, N) with NaN padding,
        sorted by γ within each orientation; ``label`` (channel name).

    Raises
    ------
    KesbrdfError
        If the measurement has no in-plane samples.
    """
    inplane = measurement.is_in_plane
    if not inplane.any():
        raise KesbrdfError(
            f"{measurement.source or 'measurement'}: expected in-plane samples (psi_deg) "
            "for this figure, got only general samples"
        )
    q, label = select_channel(measurement.q, measurement.channels, channel)
    theta_sum = measurement.theta_i + measurement.theta_r
    on_line = inplane & np.isclose(theta_sum, np.pi / 2, atol=np.radians(1e-3))
    keep = on_line if (paper_line is True or (paper_line == "auto" and on_line.any())) else inplane
    psi_deg = np.degrees(measurement.psi[keep])
    gamma_deg = np.degrees(measurement.gamma[keep])
    q = q[keep]
    key = np.round(psi_deg / PSI_TOL_DEG).astype(np.int64)
    groups, inverse = np.unique(key, return_inverse=True)
    counts = np.bincount(inverse, minlength=groups.size)
    order = np.lexsort((gamma_deg, inverse))
    n_max = int(counts.max())
    slot = np.arange(order.size) - np.repeat(np.cumsum(counts) - counts, counts)
    G = np.full((groups.size, n_max), np.nan)
    Q = np.full((groups.size, n_max), np.nan)
    G[inverse[order], slot] = gamma_deg[order]
    Q[inverse[order], slot] = q[order]
    return {"psi_deg": groups * PSI_TOL_DEG, "gamma_deg": G, "q": Q, "label": label}


def model_in_plane(model, psi, gamma, mapping: str | None = None) -> np.ndarray:
    """The model's q at the paper's in-plane geometry for orientation ψ and signed γ.

    θ_i = π/4 − γ/2, θ_r = π/4 + γ/2, light at azimuth ψ + π, viewer at ψ
    (docs/method.md, "Conventions"); returns ``evaluate(model, wi, wr, mapping) · √(cos θ_i cos θ_r)``.

    Parameters
    ----------
    model : Model
    psi, gamma : array_like
        Radians, broadcast together; |γ| < π/2.
    mapping : str
        Passed to :func:`kesbrdf.models.brdf.evaluate`.

    Returns
    -------
    ndarray, shape (..., C)
    """
    from kesbrdf.models import brdf
    from kesbrdf.geometry import in_plane_directions

    psi, gamma = np.broadcast_arrays(np.asarray(psi, float), np.asarray(gamma, float))
    theta_i = np.pi / 4 - gamma / 2
    theta_r = np.pi / 4 + gamma / 2
    wi, wr = in_plane_directions(psi, theta_i, theta_r)
    f_r = np.asarray(brdf.evaluate(model, wi, wr, mapping=mapping), float)
    return f_r * np.sqrt(np.cos(theta_i) * np.cos(theta_r))[..., None]


def hemisphere_grid(n: int, projection: str = "equal-area") -> dict:
    """Pixel grid over the unit disk and the viewing directions it shows.

    Parameters
    ----------
    n : int
        Pixels per side.
    projection : {"equal-area", "theta-linear"}
        Disk radius r of a direction at polar angle θ: ``equal-area`` (Lambert)
        r = √2·sin(θ/2), ``theta-linear`` r = θ/(π/2).  r = 1 at the horizon; the disk's
        x axis is the warp, y the weft (top view).

    Returns
    -------
    dict
        ``u, v, theta, phi`` (n, n) (row = v index from −1 up), ``inside`` (n, n) bool,
        ``extent`` for imshow, ``label`` describing the projection.
    """
    validate_choice("projection", projection, ("equal-area", "theta-linear"))
    c = np.linspace(-1.0, 1.0, n)
    half = 1.0 / (n - 1) if n > 1 else 1.0
    u, v = np.meshgrid(c, c)
    r = np.hypot(u, v)
    inside = r < 1.0
    rc = np.minimum(r, 1.0)
    if projection == "equal-area":
        theta = 2.0 * np.arcsin(rc / np.sqrt(2.0))
        label = r"[equal-area, $r=\sqrt{2}\sin(\theta_r/2)$]"
    else:
        theta = rc * np.pi / 2
        label = r"[$r=\theta_r/90°$]"
    return {
        "u": u,
        "v": v,
        "theta": theta,
        "phi": np.arctan2(v, u),
        "inside": inside,
        "extent": (-1 - half, 1 + half, -1 - half, 1 + half),
        "label": label,
        "projection": projection,
    }


def _disk_positions(theta, phi, projection: str):
    """Disk coordinates (u, v) of directions (θ, φ) in a :func:`hemisphere_grid` projection."""
    theta = np.asarray(theta, float)
    r = np.sqrt(2.0) * np.sin(theta / 2) if projection == "equal-area" else theta / (np.pi / 2)
    return r * np.cos(phi), r * np.sin(phi)


def _disk_position(theta, phi, projection: str):
    u, v = _disk_positions(theta, phi, projection)
    return float(u), float(v)


def _require(obj, what: str, figure: str):
    if obj is None:
        raise KesbrdfError(f"figure {figure}: expected a {what}, got none")
    return obj


def _gamma_max(model) -> float:
    """Largest |γ| of a model curve: the model's table's (its tabulated view for kinds
    without one), at most :data:`GAMMA_LIMIT_DEG`."""
    return float(min(np.max(model.table_view().gamma_grid), np.radians(GAMMA_LIMIT_DEG)))


def _model_channels(model):
    return tuple(getattr(model, "channels", ("value",)))


# --------------------------------------------------------------------------------------
# figure_* : compute arrays through the core API, lay out, attach provenance
# --------------------------------------------------------------------------------------
def _orientations_deg(measured: dict | None) -> np.ndarray:
    if measured is not None:
        return np.asarray(measured["psi_deg"], float)
    return np.asarray(PAPER_PSI_DEG)


def _fig3_data(model, measurement, channel, mapping, n_gamma):
    if model is None and measurement is None:
        raise KesbrdfError("figure 3: expected a model or a measurement, got neither")
    measured = measured_in_plane(measurement, channel) if measurement is not None else None
    psi_deg = _orientations_deg(measured)
    label = measured["label"] if measured else None
    curve = None
    if model is not None:
        gmax = _gamma_max(model)
        gamma = np.linspace(-gmax, gmax, n_gamma)
        q = model_in_plane(model, np.radians(psi_deg)[:, None], gamma[None, :], mapping)
        q, label = select_channel(q, _model_channels(model), channel)
        curve = (np.degrees(gamma), q)
    return measured, psi_deg, curve, label


def figure_3a(model=None, measurement=None, reference=None, *, channel=None, mapping="deviation",
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
    )
    return attach_provenance(fig, provenance(model, measurement, figure="3a", channel=label,
                                             mapping=mapping, psi_deg=psi_deg, logy=logy))


def figure_3b(model=None, measurement=None, reference=None, *, channel=None, mapping="deviation",
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
        gmax = _gamma_max(model)
        s_psi = np.linspace(0.0, 180.0, n_psi)
        s_gamma = np.linspace(-gmax, gmax, n_gamma)
        q = model_in_plane(model, np.radians(s_psi)[:, None], s_gamma[None, :], mapping)
        q, label = select_channel(q, _model_channels(model), channel)
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


def _measured_at_gamma(measured: dict, gamma_deg: float):
    """Measured (angle, q) at signed γ: ψ with γ, and ψ + 180° with −γ (docs/method.md, "From the table to a BRDF")."""
    phis, values = [], []
    for sign, offset in ((1.0, 0.0), (-1.0, 180.0)):
        # at γ = 0 both halves are the same sample, drawn at ψ and at ψ + 180°
        dist = np.abs(measured["gamma_deg"] - sign * gamma_deg)
        dist = np.where(np.isfinite(dist), dist, np.inf)
        j = np.argmin(dist, axis=1)
        rows = np.arange(dist.shape[0])
        hit = dist[rows, j] <= GAMMA_TOL_DEG
        phis.append(measured["psi_deg"][hit] + offset)
        values.append(measured["q"][rows, j][hit])
    return np.radians(np.concatenate(phis)), np.concatenate(values)


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
    _require(model, "model", "4")
    gamma_deg = np.atleast_1d(np.asarray(gamma_deg, float))
    measured = measured_in_plane(measurement, channel) if measurement is not None else None
    phi = np.arange(n_phi) * (2 * np.pi / n_phi)
    q = model_in_plane(model, phi[None, :], np.radians(gamma_deg)[:, None], mapping)
    q, label = select_channel(q, _model_channels(model), channel)
    fig = new_figure(figsize or (4.2 * len(gamma_deg), 4.6))
    for k, g in enumerate(gamma_deg):
        ax = fig.add_subplot(1, len(gamma_deg), k + 1, projection="polar")
        mphi = mrho = None
        if measured is not None:
            mphi, mrho = _measured_at_gamma(measured, g)
        plot_polar_rho(ax, phi, q[k], measured_phi=mphi, measured_rho=mrho, gamma_deg=g,
                       title=rf"Fig. 4  $\gamma$ = {g:g}° ({label})")
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

    table = _require(model, "model", "5").table_view()
    if gamma_deg is None:
        gamma_deg = np.arange(0.0, np.degrees(np.max(table.gamma_grid)) + 1e-9, 12.0)
    gamma_deg = np.atleast_1d(np.asarray(gamma_deg, float))
    if np.any(gamma_deg < 0):
        raise KesbrdfError(f"figure 5: expected γ ≥ 0 (the model's domain), got {gamma_deg.min():g}°")
    phi = np.linspace(0.0, 2 * np.pi, n_phi)
    gamma = np.radians(gamma_deg)
    rho = np.asarray(brdf.lookup(table, phi[None, :], gamma[:, None]), float)
    rho, label = select_channel(rho, _model_channels(model), channel)
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


def _difference(model_values, truth, kind: str):
    """log10(model / truth) or (model − truth) / truth; NaN where undefined."""
    with np.errstate(divide="ignore", invalid="ignore"):
        if kind == "log":
            ok = (model_values > 0) & (truth > 0)
            return np.where(ok, np.log10(np.where(ok, model_values, 1.0) / np.where(ok, truth, 1.0)), np.nan)
        ok = truth > 0
        return np.where(ok, (model_values - truth) / np.where(ok, truth, 1.0), np.nan)


def measured_at_light(measurement, theta_i, phi_i, tol=np.radians(LIGHT_TOL_DEG)):
    """Rows of ``measurement`` whose light is within ``tol`` (radians) of (θ_i, φ_i).

    Returns
    -------
    ndarray of bool, shape (N,)
    """
    from kesbrdf.geometry import spherical_to_cartesian

    wi = spherical_to_cartesian(theta_i, phi_i)
    cos_angle = np.clip(measurement.wi @ wi, -1.0, 1.0)
    return (np.arccos(cos_angle) <= tol) & (measurement.theta_r < np.pi / 2)


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
        mapping = model.check_mapping(mapping)  # None: the kind's own (deviation for kes)
    from kesbrdf.models import brdf
    from kesbrdf.geometry import spherical_to_cartesian

    _require(model, "model", "6")
    validate_choice("figure 6 difference", difference, ("log", "relative"))
    grid = hemisphere_grid(n, projection)
    inside = grid["inside"]
    wr = spherical_to_cartesian(grid["theta"][inside], grid["phi"][inside])
    lights = np.atleast_2d(np.asarray(lights_deg, float))
    model_channels = _model_channels(model)

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
                u, v = _disk_positions(sub.theta_r, sub.phi_r, projection)
                f_meas, _ = select_channel(sub.values, sub.channels,
                                           channel if not isinstance(channel, str) or channel in sub.channels else None)
                f_pred, _ = select_channel(np.asarray(brdf.evaluate(model, sub.wi, sub.wr, mapping=mapping), float),
                                           model_channels, channel)
                measured = (u, v, f_meas, f_pred)
        diff = None if ref_img is None else _difference(model_img, ref_img, difference)
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
        mirror = _disk_position(np.radians(theta_i_deg), np.radians(phi_i_deg) + np.pi, projection)
        light_text = rf"$\theta_i$ = {theta_i_deg:g}°, $\phi_i$ = {phi_i_deg:g}°"
        common = dict(extent=grid["extent"], marks={"mirror": mirror})
        ax = fig.add_subplot(len(rows), n_cols, k * n_cols + 1)
        plot_hemisphere(ax, row["model"], scale=scale, vmax=vmax, vmin=None if scale == "log" else 0.0,
                        label=f"$f_r$ {label} (1/sr)", title=f"model (KES, {mapping})\n{light_text}",
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
            diff_points = (measured[0], measured[1], _difference(measured[3], measured[2], difference))
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

        diagnostics = diagnose(_require(model, "model", "albedo"))
    grid = _albedo_grid(diagnostics)
    if grid is None:
        raise KesbrdfError("albedo figure: expected diagnostics with an albedo grid, got none")
    theta_i_deg, phi_i_deg, albedo = grid
    fig = new_figure(figsize)
    ax = fig.add_subplot()
    plot_albedo(ax, theta_i_deg, phi_i_deg, albedo, title="directional albedo (white furnace: ≤ 1)")
    return attach_provenance(fig, provenance(model, measurement, figure="albedo"))


def _albedo_grid(diagnostics):
    """(θ_i°, φ_i°, albedo (T, P)) from a diagnostics dict, or None."""
    alb = diagnostics.get("albedo") if isinstance(diagnostics, dict) else None
    if not isinstance(alb, dict):
        return None
    t = alb.get("theta_i_deg")
    a = alb.get("albedo", alb.get("values"))
    if t is None or a is None:
        return None
    t = np.atleast_1d(np.asarray(t, float))
    a = np.asarray(a, float)
    p = alb.get("phi_i_deg")
    p = np.zeros(1) if p is None else np.atleast_1d(np.asarray(p, float))
    if a.ndim == 3 or (a.ndim == 2 and a.shape != (t.size, p.size)):
        a = a.reshape(t.size, p.size, -1).mean(axis=-1)
    return t, p, a.reshape(t.size, p.size)


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
