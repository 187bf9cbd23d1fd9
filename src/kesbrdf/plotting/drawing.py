"""Drawing the paper's figures: ``plot_<what>(ax, ...) -> Axes`` (STYLE "Plots, CLI, renders").

Each function draws **computed arrays** on one axes: no model math, every axis
labelled with its symbol and unit.  The arrays come from :mod:`kesbrdf.plotting.sampling`
and the figures are assembled in :mod:`kesbrdf.plotting.figures`.
"""

from __future__ import annotations

import numpy as np

from kesbrdf.errors import validate_choice
from kesbrdf.plotting._mpl import require_matplotlib

__all__ = [
    "Q_LABEL",
    "FR_LABEL",
    "plot_rho_vs_gamma",
    "plot_rho_3d",
    "plot_polar_rho",
    "plot_spherical_projection",
    "plot_hemisphere",
    "plot_albedo",
]

#: Axis label of the plotted KES quantity (paper eq. 3 normalisation).
Q_LABEL = r"$q = f_r\,\sqrt{\cos\theta_i\cos\theta_r}$ (1/sr)"
#: Axis label of the BRDF.
FR_LABEL = r"$f_r$ (1/sr)"


def _colour(i: int):
    return f"C{i % 10}"


#: Marker and dash per orientation, so that coinciding curves (a fabric symmetric
#: under φ → π − φ has ψ = 45° on top of 135°) stay visible.
_MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*")
_DASHES = ("-", "--", "-.", ":")


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
    model_label: str = "KES model",
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
    model_label : str
        Legend name of the model curves (the figures pass the model's kind).

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
                label=f"ψ = {psi:g}° {model_label}",
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
    model_label: str = "KES",
):
    """Paper Fig. 4: ρ over the azimuth at one γ; the model solid (legend ``model_label``), measured dashed.

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
    model_label : str
        Legend name of the model curve (the figures pass the model's kind).

    Returns
    -------
    PolarAxes
    """
    if getattr(ax, "name", "") != "polar":
        raise ValueError(f"expected an axes with projection='polar', got {getattr(ax, 'name', ax)!r}")
    phi = np.asarray(phi, float)
    rho = np.asarray(rho, float)
    ax.plot(_close(phi), _close(rho), "-", lw=1.5, color="C0", label=model_label, gid="kes")
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

