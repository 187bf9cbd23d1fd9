r"""Far-field woven-cloth BRDF after Irawan & Marschner, "Specular Reflection from Woven
Cloth", ACM TOG 31(1), article 11, 2012 (IM12), and Piti Irawan's Cornell thesis
"Appearance of Woven Cloth", 2008 (Irawan 2008), where the model is derived in full.

Sources and numbering
---------------------
Neither text could be read past its front matter here: the stored copies of the thesis
(zlibrary.cc "appearance-of-woven-cloth", scribd 211705726) reach the title page,
abstract, biography and acknowledgements only, and no copy of the TOG paper's body was
found.  **No equation numbers are cited, because none could be checked**; giving some
would be inventing them.  What *was* read is Irawan's own implementation, as
redistributed with permission in Mitsuba 0.x (``src/bsdfs/irawan.cpp``:
``evalFilamentIntegrand``, ``evalStapleIntegrand``, ``radiusOfCurvature``,
``vonMises``, ``seeliger``).  Its header names the thesis as the model's description
and its comments cite thesis sections: Irawan 2008 §5.3 (the spine conic chosen by r̂),
§5.3.1 circle, §5.3.2 parabola, §5.3.3 hyperbola, and ch. 6 (the segment coordinates
u, v).  Those are the only section numbers below; every formula of this module was
checked term by term against that code (frames rotated, see the end).

What the model is
-----------------
Cloth is two families of yarns, warp and weft.  A yarn is a bundle of fibres; a
fibre reflects light specularly wherever the half vector h is perpendicular to its
tangent t (the cylinder condition).  Along a yarn segment the fibre tangent tilts out
of the cloth plane by the yarn's *u* angle, |u| ≤ u_max (the yarn follows a curved
spine over and under the crossing yarns, Irawan 2008 §5.3); across the yarn the surface
normal turns by the *v* angle, |v| ≤ π/2 (ch. 6 maps a segment's rectangle w × l
linearly onto these two angles).  Two kinds of yarn:

*filament* (ψ = 0)
    fibres parallel to the yarn.  The specular point on a segment is the tilt
    u*(h) = atan2(h'_y, h'_z) (the source's ``u_of_v``), valid while |u*| < u_max.
*staple* (twist ψ ≠ 0)
    fibres wound around the yarn at angle ψ.  For every tilt u the specular point is
    at the across-yarn angle v*(u) (the source's ``v_of_u``)

    .. math::

        D = \frac{h'_y\cos u - h'_z\sin u}{\sqrt{h'^2_x + (h'_y\sin u + h'_z\cos u)^2}\,\tan\psi},
        \qquad v^* = \operatorname{atan2}(-h'_y\sin u - h'_z\cos u,\ h'_x) + \arccos D

    valid while |D| < 1 and |v*| ≤ π/2, v* taken in (−π, π] (see Departures).

The scattering of one specular point is fs = G · f_c · A:

* geometry factor :math:`G = a\,(R(u) + a\cos v) / (|\omega_i+\omega_r|\,J)` with
  a = w/2, the spine's radius of curvature R(u) (Irawan 2008 §5.3.1–5.3.3) and the
  Jacobian J = |(t × h)_x| for filaments (= √(1 − h'_x²) at u*), n·h·|sin ψ| for
  staple yarns;
* phase function :math:`f_c = \alpha + \mathrm{vM}(-\omega_i\cdot\omega_r;\ \beta)`, a
  uniform part plus a von Mises lobe of concentration β;
* attenuation A = Seeliger law :math:`\frac{1}{4\pi}\frac{\cos_i\cos_r}{\cos_i+\cos_r}`
  (unit albedo) on the yarn-surface normal n; filament yarns fade it with
  1 − smoothstep over the last ``ss``·u_max of the tilt range, and evaluate R at
  min(|u*|, (1 − ss) u_max) on a spine whose u_max is (1 − ss) u_max.

Far field (our derivation, not in the sources)
----------------------------------------------
The source renders a spatially resolved weave: a pixel at (u, v) of a segment keeps
the specular point only if it lies within a highlight width δ of the pixel, and
multiplies fs by the "domain transform" (π l/δ_y for filaments, 2 w u_max/δ_x for
staple yarns).  Averaging over a whole segment (u uniform in ±u_max, v uniform in
±π/2), the window keeps a fraction δ_y/l (resp. δ_x/w) of the pixels, so δ cancels and

.. math::

    S_\text{fil} = \int_{-\pi/2}^{\pi/2} G\,A\,dv \Big|_{u=u^*},\qquad
    S_\text{sta} = \int_{-u_\max}^{u_\max} G\,A\,du \Big|_{v=v^*(u)}

exactly (the source's window is clamped inside the segment, so the fraction holds at
the ends too).  Each family's segments are weighted by its share of the pattern times
the source's area factor (A_warp + A_weft)/A_family; for all six presets below that
product is exactly 1, so the BRDF is

.. math::

    f_r = \frac{1}{\pi}\Big[\sum_j c_j k_{d,j} + N\,f_c\sum_j k_{s,j}\,S_j\Big]

with c_j the family's coverage.

Departures from the source
--------------------------
* The far-field average above replaces the per-pixel evaluation.  The source's
  per-fibre intensity noise (min(−ln ξ, 10), mean ≈ 1) averages out and is left out;
  its per-segment Perlin variation of u_max would not average out exactly and is
  dropped.
* N normalises the specular part so that its cosine-weighted mean albedo is 1 (k_s is
  then an albedo-like weight); the source leaves the scale to the user's k_s and adds
  k_d without 1/π.  N comes from a fixed, seeded quadrature (deterministic).
* v* wrap: atan2 + arccos lies in (−π, 2π]; the source tests |v*| < π/2 on that raw
  value and so drops specular points with v* ∈ (3π/2, 2π), which are the valid points
  v* − 2π ∈ (−π/2, 0).  We wrap first.  This restores the exact mirror symmetry
  between the twists ψ and −ψ (tested); for cotton_twill it moves N by 3·10⁻⁶.
* The cylinder condition t·h = 0 has two roots in v, atan2(…) ± arccos D; like the
  source we keep the + root only.  That loses nothing: wherever the − root lies on
  the visible half (|v| < π/2) it has n·h < 0 (tested on 2·10⁴ random h, u, ψ), and
  the Seeliger law vanishes there, because cos_i, cos_r > 0 imply n·h > 0.

Frames: fabric frame x = warp, y = weft, z = normal.  Family j lies along
y' = (cos α_j, sin α_j, 0) (α = 0 warp, 90° weft); x' = (sin α, −cos α, 0) is across
it.  (The source has its warp along y and rotates ω by +90° about z for the weft; both
are proper rotations, so the sign of ψ means the same handedness.)  The BRDF is
reciprocal by construction: every factor depends on (ωi, ωr) only through h,
ωi + ωr, ωi·ωr and the symmetric Seeliger law.

Presets: yarn geometry (ψ, u_max, κ, w, l), α, β, ss and the weave coverage come from
Piti Irawan's weave data, redistributed with LuxRender and Mitsuba; k_d and k_s are
**our guesses** (documented per preset) because the tables leave colour to the user.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace

import numpy as np
from scipy.special import i0e

from kesbrdf.errors import KesbrdfError
from kesbrdf.references.base import ReferenceBRDF

__all__ = [
    "Yarn",
    "Weave",
    "Irawan2012",
    "PRESETS",
    "PRESET_NAMES",
    "yarn_frame",
    "seeliger",
    "von_mises",
    "radius_of_curvature",
    "filament_integral",
    "staple_integral",
]

#: Gauss–Legendre nodes across the yarn (v) for filament yarns.
N_V = 24
#: Gauss–Legendre nodes along the yarn (u) for staple yarns.
N_U = 32
#: Seeded cosine-weighted pairs used for the specular normalisation N.
N_NORMALISATION = 1 << 14


@dataclass(frozen=True)
class Yarn:
    """One yarn family of IM12 (angles in degrees at this edge).

    psi_deg : twist angle ψ (0 = filament yarn).
    umax_deg : largest tilt u_max of the fibre tangent out of the cloth plane.
    kappa : spine shape κ (0 = circle; Irawan 2008 §5.3), > −1.
    width, length : yarn width w and segment length l (same unit).
    kd, ks : RGB diffuse and specular weights of the family.
    """

    psi_deg: float
    umax_deg: float
    kappa: float
    width: float
    length: float
    kd: tuple = (0.2, 0.2, 0.2)
    ks: tuple = (0.3, 0.3, 0.3)

    @property
    def is_filament(self) -> bool:
        return self.psi_deg == 0.0


@dataclass(frozen=True)
class Weave:
    """A woven fabric: two yarn families, the phase function and the coverage."""

    name: str
    warp: Yarn
    weft: Yarn
    warp_coverage: float
    alpha: float = 0.01
    beta: float = 4.0
    ss: float = 0.0
    source: str = ""


def yarn_frame(w, alpha: float):
    """Components (x', y', z) of vectors ``w`` (..., 3) in the frame of a family at α."""
    w = np.asarray(w, float)
    s, c = np.sin(alpha), np.cos(alpha)
    xp = s * w[..., 0] - c * w[..., 1]
    yp = c * w[..., 0] + s * w[..., 1]
    return np.stack([xp, yp, w[..., 2]], axis=-1)


def seeliger(cos_1, cos_2):
    r"""Seeliger law, the attenuation A, with unit albedo: :math:`\frac{1}{4\pi}\frac{c_1c_2}{c_1+c_2}`, 0 if either ≤ 0."""
    c1 = np.maximum(cos_1, 0.0)
    c2 = np.maximum(cos_2, 0.0)
    ok = (c1 > 0) & (c2 > 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(ok, c1 * c2 / np.where(ok, c1 + c2, 1.0), 0.0) / (4 * np.pi)


def von_mises(cos_x, beta: float):
    r"""von Mises density on the circle :math:`e^{\beta\cos x}/(2\pi I_0(\beta))`, overflow-safe.

    The forward-scattering part of f_c.  The source evaluates I_0 by a polynomial
    approximation; we use scipy's exactly scaled ``i0e``.
    """
    return np.exp(beta * (np.asarray(cos_x, float) - 1.0)) / (2 * np.pi * i0e(beta))


def radius_of_curvature(u, umax: float, kappa: float, width: float, length: float):
    """Radius of curvature R(u) of the yarn spine (Irawan 2008 §5.3): a conic chosen by κ.

    r̂ = 1 + κ(1 + 1/tan u_max) selects circle (r̂ = 1, §5.3.1), ellipse (r̂ > 0),
    parabola (r̂ = 0, §5.3.2) or hyperbola (r̂ < 0, §5.3.3); the conic passes the
    segment's end points with slope u_max.  Term by term the source's
    ``radiusOfCurvature``; here clipped to ≥ 0 and with the hyperbola's artanh argument
    kept inside (−1, 1).
    """
    u = np.abs(np.asarray(u, float))
    a = 0.5 * width
    rhat = 1.0 + kappa * (1.0 + 1.0 / np.tan(umax))
    half = 0.5 * length - a * np.sin(umax)
    if abs(rhat - 1.0) < 1e-12:
        R = np.full_like(u, 0.5 * length / np.sin(umax) - a)
    elif rhat > 0:
        tmax = np.arctan(rhat * np.tan(umax))
        bhat = half / np.sin(tmax)
        ahat = bhat / rhat
        t = np.arctan(rhat * np.tan(u))
        R = (bhat**2 * np.cos(t) ** 2 + ahat**2 * np.sin(t) ** 2) ** 1.5 / (ahat * bhat)
    elif rhat < 0:
        tmax = -np.arctanh(rhat * np.tan(umax))
        bhat = half / np.sinh(tmax)
        ahat = bhat / rhat
        t = -np.arctanh(np.clip(rhat * np.tan(u), -1 + 1e-12, 1 - 1e-12))
        R = -((bhat**2 * np.cosh(t) ** 2 + ahat**2 * np.sinh(t) ** 2) ** 1.5) / (ahat * bhat)
    else:
        tmax = np.tan(umax)
        ahat = half / (2.0 * tmax)
        t = np.tan(u)
        R = 2.0 * ahat * (1.0 + t * t) ** 1.5
    return np.maximum(R, 0.0)


def _gauss(n: int, lo: float, hi: float):
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (hi - lo) * x + 0.5 * (hi + lo), 0.5 * (hi - lo) * w


def filament_integral(hp, wip, wrp, norm_sum, yarn: Yarn, ss: float = 0.0, n_v: int = N_V):
    r"""S_fil of one filament family (module docstring), shape (N,).

    ``hp, wip, wrp`` are h, ωi, ωr in the family frame (N, 3); ``norm_sum`` = |ωi + ωr|.
    The integrand is the source's ``evalFilamentIntegrand`` without f_c, the domain
    transform and the highlight window (they cancel in the far field); the v integral
    is Gauss–Legendre with ``n_v`` nodes.
    """
    umax = np.radians(yarn.umax_deg)
    a = 0.5 * yarn.width
    u_star = np.arctan2(hp[:, 1], hp[:, 2])
    valid = np.abs(u_star) < umax
    v, wv = _gauss(n_v, -np.pi / 2, np.pi / 2)
    su, cu = np.sin(u_star)[:, None], np.cos(u_star)[:, None]
    sv, cv = np.sin(v)[None, :], np.cos(v)[None, :]
    n = (sv + 0 * su, su * cv, cu * cv)
    ci = n[0] * wip[:, :1] + n[1] * wip[:, 1:2] + n[2] * wip[:, 2:3]
    cr = n[0] * wrp[:, :1] + n[1] * wrp[:, 1:2] + n[2] * wrp[:, 2:3]
    umax_eff = (1.0 - ss) * umax
    R = radius_of_curvature(np.minimum(np.abs(u_star), umax_eff), umax_eff if ss > 0 else umax, yarn.kappa, yarn.width, yarn.length)
    jac = np.sqrt(np.maximum(1.0 - hp[:, 0] ** 2, 1e-300))  # |(t × h)_x|
    G = a * (R[:, None] + a * cv) / (norm_sum[:, None] * jac[:, None])
    S = np.sum(G * seeliger(ci, cr) * wv[None, :], axis=1)
    if ss > 0:
        x = np.clip((umax - np.abs(u_star)) / (ss * umax), 0.0, 1.0)
        S = S * x * x * (3 - 2 * x)
    return np.where(valid, S, 0.0)


def staple_integral(hp, wip, wrp, norm_sum, yarn: Yarn, n_u: int = N_U):
    r"""S_sta of one staple family (module docstring), shape (N,).

    The integrand is the source's ``evalStapleIntegrand`` without f_c, the domain
    transform and the highlight window, with v* wrapped into (−π, π] (module docstring,
    Departures); the u integral is Gauss–Legendre with ``n_u`` nodes.
    """
    umax = np.radians(yarn.umax_deg)
    psi = np.radians(yarn.psi_deg)
    a = 0.5 * yarn.width
    u, wu = _gauss(n_u, -umax, umax)
    su, cu = np.sin(u)[None, :], np.cos(u)[None, :]
    hx, hy, hz = hp[:, :1], hp[:, 1:2], hp[:, 2:3]
    A = hy * su + hz * cu
    B = hy * cu - hz * su
    with np.errstate(invalid="ignore", divide="ignore"):
        D = B / (np.sqrt(hx**2 + A**2) * np.tan(psi))
    ok = np.abs(D) < 1.0
    v = np.arctan2(-A, hx) + np.arccos(np.clip(D, -1.0, 1.0))  # in (−π, 2π]
    v = np.where(v > np.pi, v - 2 * np.pi, v)  # the same point, as an angle in (−π, π]
    ok &= np.abs(v) <= np.pi / 2
    sv, cv = np.sin(v), np.cos(v)
    n = (sv, su * cv, cu * cv)
    ci = n[0] * wip[:, :1] + n[1] * wip[:, 1:2] + n[2] * wip[:, 2:3]
    cr = n[0] * wrp[:, :1] + n[1] * wrp[:, 1:2] + n[2] * wrp[:, 2:3]
    nh = np.abs(n[0] * hx + n[1] * hy + n[2] * hz)
    R = radius_of_curvature(u, umax, yarn.kappa, yarn.width, yarn.length)[None, :]
    with np.errstate(invalid="ignore", divide="ignore"):
        G = a * (R + a * cv) / (norm_sum[:, None] * np.maximum(nh, 1e-300) * abs(np.sin(psi)))
    integrand = np.where(ok, G * seeliger(ci, cr), 0.0)
    return np.sum(integrand * wu[None, :], axis=1)


class Irawan2012(ReferenceBRDF):
    """Callable far-field IM12 BRDF f_r(wi, wr) -> (..., 3) in 1/sr (module docstring).

    Parameters
    ----------
    weave : Weave or str
        A :class:`Weave` or a preset name (:data:`PRESET_NAMES`).

    >>> f = Irawan2012("silk_charmeuse")
    >>> f.channels
    ('R', 'G', 'B')
    """

    channels = ("R", "G", "B")

    def __init__(self, weave="silk_charmeuse", n_v: int = N_V, n_u: int = N_U):
        if isinstance(weave, str):
            if weave not in PRESETS:
                raise KesbrdfError(f"unknown Irawan-Marschner preset {weave!r}; expected one of {', '.join(PRESET_NAMES)}")
            weave = PRESETS[weave]
        self.weave = weave
        self.n_v = int(n_v)
        self.n_u = int(n_u)
        self.normalisation = 1.0
        self.normalisation = self._normalisation()

    def params(self) -> dict:
        w = self.weave
        return {
            "reference": "irawan2012",
            "preset": w.name,
            "warp": asdict(w.warp),
            "weft": asdict(w.weft),
            "warp_coverage": w.warp_coverage,
            "alpha": w.alpha,
            "beta": w.beta,
            "ss": w.ss,
        }

    def family_lobes(self, wi, wr) -> np.ndarray:
        """f_c·S_j per family (warp, weft), unnormalised, shape (2, N) for (N, 3) inputs."""
        wi = np.asarray(wi, float).reshape(-1, 3)
        wr = np.asarray(wr, float).reshape(-1, 3)
        s = wi + wr
        norm_sum = np.linalg.norm(s, axis=-1)
        h = s / np.maximum(norm_sum, 1e-300)[:, None]
        fc = self.weave.alpha + von_mises(-np.sum(wi * wr, axis=-1), self.weave.beta)
        out = []
        for alpha, yarn in ((0.0, self.weave.warp), (np.pi / 2, self.weave.weft)):
            hp, wip, wrp = yarn_frame(h, alpha), yarn_frame(wi, alpha), yarn_frame(wr, alpha)
            if yarn.is_filament:
                S = filament_integral(hp, wip, wrp, norm_sum, yarn, self.weave.ss, self.n_v)
            else:
                S = staple_integral(hp, wip, wrp, norm_sum, yarn, self.n_u)
            out.append(fc * S)
        return np.stack(out)

    def _normalisation(self) -> float:
        rng = np.random.default_rng(2012)
        def cosine(n):
            r = np.sqrt(rng.random(n))
            p = 2 * np.pi * rng.random(n)
            return np.stack([r * np.cos(p), r * np.sin(p), np.sqrt(np.maximum(1 - r * r, 0))], -1)
        wi, wr = cosine(N_NORMALISATION), cosine(N_NORMALISATION)
        lobes = self.family_lobes(wi, wr)
        mean = float(np.mean(lobes.sum(axis=0)))  # π·f_spec averaged over cos-weighted pairs, k_s = 1
        return 1.0 / max(mean, 1e-300)

    def core(self, wi, wr) -> np.ndarray:
        """f_r (n, 3) of unit pairs above the horizon; edges: :class:`ReferenceBRDF`."""
        w = self.weave
        lobes = self.family_lobes(wi, wr) * self.normalisation
        kd = w.warp_coverage * np.asarray(w.warp.kd) + (1 - w.warp_coverage) * np.asarray(w.weft.kd)
        spec = lobes[0][:, None] * np.asarray(w.warp.ks)[None] + lobes[1][:, None] * np.asarray(w.weft.ks)[None]
        return (kd[None, :] + spec) / np.pi


def _preset(name, warp, weft, coverage, alpha, beta, ss, kd_w, ks_w, kd_f, ks_f):
    return Weave(
        name=name,
        warp=Yarn(*warp, kd=kd_w, ks=ks_w),
        weft=Yarn(*weft, kd=kd_f, ks=ks_f),
        warp_coverage=coverage,
        alpha=alpha,
        beta=beta,
        ss=ss,
        source="yarn (psi, umax, kappa, w, l), alpha, beta, ss and coverage: Irawan's weave data "
        "(LuxRender/Mitsuba tables); kd, ks: kesbrdf guesses",
    )


#: The six fabrics of Irawan's weave data. Yarn tuples are (ψ°, u_max°, κ, w, l);
#: coverage = warp cells / pattern cells.  k_d, k_s (RGB) are guesses chosen so that
#: k_d + k_s ≤ 0.8 per family (colours: indigo denim, ivory silks, grey wool, ...).
PRESETS: dict[str, Weave] = {
    "cotton_denim": _preset("cotton_denim", (-30, 12, 0, 1, 5), (-30, 38, 0, 1, 1), 15 / 18, 0.01, 4.0, 0.0,
                            (0.05, 0.08, 0.25), (0.2, 0.2, 0.25), (0.4, 0.4, 0.38), (0.2, 0.2, 0.2)),
    "silk_shantung": _preset("silk_shantung", (0, 50, -0.5, 2, 4), (0, 23, -0.3, 4, 4), 16 / 48, 0.02, 1.5, 0.5,
                             (0.3, 0.2, 0.1), (0.4, 0.4, 0.4), (0.3, 0.2, 0.1), (0.4, 0.4, 0.4)),
    "silk_charmeuse": _preset("silk_charmeuse", (0, 40, 2, 1, 9), (0, 60, 0, 1, 1), 45 / 50, 0.02, 7.3, 0.5,
                              (0.2, 0.18, 0.15), (0.4, 0.4, 0.4), (0.2, 0.18, 0.15), (0.2, 0.2, 0.2)),
    "cotton_twill": _preset("cotton_twill", (-30, 24, 0, 1, 6), (-30, 36, 0, 2, 1), 24 / 32, 0.01, 4.0, 0.0,
                            (0.35, 0.3, 0.2), (0.2, 0.2, 0.2), (0.35, 0.3, 0.2), (0.2, 0.2, 0.2)),
    "wool_gabardine": _preset("wool_gabardine", (30, 30, 0, 2, 6), (30, 30, 0, 3, 2), 36 / 54, 0.01, 4.0, 0.0,
                              (0.3, 0.3, 0.3), (0.15, 0.15, 0.15), (0.3, 0.3, 0.3), (0.15, 0.15, 0.15)),
    "polyester_lining": _preset("polyester_lining", (0, 22, -0.7, 1, 1), (0, 16, -0.7, 1, 1), 0.5, 0.015, 4.0, 0.5,
                                (0.25, 0.1, 0.1), (0.45, 0.45, 0.45), (0.25, 0.1, 0.1), (0.45, 0.45, 0.45)),
}
PRESET_NAMES = tuple(PRESETS)


def with_ks(weave: Weave, ks_warp, ks_weft) -> Weave:
    """A copy of ``weave`` with other specular weights (e.g. one family switched off)."""
    return replace(weave, warp=replace(weave.warp, ks=tuple(ks_warp)), weft=replace(weave.weft, ks=tuple(ks_weft)))
