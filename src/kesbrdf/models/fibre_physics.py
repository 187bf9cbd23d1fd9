r"""A few-parameter woven-cloth prior and its fit (docs/prior.md).

The model (docs/prior.md, after Irawan & Marschner 2012)
---------------------------------------------------------------------------------

.. math::

    f_r(\omega_i, \omega_r) = k_d + \Phi(\theta_d)\sum_{j\in\{\text{warp},\text{weft}\}} k_{s,j}\,S_j(\omega_i,\omega_r)

with k_d and k_{s,j} per channel (1/sr).  Family j lies along y' = (cos α_j, sin α_j, 0)
(α = 0 warp, π/2 weft, plus an optional common axis offset δ for data in a sample
frame); x' = (sin α, −cos α, 0) is across it; h' is the half vector in that frame.

Filament family (fibres along the yarn; IM12 §5.1):
    u* = atan2(h'_y, h'_z), t = (0, cos u*, −sin u*) and

    .. math:: S = \frac{P(u^*)\,N(\phi)\,\bar A}{|\omega_i+\omega_r|\sqrt{1-h'^2_x}}

    with Ā the mean over v ∈ (−π/2, π/2) of the Seeliger law on n = (sin v, sin u* cos v,
    cos u* cos v).
Staple family (twist ψ; IM12 §5.2 with a general tilt profile): for each tilt u of a
    fixed quadrature, v*(u) from D = B/(√(h'_x² + A²) tan ψ), A = h'_y sin u + h'_z cos u,
    B = h'_y cos u − h'_z sin u, v* = atan2(−A, h'_x) + acos D (|D| < 1, |v*| < π/2), and

    .. math:: S = \frac{\sum_u P(u)\,\Delta u\,N(\phi)\,A_S(n\cdot\omega_i', n\cdot\omega_r')/|n\cdot h'|}{|\omega_i+\omega_r|\,|\sin\psi|}.

Shared terms:
    tilt profile :math:`P(u) = \sigma((u-u_{lo})/s)\,\sigma((u_{hi}-u)/s)\,e^{c_2u^2}`
    (σ logistic), azimuthal lobe :math:`N(\phi) = (1-\rho)^2/(1-2\rho\cos\phi+\rho^2) + 10^{-4}`
    with φ the angle between the projections of ωi and ωr on the plane ⟂ t, and the
    θ_d law Φ = F(η=1.5, cos θ_d)/F(η=1.5, cos 45°) (cos θ_d = ωi·h), times
    exp(d₁x + d₂x²), x = ωi·ωr, when the data spans several θ_d.

Reciprocal by construction (every factor is symmetric in ωi ↔ ωr).

The fit (:func:`fit_prior`)
---------------------------
Bounded least squares on log values, residual
r = (ln(f + ε) − ln(y + ε))/σ_ln with ε = 10⁻⁴·max y per channel and
σ_ln = max(σ_y/(y + ε), 0.01) when the measurement carries uncertainties (1 otherwise).
Stage 1 fits filament/filament from six starts (u_hi = −u_lo ∈ {6, 20, 45}°, ρ ∈ {0, 0.6});
stage 2 the staple variants from the stage-1 geometry with twist starts ±20°, ±40°.
With more than :data:`MULTISTART_MAX_ROWS` rows the starts run on a stratified
subsample and the best start of every variant is polished on all rows.  The variant
with the lowest BIC wins: BIC = χ² + k ln n when uncertainties are given (χ² = Σ r²),
otherwise n ln(RSS/n) + k ln n.

Derivatives (:func:`evaluate_with_jacobian`, docs/prior.md §3): analytic for every
parameter, the staple twist ψ included (through v*(u), n, t and cos φ), except the axis
offset δ, which rotates every frame and is a one-sided difference (one geometry
evaluation per Jacobian).  The residual's Jacobian is (∂f/∂θ)/((f + ε)σ).  Fit times:
docs/results.md, "prior".
"""

from __future__ import annotations

import functools
import math
import time
from collections import ChainMap
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.optimize import least_squares

from kesbrdf.errors import MeasurementError, ModelError
from kesbrdf.models.body import log_body_upper
from kesbrdf.models.mappings import evaluate_pairs
from kesbrdf.optics import fresnel_dielectric

__all__ = [
    "FAMILY_KINDS",
    "PriorSpec",
    "FibrePrior",
    "fit_prior",
    "evaluate_with_jacobian",
    "THETA_D_ETA",
    "U_NODES",
    "V_NODES",
    "DU",
    "tilt_profile",
]

FAMILY_KINDS = ("filament", "staple")
#: Refractive index of the default θ_d law (fibre-prior.md: close to what real CUReT data gives).
THETA_D_ETA = 1.5
#: Fixed tilt quadrature of staple families (midpoints over ±U_RANGE).
N_U = 32
U_RANGE = math.radians(85.0)
#: Across-yarn nodes of Ā for filament families.
N_V = 12
#: Floor of the data, relative to each channel's peak (log residuals stay finite).
REL_FLOOR = 1e-4
#: Smallest σ of a log residual when uncertainties are given (model error floor).
MIN_SIGMA_LOG = 0.01
#: Rows above which the multistart runs on a subsample.
MULTISTART_MAX_ROWS = 240
#: Function evaluations of each start before the best one is polished.
START_NFEV = 40
#: Spread of ωi·ωr above which the θ_d law gets free coefficients d₁, d₂.
THETA_D_SPREAD = 0.05
#: Fewest samples off the θ_d = 45° slice (|ωi·ωr| > THETA_D_SPREAD) for the free θ_d law:
#: 16 = one specular group at each of the four orientations, the smallest θ_d extension
#: `kesbrdf plan` offers.  Eight out-of-plane samples once drove d₂ to its bound and the
#: law to 10⁴× at θ_i = 70° (a user's plan); with fewer, the Fresnel law stays fixed.
MIN_THETA_D_SAMPLES = 16


_F45 = float(fresnel_dielectric(math.cos(math.pi / 4), THETA_D_ETA))


@dataclass(frozen=True)
class PriorSpec:
    """Structure of a prior: family kinds, channel count, free axes, free θ_d law.

    ``theta_d_range``: the (min, max) of x = ωi·ωr over the rows the free θ_d law was
    fitted on.  Outside it the law is held at its value at the nearer end (docs/prior.md, "θ_d law":
    exp(d₁x + d₂x²) with x clipped): a quadratic in the exponent fitted on one extra
    incidence line otherwise extrapolates to e^±12 at retro-reflection (x → 1), which the
    paper's line and one other line never see.  None: not clipped (files written before
    the range was kept, and a θ_d law that did not come from the data).
    """

    kinds: tuple = ("filament", "filament")
    n_channels: int = 1
    free_axes: bool = False
    free_theta_d: bool = False
    theta_d_range: tuple | None = None

    def __post_init__(self):
        if self.theta_d_range is not None:  # a (min, max) pair of floats: hashable, checked
            try:
                lo, hi = (float(v) for v in self.theta_d_range)
            except (TypeError, ValueError):
                lo = hi = float("nan")
            if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
                raise ModelError(f"fibre prior theta_d_range: expected [min, max] of finite numbers, got "
                                 f"{str(self.theta_d_range)[:60]}")
            object.__setattr__(self, "theta_d_range", (lo, hi))

    def held_x(self, x):
        """x = ωi·ωr as the θ_d law reads it: clipped to :attr:`theta_d_range` when set."""
        return x if self.theta_d_range is None else np.clip(x, *self.theta_d_range)

    def names(self) -> list[str]:
        return list(_spec_names(self))

    def index(self) -> dict:
        return dict(_spec_index(self))

    def _names(self) -> list[str]:
        C = self.n_channels
        out = [f"log_kd_{c}" for c in range(C)]
        for fam, kind in zip(("warp", "weft"), self.kinds):
            out += [f"{fam}_log_ks_{c}" for c in range(C)]
            out += [f"{fam}_u_lo", f"{fam}_u_hi", f"{fam}_log_s", f"{fam}_c2", f"{fam}_rho"]
            if kind == "staple":
                out.append(f"{fam}_psi")
        if self.free_axes:
            out.append("axis_offset")
        if self.free_theta_d:
            out += ["d1", "d2"]
        return out

    def bounds(self, psi_sign=None):
        lo, hi = [], []
        signs = dict(zip(("warp", "weft"), psi_sign or (1, 1)))
        for n in self.names():
            if n.startswith("log_kd") or "log_ks" in n:
                a, b = -40.0, 8.0
            elif n.endswith("u_lo") or n.endswith("u_hi"):
                a, b = -math.radians(84), math.radians(84)
            elif n.endswith("log_s"):
                a, b = math.log(math.radians(0.3)), math.log(math.radians(40))
            elif n.endswith("c2"):
                # c₂ > 0 lets the profile grow toward |u| → 85° where the data may hold
                # nothing (a fit to velvet reached c₂ = 30: 10³× too bright at the rim);
                # capped so exp(c₂u²) ≤ e^4.4 anywhere
                a, b = -30.0, 2.0
            elif n.endswith("rho"):
                a, b = -0.95, 0.95
            elif n.endswith("psi"):
                s = signs[n.split("_")[0]]
                a, b = (math.radians(4), math.radians(80)) if s > 0 else (-math.radians(80), -math.radians(4))
            elif n == "axis_offset":
                a, b = -math.pi, math.pi
            else:  # d1, d2
                a, b = -6.0, 6.0
            lo.append(a)
            hi.append(b)
        return np.array(lo), np.array(hi)


@functools.lru_cache(maxsize=64)
def _spec_names(spec: PriorSpec) -> tuple:
    """The parameter names of a spec, built once (evaluate_batch asks on every call of a fit)."""
    return tuple(spec._names())


@functools.lru_cache(maxsize=64)
def _spec_index(spec: PriorSpec) -> dict:
    return {n: i for i, n in enumerate(_spec_names(spec))}


@functools.lru_cache(maxsize=64)
def _spec_layout(spec: PriorSpec):
    """Column indices :func:`evaluate_with_jacobian` reads and fills, built once per spec: the
    k_d columns and, per family, (its k_s columns, its Jacobian shape columns u_lo, u_hi, ln s,
    c₂, ρ and then ψ for a staple family, the five shape parameters' indices as a list, its
    twist column or None for a filament family)."""
    idx = _spec_index(spec)
    C = spec.n_channels
    families = []
    for fam, kind in zip(("warp", "weft"), spec.kinds):
        shape = [idx[f"{fam}_{n}"] for n in ("u_lo", "u_hi", "log_s", "c2", "rho")]
        psi = idx[f"{fam}_psi"] if kind == "staple" else None
        families.append((np.array([idx[f"{fam}_log_ks_{c}"] for c in range(C)]),
                         np.array(shape + ([psi] if psi is not None else [])), shape, psi))
    return np.array([idx[f"log_kd_{c}"] for c in range(C)]), tuple(families)


def _sigmoid(x):
    return 0.5 * (1.0 + np.tanh(0.5 * x))


def _family_frame(w, alpha):
    """w (..., 3) in the frame of a family at angle(s) α (broadcast over leading axes)."""
    s, c = np.sin(alpha), np.cos(alpha)
    return s * w[..., 0] - c * w[..., 1], c * w[..., 0] + s * w[..., 1], w[..., 2] + 0 * s


def _seeliger(ci, cr):
    with np.errstate(invalid="ignore", divide="ignore"):
        return _seeliger_quiet(ci, cr)


def _seeliger_quiet(ci, cr):
    """:func:`_seeliger` for callers that already silence invalid/divide warnings."""
    ok = (ci > 0) & (cr > 0)
    return np.where(ok, ci * cr / np.where(ok, ci + cr, 1.0), 0.0)


def _lobe_rho(cos_phi, rho):
    return (1.0 - rho) ** 2 / (1.0 - 2.0 * rho * cos_phi + rho * rho) + 1e-4


def _cos_phi(wx, wy, wz, rx, ry, rz, tx, ty, tz):
    """cos of the angle between the projections of ωi and ωr on the plane ⟂ t."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return _cos_phi_quiet(wx, wy, wz, rx, ry, rz, tx, ty, tz)


def _cos_phi_quiet(wx, wy, wz, rx, ry, rz, tx, ty, tz):
    """:func:`_cos_phi` for callers that already silence invalid/divide warnings."""
    di = wx * tx + wy * ty + wz * tz
    dr = rx * tx + ry * ty + rz * tz
    pix, piy, piz = wx - di * tx, wy - di * ty, wz - di * tz
    prx, pry, prz = rx - dr * tx, ry - dr * ty, rz - dr * tz
    num = pix * prx + piy * pry + piz * prz
    den = np.sqrt((pix**2 + piy**2 + piz**2) * (prx**2 + pry**2 + prz**2))
    return np.clip(np.where(den > 1e-300, num / np.maximum(den, 1e-300), 1.0), -1.0, 1.0)


def _dot(p, q):
    """p·q of two 3-tuples of arrays, summed as p_x q_x + p_y q_y + p_z q_z."""
    return p[0] * q[0] + p[1] * q[1] + p[2] * q[2]


def _cos_phi_derivative(w, r, t, dt, dots=None):
    """d cos φ of :func:`_cos_phi` for a change dt of a unit t (w, r, t, dt: 3-tuples of arrays).

    With a = w·t, b = r·t: cos φ = (w·r − ab)/√((|w|² − a²)(|r|² − b²)), so
    d cos φ = −(b da + a db)/den + cos φ (a da/(|w|² − a²) + b db/(|r|² − b²)),
    da = w·dt, db = r·dt; zero where cos φ is clipped or undefined.  ``dots``: (w·w, r·r, w·r)
    when the caller has them (they do not depend on t).
    """
    with np.errstate(invalid="ignore", divide="ignore"):
        return _cos_phi_derivative_quiet(w, r, t, dt, dots)


def _cos_phi_derivative_quiet(w, r, t, dt, dots=None):
    """:func:`_cos_phi_derivative` for callers that already silence invalid/divide warnings."""
    ww, rr_, wr = dots if dots is not None else (_dot(w, w), _dot(r, r), _dot(w, r))
    a, b, da, db = _dot(w, t), _dot(r, t), _dot(w, dt), _dot(r, dt)
    ii, rr = ww - a * a, rr_ - b * b
    den = np.sqrt(np.maximum(ii * rr, 0.0))
    c = (wr - a * b) / den
    d = -(b * da + a * db) / den + c * (a * da / ii + b * db / rr)
    return np.where((den > 1e-300) & (np.abs(c) < 1.0), d, 0.0)


def _lobe_cos_derivative(cos_phi, rho):
    """∂N/∂cos φ = 2ρ(1 − ρ)²/(1 − 2ρ cos φ + ρ²)²."""
    q = 1.0 - 2.0 * rho * cos_phi + rho * rho
    return 2.0 * rho * (1.0 - rho) ** 2 / (q * q)


def _profile(u, lo, hi, log_s, c2):
    s = np.exp(log_s)
    return _sigmoid((u - lo) / s) * _sigmoid((hi - u) / s) * np.exp(np.clip(c2 * u * u, -700, 50))


def _profile_derivatives(u, lo, hi, log_s, c2):
    """P(u) of :func:`_profile` and dP/d(u_lo, u_hi, log s, c₂) stacked on a leading axis.

    With a = (u − u_lo)/s, b = (u_hi − u)/s and σ' = σ(1 − σ):
    ∂P/∂u_lo = −P σ(−a)/s, ∂P/∂u_hi = P σ(−b)/s, ∂P/∂ln s = −P (a σ(−a) + b σ(−b)),
    ∂P/∂c₂ = P u² inside the clip of the exponent and 0 where it clips.
    """
    s = np.exp(log_s)
    a, b = (u - lo) / s, (hi - u) / s
    q = c2 * u * u
    P = _sigmoid(a) * _sigmoid(b) * np.exp(np.clip(q, -700, 50))
    na, nb = _sigmoid(-a), _sigmoid(-b)  # 1 − σ without the cancellation
    dP = np.empty((4,) + np.shape(P))
    dP[0] = -P * na / s
    dP[1] = P * nb / s
    dP[2] = -P * (a * na + b * nb)
    dP[3] = np.where((q > -700) & (q < 50), P * u * u, 0.0)
    return P, dP


def _lobe_rho_derivative(cos_phi, rho):
    """∂N/∂ρ = −2(1 − ρ²)(1 − cos φ)/(1 − 2ρ cos φ + ρ²)²."""
    q = 1.0 - 2.0 * rho * cos_phi + rho * rho
    return -2.0 * (1.0 - rho * rho) * (1.0 - cos_phi) / (q * q)


def _lobe_with_derivatives(cos_phi, rho):
    """(N, ∂N/∂ρ, ∂N/∂cos φ) of :func:`_lobe_rho`, :func:`_lobe_rho_derivative` and
    :func:`_lobe_cos_derivative` with their common denominator q = 1 − 2ρ cos φ + ρ² and q²
    formed once (the same operations, so the same values)."""
    q = 1.0 - 2.0 * rho * cos_phi + rho * rho
    q2 = q * q
    return ((1.0 - rho) ** 2 / q + 1e-4, -2.0 * (1.0 - rho * rho) * (1.0 - cos_phi) / q2,
            2.0 * rho * (1.0 - rho) ** 2 / q2)


_V_NODES = (np.arange(N_V) + 0.5) * (np.pi / N_V) - np.pi / 2
_U_NODES = (np.arange(N_U) + 0.5) * (2 * U_RANGE / N_U) - U_RANGE
_DU = 2 * U_RANGE / N_U
#: Public names of the fixed quadratures, for ports of the model (the Mitsuba plugin
#: ``kesbrdf.render.prior_bsdf``): across-yarn nodes v of Ā, staple tilt nodes u, their spacing.
V_NODES, U_NODES, DU = _V_NODES, _U_NODES, _DU


def tilt_profile(u, u_lo, u_hi, log_s, c2):
    """The tilt profile P(u) = σ((u − u_lo)/s)·σ((u_hi − u)/s)·exp(c₂u²), s = e^{log_s} (module docstring)."""
    return _profile(u, u_lo, u_hi, log_s, c2)


def _filament_geometry(hx, hy, hz, ix, iy, iz, rx, ry, rz, norm_sum):
    """Parameter-free part of a filament family: (u*, cos φ, G0), each (K, N).

    S = P(u*) N(φ) G0 with G0 = Ā / (|ωi+ωr| √(1 − h'_x²)).
    """
    u = np.arctan2(hy, hz)
    su, cu = np.sin(u), np.cos(u)
    sv, cv = np.sin(_V_NODES), np.cos(_V_NODES)
    ci = ix[..., None] * sv + (iy * su)[..., None] * cv + (iz * cu)[..., None] * cv
    cr = rx[..., None] * sv + (ry * su)[..., None] * cv + (rz * cu)[..., None] * cv
    A_bar = _seeliger(ci, cr).mean(axis=-1)
    cphi = _cos_phi(ix, iy, iz, rx, ry, rz, 0.0, cu, -su)
    jac = np.sqrt(np.maximum(1.0 - hx * hx, 1e-12))
    return u, cphi, A_bar / (norm_sum * jac)


def _staple_base(hx, hy, hz, ix, iy, iz, rx, ry, rz, norm_sum):
    """The twist-free part of :func:`_staple_geometry` for one frame (cached per family and offset).

    A = h'_y sin u + h'_z cos u, B = h'_y cos u − h'_z sin u, √(h'_x² + A²) and
    atan2(−A, h'_x) on the tilt nodes u, with the frame's components broadcast to (K, N, 1).
    """
    u = _U_NODES
    su, cu = np.sin(u), np.cos(u)
    e = lambda a: a[..., None]  # noqa: E731  (K, N) -> (K, N, 1)
    A = e(hy) * su + e(hz) * cu
    Bq = e(hy) * cu - e(hz) * su
    root = np.sqrt(e(hx) ** 2 + A * A)
    v0 = np.arctan2(-A, e(hx))
    # the frame's components, one row each, for gathering at the valid nodes in one step
    # and ωi'·ωi', ωr'·ωr', ωi'·ωr' (∂cos φ/∂ψ needs them; they do not depend on ψ)
    wi_, wr_ = (ix, iy, iz), (rx, ry, rz)
    rows = np.stack([np.broadcast_to(a, hx.shape).reshape(-1) for a in (
        ix, iy, iz, rx, ry, rz, hx, hy, hz, norm_sum, _dot(wi_, wi_), _dot(wr_, wr_), _dot(wi_, wr_))])
    return (su, cu, Bq, root, v0, e(hx), e(hy), e(hz), (e(ix), e(iy), e(iz)), (e(rx), e(ry), e(rz)), e(norm_sum),
            rows, np.stack([su, cu]))


def _staple_geometry(hx, hy, hz, ix, iy, iz, rx, ry, rz, norm_sum, psi):
    """ψ-dependent part of a staple family: (G, cos φ, ∂G/∂ψ, ∂cos φ/∂ψ), each (K, N, U).

    For K distinct (frame, ψ). G = [valid] · A_S(n·ωi', n·ωr') / (|n·h'| |ωi+ωr| |sin ψ|),
    so that S = Σ_u P(u) Δu N(φ) G.  The ψ-derivatives follow v*(u):
    ∂D/∂ψ = −D/(sin ψ cos ψ), ∂v*/∂ψ = −(∂D/∂ψ)/√(1 − D²), n' = ∂n/∂v · ∂v*/∂ψ, and
    t = t(v*, ψ) through both arguments; the validity mask is held fixed (its edges are
    jumps of S, not part of the derivative).
    """
    return _staple_psi(_staple_base(hx, hy, hz, ix, iy, iz, rx, ry, rz, norm_sum), psi)


def _staple_psi(base, psi):
    """:func:`_staple_geometry` from the frame's :func:`_staple_base` (the fit evaluates many ψ on one frame)."""
    entry = _StapleEntry(base, psi)
    return (entry.G, entry.cphi, *entry.derivatives())


class _StapleEntry:
    """One (frame, ψ) of :func:`_staple_geometry`: G and cos φ at once, the ψ-derivatives when asked.

    Only the valid tilt nodes (|D| < 1 and |v*| < π/2, 17–62 % of them in the paper
    protocol) are computed: :attr:`k` holds their flat indices into the (K, N, U) grid and
    ``G_k``, ``cphi_k`` their values.  Elsewhere G = 0, ∂G/∂ψ = ∂cos φ/∂ψ = 0 and cos φ
    (finite there too) only ever multiplies G, so :attr:`G` and :attr:`cphi` fill those
    nodes with 0 (cos φ = 0 instead of its value: every sum over u is the same bit for bit).
    Each valid node goes through the same operations in the same order as over the whole grid.

    A fit evaluates the residuals at every trial step but the Jacobian only at accepted
    ones, so the derivatives (half the work) wait for :meth:`derivatives`, which finishes
    the same computation from the kept intermediates (the same operations in the same order).
    """

    def __init__(self, base, psi):
        Bq, root, v0, rows, sucu = base[2], base[3], base[4], base[11], base[12]
        self.shape = Bq.shape  # (K, N, U)
        K, N, U = self.shape
        e = lambda a: a[..., None]  # noqa: E731  (K, N) -> (K, N, 1)
        tpsi = e(np.tan(psi))
        with np.errstate(invalid="ignore", divide="ignore"):
            D = Bq / (root * tpsi)
        k = np.flatnonzero(np.abs(D) < 1.0)
        D = D.reshape(-1)[k]
        v = v0.reshape(-1)[k] + np.arccos(np.clip(D, -1.0, 1.0))  # in (−π, 2π]
        v = np.where(v > np.pi, v - 2 * np.pi, v)  # the same point in (−π, π] (irawan2012: v* wrap)
        keep = np.abs(v) < np.pi / 2
        k, D, v = k[keep], D[keep], v[keep]
        self.k = k
        self.u_index = k % U
        row = k // U  # index into the (K, N) frame arrays
        ix, iy, iz, rx, ry, rz, hx, hy, hz, ns, *dots = rows[:, row]
        wi_, wr_ = (ix, iy, iz), (rx, ry, rz)
        su, cu = sucu[:, self.u_index]
        sp, cp = e(np.sin(psi)), e(np.cos(psi))  # (K, 1, 1)
        sp, cp = (a.reshape(1) if K == 1 else a.reshape(-1)[row // N] for a in (sp, cp))
        scale = 1.0 / (ns * np.abs(sp))
        sv, cv = np.sin(v), np.cos(v)
        nx, ny, nz = sv, su * cv, cu * cv
        ci = nx * ix + ny * iy + nz * iz
        cr = nx * rx + ny * ry + nz * rz
        nh_signed = nx * hx + ny * hy + nz * hz
        nh = np.abs(nh_signed)
        tx = -cv * sp
        ty = cu * cp + su * sv * sp
        tz = -su * cp + cu * sv * sp
        with np.errstate(invalid="ignore", divide="ignore"):
            self.cphi_k = _cos_phi_quiet(*wi_, *wr_, tx, ty, tz)
            AS = _seeliger_quiet(ci, cr)
        nhf = np.maximum(nh, 1e-9)
        self.G_k = AS / nhf * scale
        self._lazy = (su, cu, hx, hy, hz, wi_, wr_, dots, D, sv, cv, sp, cp, ci, cr, nh, nh_signed, nhf, AS, scale,
                      tx, ty, tz)
        self._derivatives = None
        self._dense = {}
        #: bytes held, for the cache's bound: k, the u index, G, cos φ and up to 27 node arrays kept
        self.nbytes = 31 * 8 * k.size

    def dense(self, values) -> np.ndarray:
        """Values at the valid nodes as a (K, N, U) array, 0 elsewhere."""
        out = np.zeros(self.shape)
        out.reshape(-1)[self.k] = values
        return out

    @property
    def G(self):
        if "G" not in self._dense:
            self._dense["G"] = self.dense(self.G_k)
        return self._dense["G"]

    @property
    def cphi(self):
        if "cphi" not in self._dense:
            self._dense["cphi"] = self.dense(self.cphi_k)
        return self._dense["cphi"]

    def derivatives_k(self):
        """(∂G/∂ψ, ∂cos φ/∂ψ) at the valid nodes (:attr:`k`)."""
        if self._derivatives is None:
            su, cu, hx, hy, hz, wi_, wr_, dots, D, sv, cv, sp, cp, ci, cr, nh, nh_signed, nhf, AS, scale, tx, ty, tz = self._lazy
            ix, iy, iz = wi_
            rx, ry, rz = wr_
            G = self.G_k
            with np.errstate(invalid="ignore", divide="ignore"):
                dv = D / (np.sqrt(np.maximum(1.0 - D * D, 1e-300)) * sp * cp)
                dnx, dny, dnz = cv * dv, -su * sv * dv, -cu * sv * dv
                dci = dnx * ix + dny * iy + dnz * iz
                dcr = dnx * rx + dny * ry + dnz * rz
                dnh = np.where(nh > 1e-9, np.sign(nh_signed) * (dnx * hx + dny * hy + dnz * hz), 0.0)
                pos = (ci > 0) & (cr > 0)
                dAS = np.where(pos, (cr * cr * dci + ci * ci * dcr) / np.where(pos, (ci + cr) ** 2, 1.0), 0.0)
                dG = (dAS / nhf - AS * dnh / (nhf * nhf)) * scale - G * (cp / sp)
                dt = (-cv * cp + sv * sp * dv,
                      -cu * sp + su * sv * cp + su * cv * sp * dv,
                      su * sp + cu * sv * cp + cu * cv * sp * dv)
                dcphi = _cos_phi_derivative_quiet(wi_, wr_, (tx, ty, tz), dt, dots)
            self._derivatives = (dG, dcphi)
            self._lazy = None  # the intermediates are not needed again
        return self._derivatives

    def derivatives(self):
        """(∂G/∂ψ, ∂cos φ/∂ψ), each (K, N, U) (:func:`_staple_geometry`)."""
        return tuple(self.dense(a) for a in self.derivatives_k())


def _staple_cached(cache, fam, alpha, offset, psi, h, wi, wr, norm_sum) -> _StapleEntry:
    """The :class:`_StapleEntry` of one family at one (δ, ψ) (K = 1), its ψ-free base cached per (family, δ)."""
    def compute():
        base = _cached(cache, ("stb", fam, offset), lambda: _staple_base(
            *(q[None] for q in _frames(h, wi, wr, alpha + offset)), norm_sum[None]))
        return _StapleEntry(base, np.array([[psi]]))

    return _cached(cache, ("sta", fam, offset, psi), compute)


def _staple_combine(G, cphi, lo, hi, log_s, c2, rho):
    """S = Σ_u P(u) Δu N(φ) G for parameters (B, 1) and geometry (B, N, U)."""
    e = lambda a: a[..., None]  # noqa: E731
    P = _profile(_U_NODES, e(lo), e(hi), e(log_s), e(c2))  # (B, 1, U)
    return np.sum(P * _lobe_rho(cphi, e(rho)) * G, axis=-1) * _DU


def _staple_combine_k(entry: _StapleEntry, lo, hi, log_s, c2, rho):
    """:func:`_staple_combine` for one parameter vector (B = 1) from the valid nodes of ``entry``
    (the products are 0 at the others, as over the whole grid)."""
    e = lambda a: a[..., None]  # noqa: E731
    P = _profile(_U_NODES, e(lo), e(hi), e(log_s), e(c2))  # (1, 1, U)
    terms = P.reshape(-1)[entry.u_index] * _lobe_rho(entry.cphi_k, e(rho).reshape(-1)) * entry.G_k
    return np.sum(entry.dense(terms), axis=-1) * _DU


#: Bound of a geometry cache (a staple entry holds four (N, U) arrays: 0.9 MB at N = 900).
CACHE_MAX_ENTRIES = 256
CACHE_MAX_BYTES = 2**28


def _cached(cache, key, compute):
    if cache is None:
        return compute()
    if key not in cache:
        value = compute()
        size = value.nbytes if isinstance(value, _StapleEntry) else sum(a.nbytes for a in value if isinstance(a, np.ndarray))
        used = cache.get("nbytes", 0) + size
        if len(cache) > CACHE_MAX_ENTRIES or used > CACHE_MAX_BYTES:
            cache.clear()
            used = size
        cache[key] = value
        cache["nbytes"] = used
    return cache[key]


def _base(wi, wr):
    """Parameter-free shared terms: |ωi+ωr|, h, Φ(θ_d) of the fixed law, x = ωi·ωr."""
    s = wi + wr
    norm_sum = np.linalg.norm(s, axis=-1)
    h = s / np.maximum(norm_sum, 1e-300)[:, None]
    Phi = fresnel_dielectric(np.sum(wi * h, axis=-1), THETA_D_ETA) / _F45
    return norm_sum, h, Phi, np.sum(wi * wr, axis=-1)


def _frames(h, wi, wr, alpha):
    """h', ωi', ωr' components in the frame of a family at angle α (9 arrays)."""
    return (*_family_frame(h, alpha), *_family_frame(wi, alpha), *_family_frame(wr, alpha))


def evaluate_batch(spec: PriorSpec, theta, wi, wr, cache: dict | None = None) -> np.ndarray:
    """f_r for a batch of parameter vectors: theta (B, P), wi/wr (N, 3) → (B, N, C).

    Directions must be above the horizon (callers mask the others).  ``cache`` (a dict
    owned by the caller, for one fixed (wi, wr)) keeps the parameter-free geometry of
    each family per axis offset (and twist, for staple families) between calls.
    """
    theta = np.atleast_2d(np.asarray(theta, float))
    idx = _spec_index(spec)
    C = spec.n_channels
    B = theta.shape[0]
    col = lambda name: theta[:, idx[name]][:, None]  # noqa: E731  (B, 1)

    norm_sum, h, Phi, x = _cached(cache, "base", lambda: _base(wi, wr))
    Phi = Phi[None, :]
    if spec.free_theta_d:
        x = spec.held_x(x)
        Phi = Phi * np.exp(np.clip(col("d1") * x[None] + col("d2") * x[None] ** 2, -50, 50))
    offset = col("axis_offset")[:, 0] if spec.free_axes else np.zeros(B)
    f = np.exp(theta[:, [idx[f"log_kd_{c}"] for c in range(C)]])[:, None, :] + 0.0 * norm_sum[None, :, None]

    for fam, kind, alpha in zip(("warp", "weft"), spec.kinds, (0.0, np.pi / 2)):
        shape_params = (col(f"{fam}_u_lo"), col(f"{fam}_u_hi"), col(f"{fam}_log_s"), col(f"{fam}_c2"), col(f"{fam}_rho"))
        lo, hi, log_s, c2, rho = shape_params
        if kind == "filament":
            if B == 1:  # one parameter vector (every call of the fit): no distinct offsets to sort out
                part = _cached(cache, ("fil", fam, float(offset[0])),
                               lambda: _filament_geometry(*_frames(h, wi, wr, alpha + offset[0]), norm_sum))
                u, cphi, G0 = (a[None] for a in part)
            else:
                uniq, inv = np.unique(offset, return_inverse=True)
                parts = [_cached(cache, ("fil", fam, float(o)), lambda o=o: _filament_geometry(*_frames(h, wi, wr, alpha + o), norm_sum))
                         for o in uniq]
                u, cphi, G0 = (np.stack([p[k] for p in parts])[np.asarray(inv).reshape(-1)] for k in range(3))
            S = _profile(u, lo, hi, log_s, c2) * _lobe_rho(cphi, rho) * G0
        else:
            # the expensive geometry depends only on (δ, ψ): evaluate it once per distinct pair
            if B == 1:
                entry = _staple_cached(cache, fam, alpha, float(offset[0]), float(theta[0, idx[f"{fam}_psi"]]),
                                       h, wi, wr, norm_sum)
                S = _staple_combine_k(entry, *shape_params)
            else:
                key = np.column_stack([offset, col(f"{fam}_psi")[:, 0]])
                uniq, inv = np.unique(key, axis=0, return_inverse=True)
                parts = [_staple_cached(cache, fam, alpha, float(o), float(p), h, wi, wr, norm_sum) for o, p in uniq]
                inv = np.asarray(inv).reshape(-1)
                G = np.concatenate([q.G for q in parts])[inv]
                cphi = np.concatenate([q.cphi for q in parts])[inv]
                S = _staple_combine(G, cphi, *shape_params)
        ks = np.exp(theta[:, [idx[f"{fam}_log_ks_{c}"] for c in range(C)]])  # (B, C)
        f = f + (Phi * S)[..., None] * ks[:, None, :]
    return f


#: Relative step of the one-sided difference of the axis-offset column δ of the Jacobian.
#: The staple sum is only piecewise smooth in δ (a node drops out where |D| → 1 or
#: |v*| → π/2), so a step straddles such an edge with a probability ∝ step; 1e-7 keeps
#: that rare while the truncation error (∝ step·|f''/f'|, |f''/f'| ≲ 10³ from 1/|n·h'|)
#: stays ≲ 1e-4 relative and the rounding error ~10⁻⁹.
GEOMETRY_STEP = 1e-7


def evaluate_with_jacobian(spec: PriorSpec, theta, wi, wr, cache: dict | None = None):
    r"""f_r and its Jacobian at one parameter vector: theta (P,), wi/wr (N, 3) → f (N, C), J (N, C, P).

    Analytic columns (they reuse the cached geometry and the products of f):

    * ∂f/∂ln k_d,c = k_d,c and ∂f/∂ln k_s,j,c = Φ k_s,j,c S_j;
    * the shape parameters (u_lo, u_hi, ln s, c₂, ρ) of family j:
      ∂f/∂θ = Φ k_s,j ∂S_j/∂θ with ∂P/∂θ of :func:`_profile_derivatives` and ∂N/∂ρ of
      :func:`_lobe_rho_derivative`; for a staple family the derivative sits inside the
      tilt sum, ∂S/∂θ = Σ_u ∂(P N)/∂θ Δu G;
    * d₁, d₂: ∂f/∂d_k = x̂^k Φ Σ_j k_s,j S_j (x̂ = ωi·ωr held to ``spec.theta_d_range``,
      a constant in d; 0 where the exponent clips);
    * the twist ψ_j of a staple family, from the ψ-derivatives of the cached geometry
      (:func:`_staple_geometry`): ∂S/∂ψ = Σ_u P Δu (∂N/∂cos φ · ∂cos φ/∂ψ · G + N ∂G/∂ψ).

    The axis offset δ rotates the frames of both families (every cached geometry moves):
    its column is a one-sided difference with step :data:`GEOMETRY_STEP`·max(1, |δ|), one
    batched :func:`evaluate_batch` of perturbed geometry per call (kept out of ``cache``).
    Non-finite values of f give zero rows.
    """
    theta = np.asarray(theta, float)
    idx = _spec_index(spec)
    C, P_ = spec.n_channels, theta.size
    N = wi.shape[0]
    t = lambda name: theta[idx[name]]  # noqa: E731
    norm_sum, h, Phi0, x = _cached(cache, "base", lambda: _base(wi, wr))
    Phi = Phi0
    if spec.free_theta_d:
        x = spec.held_x(x)
        q = t("d1") * x + t("d2") * x * x
        Phi = Phi0 * np.exp(np.clip(q, -50, 50))
    offset = t("axis_offset") if spec.free_axes else 0.0
    kd_cols, families = _spec_layout(spec)
    kd = np.exp(theta[kd_cols])
    f = np.empty((N, C))
    f[...] = kd
    J = np.zeros((N, C, P_))
    chans = np.arange(C)
    J[:, chans, kd_cols] = kd
    spec_sum = np.zeros((N, C))
    geometry_cols = []
    for fam, kind, alpha, (ks_cols, shape_cols, shape_idx, psi_col) in zip(
            ("warp", "weft"), spec.kinds, (0.0, np.pi / 2), families):
        lo, hi, log_s, c2, rho = theta[shape_idx]
        if kind == "filament":
            u, cphi, G0 = _cached(cache, ("fil", fam, float(offset)),
                                  lambda: _filament_geometry(*_frames(h, wi, wr, alpha + offset), norm_sum))
            P, dP = _profile_derivatives(u, lo, hi, log_s, c2)  # (N,), (4, N)
            Nl, dN_rho, _ = _lobe_with_derivatives(cphi, rho)
            S = P * Nl * G0
            dS = np.concatenate([dP * (Nl * G0), (P * dN_rho * G0)[None]])  # (5, N)
        else:
            entry = _staple_cached(cache, fam, alpha, float(offset), float(theta[psi_col]), h, wi, wr, norm_sum)
            # the products below at the valid nodes only, 0 at the others (as over the whole grid)
            G, cphi, (dG, dcphi) = entry.G_k, entry.cphi_k, entry.derivatives_k()
            P, dP = _profile_derivatives(_U_NODES, lo, hi, log_s, c2)  # (U,), (4, U)
            Nl, dN_rho, dN_cos = _lobe_with_derivatives(cphi, rho)
            NG = Nl * G
            grid = np.zeros((3, N * _U_NODES.size))
            grid[0, entry.k] = NG
            grid[1, entry.k] = dN_rho * G
            grid[2, entry.k] = dN_cos * dcphi * G + Nl * dG
            NG, RG, dpsi = (a.reshape(N, _U_NODES.size) for a in grid)  # (N, U) each
            S = NG @ P * _DU
            dS_psi = dpsi @ P
            dS = np.concatenate([(NG @ dP.T).T, (RG @ P)[None], dS_psi[None]]) * _DU
        ks = np.exp(theta[ks_cols])  # (C,)
        part = S[:, None] * ks  # (N, C)
        spec_sum += part
        J[:, chans, ks_cols] = Phi[:, None] * part
        J[:, :, shape_cols] = (Phi * dS).T[:, None, :] * ks[None, :, None]
    f += Phi[:, None] * spec_sum
    if spec.free_theta_d:
        inside = (q > -50) & (q < 50)
        g = np.where(inside, Phi, 0.0)[:, None] * spec_sum
        J[:, :, idx["d1"]] = x[:, None] * g
        J[:, :, idx["d2"]] = (x * x)[:, None] * g
    if spec.free_axes:
        geometry_cols.append(idx["axis_offset"])
    if geometry_cols:
        step = GEOMETRY_STEP * np.maximum(1.0, np.abs(theta[geometry_cols]))
        X = np.repeat(theta[None], len(geometry_cols), axis=0)
        X[np.arange(len(geometry_cols)), geometry_cols] += step
        # the perturbed geometry is never asked for again: keep it out of the caller's cache
        scratch = None if cache is None else ChainMap({}, cache)
        fp = evaluate_batch(spec, X, wi, wr, scratch)  # (G, N, C)
        J[:, :, geometry_cols] = np.moveaxis((fp - f[None]) / step[:, None, None], 0, -1)
    bad = ~np.isfinite(f)
    J[bad] = 0.0
    J[~np.isfinite(J)] = 0.0
    return f, J


@dataclass
class FibrePrior:
    """A fitted (or hand-set) prior: structure, parameter vector and fit report."""

    spec: PriorSpec
    theta: np.ndarray
    report: dict = field(default_factory=dict)
    #: Laplace covariance of ``theta`` (P, P) from the fit, or None (see :func:`fit_prior`).
    cov: np.ndarray | None = None

    def parameters(self) -> dict:
        return dict(zip(self.spec.names(), map(float, self.theta)))

    def __call__(self, wi, wr) -> np.ndarray:
        """f_prior(wi, wr) in 1/sr, (..., C); horizon, NaN and broadcasting as every model
        (:func:`kesbrdf.models.mappings.evaluate_pairs`); a non-finite value gives 0."""
        def core(a, b, _mapping):
            out = evaluate_batch(self.spec, self.theta[None], a, b)[0]
            return np.where(np.isfinite(out), out, 0.0)

        # chunks of 20000 pairs bound the memory of evaluate_batch on large grids
        return evaluate_pairs(core, wi, wr, self.spec.n_channels, "", chunk=20000)

    def to_dict(self) -> dict:
        return {"kinds": list(self.spec.kinds), "n_channels": self.spec.n_channels,
                "free_axes": self.spec.free_axes, "free_theta_d": self.spec.free_theta_d,
                **({} if self.spec.theta_d_range is None else {"theta_d_range": list(self.spec.theta_d_range)}),
                "theta": dict(zip(self.spec.names(), map(float, self.theta))),
                "cov": None if self.cov is None else np.asarray(self.cov).tolist()}

    def log_jacobian(self, wi, wr) -> np.ndarray:
        """d ln f / d theta at (wi, wr) (N, 3), shape (N, C, P), from :func:`evaluate_with_jacobian`.

        Zero where f is not finite or below 10⁻³⁰⁰ (ln f is floored there).
        """
        f, J = evaluate_with_jacobian(self.spec, self.theta, np.asarray(wi, float).reshape(-1, 3),
                                      np.asarray(wr, float).reshape(-1, 3))
        ok = np.isfinite(f) & (f > 1e-300)
        return J * np.where(ok, 1.0 / np.where(ok, f, 1.0), 0.0)[..., None]

    @classmethod
    def from_dict(cls, d: dict) -> "FibrePrior":
        spec = PriorSpec(tuple(d["kinds"]), int(d["n_channels"]), bool(d["free_axes"]), bool(d["free_theta_d"]),
                         d.get("theta_d_range"))
        names = spec.names()
        missing = [n for n in names if n not in d["theta"]]
        if missing:
            raise MeasurementError(f"fibre prior parameters missing {', '.join(missing)}")
        cov = d.get("cov")
        return cls(spec, np.array([d["theta"][n] for n in names], float),
                   cov=None if cov is None else np.asarray(cov, float))


# ---------------------------------------------------------------------------------- fit
@dataclass
class _Data:
    wi: np.ndarray
    wr: np.ndarray
    y: np.ndarray        # (N, C)
    eps: np.ndarray      # (C,)
    sigma: np.ndarray    # (N, C) of the log residual
    has_sigma: bool
    cache: dict = field(default_factory=dict)

    def __post_init__(self):
        #: ln(y + ε) of the log residual: fixed for the fit, formed once
        self.log_y = np.log(np.maximum(self.y, 0) + self.eps)


def _prepare(m, rows=None) -> _Data:
    wi, wr, y = m.wi, m.wr, m.values
    ok = (wi[:, 2] > 1e-6) & (wr[:, 2] > 1e-6) & np.all(np.isfinite(y), axis=1)
    if rows is not None:
        ok &= rows
    if np.count_nonzero(ok) < 8:
        raise MeasurementError(
            f"{m.source or 'measurement'}: the fibre prior needs at least 8 finite samples above the horizon, got {int(np.count_nonzero(ok))}"
        )
    y = y[ok]
    peak = np.max(np.abs(y), axis=0)
    eps = np.maximum(REL_FLOOR * peak, np.finfo(float).tiny)
    if m.uncertainty is not None:
        sig = np.maximum(m.uncertainty[ok] / (np.maximum(y, 0) + eps), MIN_SIGMA_LOG)
        has = True
    else:
        sig = np.ones_like(y)
        has = False
    return _Data(wi[ok], wr[ok], y, eps, sig, has)


def _residuals_batch(spec, thetas, d: _Data):
    f = evaluate_batch(spec, thetas, d.wi, d.wr, d.cache)
    f = np.where(np.isfinite(f), f, 0.0)
    r = (np.log(np.maximum(f, 0) + d.eps) - d.log_y) / d.sigma
    return r.reshape(r.shape[0], -1)


def _residual_jacobian(spec, x, d: _Data):
    """Residuals r (N·C,) and dr/dθ = (df/dθ)/((f + ε) σ) (N·C, P) of :func:`_residuals_batch`.

    Where f is not finite the residual treats it as 0 and its row of the Jacobian is 0.
    """
    f, J = evaluate_with_jacobian(spec, x, d.wi, d.wr, d.cache)
    ok = np.isfinite(f) & (f > 0)
    f = np.where(np.isfinite(f), f, 0.0)
    fe = np.maximum(f, 0) + d.eps
    r = (np.log(fe) - d.log_y) / d.sigma
    g = np.where(ok, 1.0 / (fe * d.sigma), 0.0)
    return r.reshape(-1), (J * g[..., None]).reshape(r.size, -1)


def _solve(spec, x0, d: _Data, bounds, max_nfev, penalty=None):
    """Bounded least squares of the log residuals; with ``penalty`` = (cols, μ, w) from
    :func:`_penalty_terms` the rows w·(θ[cols] − μ) of eq. (M1) (docs/prior.md §9) follow the data rows."""
    lo, hi = bounds
    x0 = np.clip(x0, lo + 1e-9, hi - 1e-9)

    if penalty is None:
        def fun(x):
            return _residuals_batch(spec, x[None], d)[0]

        def jac(x):
            return _residual_jacobian(spec, x, d)[1]
    else:
        cols, mu, w = penalty
        jp = np.zeros((cols.size, len(x0)))
        jp[np.arange(cols.size), cols] = w

        def fun(x):
            return np.concatenate([_residuals_batch(spec, x[None], d)[0], w * (x[cols] - mu)])

        def jac(x):
            return np.vstack([_residual_jacobian(spec, x, d)[1], jp])

    # lsmr: the dense SVD of the default solver took 0.5 s per iteration for 2700 residuals
    # with threaded BLAS on a loaded 2-core machine; lsmr gives the same optimum 10x faster.
    # SciPy's LinearOperator layers around the dense Jacobian cost ~45 % of a fit
    # (benchmarks/bench_default_fit.py); a copy of SciPy's solver without them was not
    # kept: the project writes its own code (docs/decisions.md, "The default fit's speed")
    return least_squares(fun, x0, jac=jac, bounds=(lo, hi), method="trf", x_scale="jac", max_nfev=max_nfev,
                         ftol=1e-8, xtol=1e-8, gtol=1e-8, tr_solver="lsmr")


def _bic(res, d: _Data, k: int) -> float:
    """BIC of the data rows only (a MAP fit's penalty rows, which follow them, are left out)."""
    n = d.y.size
    rss = float(np.sum(res.fun[:n] ** 2))
    if d.has_sigma:
        return rss + k * math.log(n)
    return n * math.log(max(rss / n, 1e-300)) + k * math.log(n)


def _start(spec: PriorSpec, d: _Data, u_half, rho, psi=(0.0, 0.0), offset=0.0, geometry=None):
    idx = spec.index()
    x = np.zeros(len(idx))
    ymin = np.maximum(np.percentile(np.maximum(d.y, 0), 5, axis=0), d.eps)
    yrng = np.maximum(np.max(d.y, axis=0) - ymin, d.eps)
    for c in range(spec.n_channels):
        x[idx[f"log_kd_{c}"]] = math.log(0.8 * ymin[c])  # clipped to eq. (B1) by the bounds
        for fam in ("warp", "weft"):
            x[idx[f"{fam}_log_ks_{c}"]] = math.log(yrng[c])
    for j, fam in enumerate(("warp", "weft")):
        x[idx[f"{fam}_u_lo"]] = -math.radians(u_half)
        x[idx[f"{fam}_u_hi"]] = math.radians(u_half)
        x[idx[f"{fam}_log_s"]] = math.log(math.radians(4.0))
        x[idx[f"{fam}_c2"]] = 0.0
        x[idx[f"{fam}_rho"]] = rho
        if f"{fam}_psi" in idx:
            x[idx[f"{fam}_psi"]] = math.radians(psi[j]) if psi[j] else math.radians(30.0)
    if spec.free_axes:
        x[idx["axis_offset"]] = offset
    if geometry is not None:  # carry over the shared parameters of a previous fit
        for name, value in geometry.items():
            if name in idx and not name.endswith("_psi"):
                x[idx[name]] = value
    return x


def _scale_ks_start(spec, x, d):
    """Rescale the k_s of a start so the model's peak matches the data's (a cheap first guess)."""
    f = evaluate_batch(spec, x[None], d.wi, d.wr, d.cache)[0]
    idx = spec.index()
    kd = np.exp(x[[idx[f"log_kd_{c}"] for c in range(spec.n_channels)]])
    spec_part = np.maximum(f - kd, 1e-300)
    target = np.maximum(np.max(d.y, axis=0) - kd, d.eps)
    scale = target / np.maximum(np.max(spec_part, axis=0), 1e-300)
    for c in range(spec.n_channels):
        for fam in ("warp", "weft"):
            x[idx[f"{fam}_log_ks_{c}"]] += math.log(max(scale[c], 1e-300))
    return x


def reading_sigma(d: _Data):
    """The readings' standard deviations (N, C) of ``d`` (from the measurement's
    uncertainty, as the log residual's σ carries it), or None without uncertainties."""
    return d.sigma * (np.maximum(d.y, 0) + d.eps) if d.has_sigma else None


def body_bounded(spec: PriorSpec, bounds, d: _Data):
    """``bounds`` with the upper bound of every ln k_d lowered to ln c_max of the data
    (eq. B2 of :mod:`kesbrdf.models.body`: the lobe is non-negative, so the body is at most
    the darkest reading, up to its noise)."""
    lo, hi = (np.array(b, float) for b in bounds)
    idx = spec.index()
    cols = [idx[f"log_kd_{c}"] for c in range(spec.n_channels)]
    hi[cols] = np.minimum(hi[cols], log_body_upper(d.y, reading_sigma(d)))
    lo[cols] = np.minimum(lo[cols], hi[cols] - 1e-6)
    return lo, hi


def _subsample(d: _Data, n_max: int, seed: int = 0) -> _Data:
    if d.y.shape[0] <= n_max:
        return d
    order = np.argsort(np.max(d.y / np.max(d.y, axis=0), axis=1))  # stratify by brightness
    pick = order[np.linspace(0, order.size - 1, n_max).round().astype(int)]
    return _Data(d.wi[pick], d.wr[pick], d.y[pick], d.eps, d.sigma[pick], d.has_sigma)


def _penalty_terms(parameter_prior, spec: PriorSpec, bounds, d: _Data):
    """(cols, μ, w) of the MAP rows of eq. (M1) for one variant, or None (docs/prior.md §9).

    w = √λ/s_k per parameter the prior knows; for data without uncertainties the log
    residuals are in units of ln f, not of σ, so w is multiplied by
    :data:`PENALTY_SIGMA_LOG` (the rows then weigh as against data of that σ)."""
    if parameter_prior is None:
        return None
    cols, mu, w = parameter_prior.terms(spec, bounds)
    if cols.size == 0:
        return None
    if not d.has_sigma:
        w = w * PENALTY_SIGMA_LOG
    return cols, mu, w


def _with_prior_theta_d(spec: PriorSpec, x, parameter_prior):
    """(spec, θ) with the θ_d law freed and d₁, d₂ at the prior's means (within their bounds)."""
    spec2 = replace(spec, free_theta_d=True)
    idx2 = spec2.index()
    x2 = np.zeros(len(idx2))
    for name, v in zip(spec.names(), x):
        x2[idx2[name]] = v
    lo, hi = spec2.bounds()
    for name in ("d1", "d2"):
        i = idx2[name]
        x2[i] = min(max(float(parameter_prior.mean[name]), lo[i]), hi[i])
    return spec2, x2


#: σ of ln f assumed for the MAP rows when the measurement carries no uncertainties
#: (2 %, the simulated protocols' noise; docs/prior.md §9).
PENALTY_SIGMA_LOG = 0.02


def fit_prior(m, kinds="auto", free_axes="auto", free_theta_d="auto", rows=None, max_nfev: int = 200,
              bound_body: bool = False, parameter_prior=None) -> FibrePrior:
    """Fit the prior to a :class:`~kesbrdf.measure.measurement.Measurement` (module docstring).

    Parameters
    ----------
    kinds : "auto" or (warp, weft) kinds
        "auto" tries the four filament/staple combinations and keeps the lowest BIC.
    free_axes : "auto" or bool
        Fit a common in-plane offset δ of the warp/weft axes; "auto" = when the
        measurement's ``frame`` metadata says it is a sample frame.
    free_theta_d : "auto" or bool
        Free θ_d-law coefficients; "auto" = when ωi·ωr spreads more than
        :data:`THETA_D_SPREAD` and at least :data:`MIN_THETA_D_SAMPLES` samples lie off
        the θ_d = 45° slice (never in the paper protocol, where ωi·ωr = 0).
    rows : bool array, optional
        Rows to use.
    bound_body : bool
        Hold k_d within eq. (B2) of :mod:`kesbrdf.models.body` (at most the darkest
        reading + 2σ); ``fibre-coord`` fits its bounded candidate with it.  The
        ``fibre-prior`` kind fits k_d free: its parametric lobe cannot carry an in-plane
        floor, and bounded it predicted the leave-one-family-out hemispheres worse
        (docs/decisions.md, "The body term").
    parameter_prior : None or :class:`kesbrdf.models.parameter_prior.ParameterPrior`
        A Gaussian prior over the parameters (MAP fit, eq. M1 of docs/prior.md §9):
        rows √λ (θ_k − μ_k)/s_k are appended to the residuals of the polish of each
        variant's best start (the multistart itself is the least-squares one: with the
        rows in it the solver found worse optima, docs/prior.md §9).  When ``free_theta_d="auto"`` leaves the θ_d law
        fixed (the data do not span θ_d) and the prior knows d₁, d₂, the law is freed
        with d₁, d₂ at the prior's means (on the paper slice ωi·ωr = 0, the data do
        not depend on them, so this is the MAP).  Variants are compared by the BIC of
        the data rows at their MAP points.  None (the
        default) is the plain least-squares fit, unchanged.

    Returns
    -------
    FibrePrior
        ``report`` holds every variant's BIC, cost, time and the choice.
    """
    t0 = time.perf_counter()
    d = _prepare(m, rows)
    if free_axes == "auto":
        free_axes = "sample frame" in str(m.metadata.get("frame", "")).lower()
    theta_d_from_prior = False
    x = np.sum(d.wi * d.wr, axis=-1)
    if free_theta_d == "auto":
        free_theta_d = (float(np.std(x)) > THETA_D_SPREAD
                        and int(np.count_nonzero(np.abs(x) > THETA_D_SPREAD)) >= MIN_THETA_D_SAMPLES)
        # the data cannot pin the θ_d law: the prior's mean law is plugged in after the fit
        # (exactly the MAP where ωi·ωr = 0 on every row, as in the paper protocol)
        theta_d_from_prior = not free_theta_d and parameter_prior is not None and parameter_prior.knows_theta_d()
    C = d.y.shape[1]
    variants = [("filament", "filament")] if kinds == "auto" else [tuple(kinds)]
    if kinds == "auto":
        variants += [("filament", "staple"), ("staple", "filament"), ("staple", "staple")]
    ds = _subsample(d, MULTISTART_MAX_ROWS)
    offsets = np.radians([0.0, 60.0, 120.0]) if free_axes else [0.0]
    n_start = START_NFEV
    report = {"variants": {}, "n": int(d.y.size), "criterion": "BIC = chi2 + k ln n" if d.has_sigma else "BIC = n ln(RSS/n) + k ln n"}
    best_geometry = None
    results = []
    for kv in variants:
        spec = PriorSpec(kv, C, bool(free_axes), bool(free_theta_d),
                         (float(x.min()), float(x.max())) if free_theta_d else None)
        if kv == ("filament", "filament"):
            starts = [(uh, rho, (0, 0), off) for uh in (6.0, 20.0, 45.0) for rho in (0.0, 0.6) for off in offsets]
            if free_axes:
                starts = [(uh, 0.3, (0, 0), off) for uh in (6.0, 30.0) for off in offsets]
        else:
            twists = (20.0, -20.0, 40.0, -40.0)
            starts = [(None, None, tuple(t if k == "staple" else 0 for k in kv), None) for t in twists]
        best = None
        t_var = time.perf_counter()
        for uh, rho, psi, off in starts:
            if uh is None:
                x0 = _start(spec, ds, 20.0, 0.0, psi, 0.0, best_geometry)
            else:
                x0 = _start(spec, ds, uh, rho, psi, off)
            x0 = _scale_ks_start(spec, x0, ds)
            bounds = spec.bounds(tuple(np.sign(p) if p else 1 for p in psi))
            if bound_body:
                bounds = body_bounded(spec, bounds, d)
            res = _solve(spec, x0, ds, bounds, n_start)  # the multistart is plain least squares (docs/prior.md §9)
            if best is None or res.cost < best[0].cost:
                best = (res, bounds)
        res, bounds = best
        penalty = _penalty_terms(parameter_prior, spec, bounds, d)
        res = _solve(spec, res.x, d, bounds, max_nfev)
        if penalty is not None:  # the MAP from the least-squares optimum (its basin: docs/prior.md §9)
            res = _solve(spec, res.x, d, bounds, max_nfev, penalty)
        k = len(spec.names())
        bic = _bic(res, d, k)
        report["variants"]["/".join(kv)] = {
            "bic": bic, "cost": float(res.cost), "k": k, "seconds": time.perf_counter() - t_var,
            "rms_log": float(np.sqrt(np.mean((res.fun[:d.y.size] * d.sigma.ravel()) ** 2))),
        }
        if penalty is not None:
            report["variants"]["/".join(kv)]["penalty"] = float(0.5 * np.sum(res.fun[d.y.size:] ** 2))
        results.append((bic, spec, res.x))
        if kv == ("filament", "filament"):
            best_geometry = dict(zip(spec.names(), res.x))
    bic, spec, x = min(results, key=lambda r: r[0])
    if theta_d_from_prior:
        spec, x = _with_prior_theta_d(spec, x, parameter_prior)
    cov = _laplace_covariance(spec, np.asarray(x, float), d)
    report["chosen"] = "/".join(spec.kinds)
    report["seconds"] = time.perf_counter() - t0
    report["free_axes"] = bool(free_axes)
    report["free_theta_d"] = bool(spec.free_theta_d)
    report["body_bounded"] = bool(bound_body)
    if parameter_prior is not None:
        report["parameter_prior"] = {"weight": float(parameter_prior.weight), "source": parameter_prior.source,
                                     "theta_d_from_prior": theta_d_from_prior}
    return FibrePrior(spec, np.asarray(x, float), report, cov)


def _laplace_covariance(spec, x, d: _Data) -> np.ndarray:
    """Laplace covariance s²·(JᵀJ)⁺ of the weighted log residuals at the optimum.

    s² = 1 when the measurement carried uncertainties (the residuals are already in
    units of σ), else RSS/(n − k).  Directions the data does not constrain get the
    pseudo-inverse's zero: their uncertainty is carried by the model term of
    :func:`kesbrdf.models.fibre_prior.predict_with_uncertainty`, not here.
    """
    r0, J = _residual_jacobian(spec, x, d)
    n, k = J.shape
    s2 = 1.0 if d.has_sigma else float(np.sum(r0**2)) / max(n - k, 1)
    return s2 * np.linalg.pinv(J.T @ J, rcond=1e-10)
