r"""Fit the extended-KES model to scattered gonio data (docs/method.md, "The body term").

The paper builds its table from in-plane curves at ψ = 0, π/4, π/2, 3π/4.  Real data
sets (CUReT, a lab's own gonio archive) hold scattered configurations instead, in a
sample frame whose azimuth zero is not the warp.  :func:`fit_scattered` estimates the
same model from them: the result is a :class:`kesbrdf.models.kes.Model` of kind ``"kes"``,
the same table format, so every consumer (``kesbrdf.models.brdf.evaluate``, the renderer,
the viewer) uses it unchanged.

Parameterisation
----------------
The unknowns are *virtual in-plane measurements*: the lobe
:math:`\ell_{n,s} = \exp\theta_{n,s} > 0` at a coarse set of deviations γ_n
(:data:`GAMMA_NODES_DEG`) and the eight half-azimuths s·π/4 (:data:`kesbrdf.models.interpolation.HALF_AZIMUTHS`),
plus a Lambertian body c ≥ 0.  The table is then built exactly as
:func:`kesbrdf.models.kes.fit` builds it from in-plane data on the paper's line
θ_i + θ_r = π/2:

1. total half-samples q_{n,s} = ℓ_{n,s} + c·w(γ_n), w(γ) the line's foreshortening
   weight (:func:`kesbrdf.models.mappings.line_foreshortening`: √(cos γ / 2), bounded toward
   grazing angles; zero beyond γ = π/2);
2. linear interpolation in q onto the table's uniform γ grid;
3. KES on K = 1/q over the whole circle of deviation azimuths
   (:func:`kesbrdf.models.interpolation.interpolate_circle`, through :func:`kesbrdf.models.kes.fill_table` with
   ``fallback="log"`` where K(φ) ≤ 0);
4. body split: lobe = max(q(φ, γ) − c·w(γ), 0).

So f_r = c + lobe(φ, γ)/w(θ_i, θ_r) (``deviation`` mapping, w of
:func:`kesbrdf.models.mappings.foreshortening`) is positive and
finite everywhere, and reciprocal by construction.

Symmetric variants (``symmetry``): ``"none"`` (8 free half-azimuths: pile/nap allowed),
``"central"`` (q(φ + π) = q(φ): the 4-orientation KES form without odd part) and
``"isotropic"`` (q depends on γ only: the isotropic-curve baseline).  ``"auto"`` (the
default) takes ``"none"`` when the data's deviation azimuths cover the whole circle
(no gap of :data:`MAX_AZIMUTH_GAP_DEG` or more between samples away from the mirror)
and ``"central"`` otherwise: CUReT's 205 configurations cover only half of the circle
(azimuths 180°…360° in its sample frame), so the odd part, a pile or nap direction,
cannot be estimated from it and would be set by the smoothness penalty alone.

Estimation
----------
Robust least squares (``scipy.optimize.least_squares``, analytic Jacobian) of

.. math:: r_j = \ln\frac{\hat f_j + \varepsilon}{\max(f_j, 0) + \varepsilon}

with ε = :data:`LOG_EPS_REL` × max f (the same ε as
:func:`kesbrdf.validate.compare.metrics`), a soft-L1 loss of scale ``loss_scale``, and two
quadratic smoothness penalties on θ: the change of slope (per radian of γ) between
neighbouring γ intervals (weight ``smooth_gamma``) and first differences between
neighbouring half-azimuths (weight ``smooth_phi``; it pulls sparse data toward
isotropy).  One set of hyper-parameters serves every data set; the defaults were
chosen on simulated anisotropic Ward lobes at the CUReT configurations (5 % noise,
5 folds), never on the real data.  The residual function reproduces :func:`kesbrdf.models.brdf.evaluate` of the final model (same
table columns, same bilinear lookup) to round-off.

Warp azimuth
------------
CUReT's azimuths are in the sample frame.  Writing δ for the sample-frame azimuth of
the warp, the fabric frame is the sample frame turned by −δ.  The whole-circle KES
family is closed under turns by π/4 (its span {1, cos 2φ, sin 2φ, cos 4φ, cos φ,
sin φ, cos 3φ, sin 3φ} is, and the interpolation through the eight half-samples is
unique), so data and smoothness penalties identify δ only modulo 45°.  It is searched
on a grid over [0°, 45°) and refined (bounded Brent); then the labelling among
δ + k·45° is fixed by a documented convention: the warp is the axis along which the
fitted lobe is *narrowest* (perpendicular to the axis given by the phase of the
second circular harmonic of the log lobe over the half-azimuths, summed over the γ
nodes weighted by the samples near each node and by the lobe's share of the signal
there), i.e. the axis of the yarn floats
of a warp-faced fabric (for an anisotropic Ward lobe, the axis of the smaller α).
The data cannot tell warp from weft by name, only by lobe shape; the result is
recorded as ``parameters["warp_offset_deg"]`` in [0, 180).

Measured on real data
---------------------
``benchmarks/bench_real_data.py`` fits the eleven CUReT fabrics with 5 seeded folds:
lobe + body beats the isotropic curve (+ body) and the anisotropic Ward on every
fabric in held-out log-RMSE and RMSE, while the pure lobe (``body="none"``) rarely
beats the isotropic curve: the observation of docs/method.md, "The body term", reproduced.  The ``deviation``
mapping fits every fabric better than ``halfvector`` (the reverse holds for Ward
lobes, which are half-vector functions by construction).

Baseline
--------
:func:`fit_ward` fits an anisotropic Ward lobe (α_x, α_y, ρ_d, ρ_s, warp azimuth) by the
same robust log least squares, for comparison on equal terms.
"""

from __future__ import annotations

import math

import numpy as np

from kesbrdf.models import interpolation as kes
from kesbrdf.errors import KesbrdfError, MeasurementError
from kesbrdf.models.base import register_fitter, check_fit_options
from kesbrdf.models.mappings import foreshortening, to_phi_gamma
from kesbrdf.measure.measurement import Measurement
from kesbrdf.models.kes import Model, fallback_warning, fill_table, line_weight

__all__ = [
    "fit_scattered",
    "ScatteredFit",
    "fit_ward",
    "to_fabric_frame",
    "evaluate_sample_frame",
    "RotatedBRDF",
    "SYMMETRIES",
    "GAMMA_NODES_DEG",
    "LOG_EPS_REL",
]

SYMMETRIES = ("auto", "none", "central", "isotropic")
#: ``symmetry="auto"`` needs no gap this wide (degrees) in the deviation azimuths of
#: samples with γ above :data:`COVERAGE_MIN_GAMMA_DEG` to estimate the odd part.
MAX_AZIMUTH_GAP_DEG = 90.0
#: Samples closer than this to the mirror direction carry no azimuth information.
COVERAGE_MIN_GAMMA_DEG = 5.0

#: Deviation nodes (degrees) of the lobe parameters: dense near the mirror where lobes
#: change fastest, 15° apart beyond.  Integers, so they fall on the 1° table grid.
GAMMA_NODES_DEG = (0, 8, 15, 25, 35, 45, 60, 75, 90, 105, 120, 135, 150, 165, 180)
#: γ step of the table (radians); every node is on the grid.
GAMMA_STEP = math.radians(1.0)
#: φ cells of the table (as kesbrdf.models.kes; the half-azimuths k·45° are on the grid).
N_PHI = 360
#: Log-error floor relative to the channel's peak, as kesbrdf.validate.compare.LOG_EPS_REL.
LOG_EPS_REL = 1e-3
#: The paper's incidence line θ_i + θ_r = π/2: the virtual in-plane samples live on it.
LINE_SUM = math.pi / 2
#: Foreshortening weight of the table (:func:`kesbrdf.models.mappings.foreshortening`), as
#: :func:`kesbrdf.models.kes.fit`'s default.
NORMALISATION = "bounded"

#: Default hyper-parameters, one set for every fabric, chosen on simulated Ward lobes
#: at the CUReT geometries (5 % noise, 5 folds, grid 0…0.1 × 0…0.3; best for the
#: deviation mapping, within 0.003 log-RMSE of best for halfvector), not on real data.
DEFAULT_SMOOTH_GAMMA = 0.03
DEFAULT_SMOOTH_PHI = 0.03
DEFAULT_LOSS_SCALE = 0.1
#: Bounds of the fitted Ward α (slope spreads); beyond ~1 the lobe is a flat band.
WARD_ALPHA_BOUNDS = (0.01, 5.0)
#: |log| bound of the parameters (keeps exp finite while the solver explores).
THETA_CLIP = 40.0
#: Grid step of the warp search over [0°, 45°), degrees.
DEFAULT_OFFSET_STEP_DEG = 7.5
#: Tolerance of the warp refinement, degrees.
OFFSET_XTOL_DEG = 0.25


# ---------------------------------------------------------------------------------
def _scipy_optimize():
    """scipy.optimize, or an ImportError naming the extra that provides it."""
    try:
        import scipy.optimize
    except ImportError as exc:  # pragma: no cover - scipy is in the cli and test extras
        raise ImportError("kesbrdf.models.scattered needs scipy: install kesbrdf[cli] (or pip install scipy)") from exc
    return scipy.optimize


def to_fabric_frame(w, warp) -> np.ndarray:
    """Turn sample-frame vectors (..., 3) by −``warp`` about z (warp azimuth → +x).

    >>> to_fabric_frame([0.0, 1.0, 0.0], np.pi / 2).round(12).tolist()
    [1.0, 0.0, 0.0]
    """
    w = np.asarray(w, float)
    c, s = math.cos(warp), math.sin(warp)
    x = c * w[..., 0] + s * w[..., 1]
    y = -s * w[..., 0] + c * w[..., 1]
    return np.stack([x, y, w[..., 2]], axis=-1)


def evaluate_sample_frame(model: Model, wi, wr, mapping: str | None = None) -> np.ndarray:
    """f_r of a model at sample-frame directions, using ``parameters["warp_offset_deg"]``.

    ``mapping`` defaults to the one the model was fitted with (``parameters["mapping"]``,
    else ``"deviation"``).
    """
    if mapping is None:
        mapping = model.parameters.get("mapping", "deviation")
    warp = model.sample_frame_warp
    return model.evaluate(to_fabric_frame(wi, warp), to_fabric_frame(wr, warp), mapping)


class RotatedBRDF:
    """A fabric-frame BRDF callable seen in a sample frame whose warp is at azimuth ``warp``."""

    def __init__(self, brdf, warp: float):
        self.brdf = brdf
        self.warp = float(warp)
        self.channels = tuple(getattr(brdf, "channels", ("value",)))

    def __call__(self, wi, wr) -> np.ndarray:
        return self.brdf(to_fabric_frame(wi, self.warp), to_fabric_frame(wr, self.warp))


def _robust(r, scale):
    """Soft-L1 as a transformed residual: ½r̃² = scale²(√(1 + (r/scale)²) − 1); and dr̃/dr."""
    s = np.sqrt(1.0 + (r / scale) ** 2)
    g = np.sqrt(2.0 / (s + 1.0))
    return r * g, g * (s + 1.0) / (2.0 * s)


def _tying(symmetry: str) -> np.ndarray:
    """S (k, 8): full half-azimuth parameters = free parameters @ S."""
    if symmetry == "none":
        return np.eye(8)
    if symmetry == "central":
        return np.hstack([np.eye(4), np.eye(4)])
    if symmetry == "isotropic":
        return np.ones((1, 8))
    raise KesbrdfError(f"unknown symmetry {symmetry!r}; expected one of {', '.join(SYMMETRIES)}")


def _hat_matrix(x, nodes) -> np.ndarray:
    """Linear interpolation weights (len(x), len(nodes)) of ``nodes`` at ``x`` (clamped)."""
    x = np.clip(np.asarray(x, float), nodes[0], nodes[-1])
    k = np.clip(np.searchsorted(nodes, x, side="right") - 1, 0, nodes.size - 2)
    t = (x - nodes[k]) / (nodes[k + 1] - nodes[k])
    H = np.zeros((x.size, nodes.size))
    rows = np.arange(x.size)
    H[rows, k] = 1.0 - t
    H[rows, k + 1] += t
    return H


class _Problem:
    """Fast forward model and Jacobian for one channel, reproducing brdf.evaluate."""

    def __init__(self, phi_s, gamma, norm, f, gamma_nodes, gamma_grid, symmetry, body_fixed,
                 smooth_gamma, smooth_phi, loss_scale):
        self.gamma_nodes = gamma_nodes
        self.gamma_grid = gamma_grid
        self.phi_grid = np.arange(N_PHI) * (2 * np.pi / N_PHI)
        self.phi_s = phi_s
        self.norm = norm
        self.S = _tying(symmetry)
        self.symmetry = symmetry
        self.body_fixed = body_fixed  # None: fitted (log c is the last parameter)
        self.eps = LOG_EPS_REL * max(float(np.max(np.abs(f))), np.finfo(float).tiny)
        self.log_t = np.log(np.maximum(f, 0.0) + self.eps)
        self.loss_scale = loss_scale
        # γ side of the bilinear lookup (kesbrdf.models.brdf.lookup), fixed for the data
        n_gamma = gamma_grid.size
        v = np.clip(gamma, 0.0, gamma_grid[-1]) / (gamma_grid[1] - gamma_grid[0])
        j0 = np.minimum(np.floor(v).astype(np.intp), n_gamma - 1)
        self.fv = v - j0
        j1 = np.minimum(j0 + 1, n_gamma - 1)
        self.J = np.unique(np.concatenate([j0, j1]))
        self.a0 = np.searchsorted(self.J, j0)
        self.a1 = np.searchsorted(self.J, j1)
        self.P = _hat_matrix(gamma_grid[self.J], gamma_nodes)  # (|J|, n_nodes)
        self.w_nodes = line_weight(gamma_nodes, LINE_SUM, NORMALISATION)
        self.w_J = line_weight(gamma_grid[self.J], LINE_SUM, NORMALISATION)
        self.Pw = self.P @ self.w_nodes
        # K(φ) = Σ_s K_half[s]·B[s, φ] (the KES interpolation is linear in K)
        self.B = kes.interpolate_circle(np.eye(8), self.phi_grid)  # (8, n_phi)
        self.reg = self._regulariser(smooth_gamma, smooth_phi)
        self.set_offset(0.0)

    # -- geometry ---------------------------------------------------------------
    def set_offset(self, delta: float) -> None:
        u = np.mod(self.phi_s - delta, 2 * np.pi) * (N_PHI / (2 * np.pi))
        i0 = np.floor(u).astype(np.intp)
        self.fu = u - i0
        self.i0 = i0 % N_PHI
        self.i1 = (self.i0 + 1) % N_PHI

    def _regulariser(self, smooth_gamma, smooth_phi) -> np.ndarray:
        """Rows (R, n_nodes·8) of the linear smoothness residuals on θ_full."""
        g = self.gamma_nodes
        n = g.size
        rows = []
        if n >= 3 and smooth_gamma > 0:
            h = np.diff(g)
            D = np.zeros((n - 2, n))
            for k in range(n - 2):  # slope change, per radian², times the mean spacing
                D[k, k] = 1.0 / h[k]
                D[k, k + 1] = -1.0 / h[k] - 1.0 / h[k + 1]
                D[k, k + 2] = 1.0 / h[k + 1]
            rows.append(smooth_gamma * np.kron(D, np.eye(8)))
        if smooth_phi > 0 and self.symmetry != "isotropic":
            C = np.roll(np.eye(8), 1, axis=1) - np.eye(8)
            rows.append(smooth_phi * np.kron(np.eye(n), C))
        if not rows:
            return np.zeros((0, n * 8))
        return np.vstack(rows)

    # -- parameters -------------------------------------------------------------
    @property
    def n_free(self) -> int:
        return self.S.shape[0]

    def unpack(self, x):
        n = self.gamma_nodes.size
        theta = np.clip(x[: n * self.n_free].reshape(n, self.n_free), -THETA_CLIP, THETA_CLIP) @ self.S
        c = math.exp(min(max(x[-1], -THETA_CLIP), THETA_CLIP)) if self.body_fixed is None else self.body_fixed
        return theta, c

    def table_columns(self, theta, c, columns):
        """Lobe table at γ-grid rows ``columns`` (as kesbrdf.models.kes.fit), (|cols|, n_phi), and extras."""
        P = _hat_matrix(self.gamma_grid[columns], self.gamma_nodes)
        q_half = P @ (np.exp(theta) + c * self.w_nodes[:, None])  # (cols, 8)
        T, fallback = fill_table(q_half[:, :, None], self.phi_grid, self.gamma_grid[columns], 4, "kes", "log")
        T = T[:, :, 0].T  # (cols, n_phi), total q
        lobe = T - c * line_weight(self.gamma_grid[columns], LINE_SUM, NORMALISATION)[:, None]
        return np.maximum(lobe, 0.0), T, q_half, fallback

    def predict(self, theta, c):
        lobe, T, q_half, fallback = self.table_columns(theta, c, self.J)
        fu, fv = self.fu, self.fv
        q = (lobe[self.a0, self.i0] * (1 - fu) + lobe[self.a0, self.i1] * fu) * (1 - fv) + (
            lobe[self.a1, self.i0] * (1 - fu) + lobe[self.a1, self.i1] * fu
        ) * fv
        return c + q / self.norm, (lobe, T, q_half, fallback)

    def residuals(self, x):
        theta, c = self.unpack(x)
        f, _ = self.predict(theta, c)
        r = np.log(f + self.eps) - self.log_t
        rr, _ = _robust(r, self.loss_scale)
        return np.concatenate([rr, self.reg @ theta.ravel()])

    def jacobian(self, x):
        theta, c = self.unpack(x)
        f, (lobe, T, q_half, fallback) = self.predict(theta, c)
        n_nodes = self.gamma_nodes.size
        log_col = np.zeros(self.J.size, bool)
        log_col[np.asarray(fallback, dtype=np.intp)] = True
        G = np.zeros((f.size, 8))  # d f / d q_half[a, s], summed over corners (per corner a)
        Jt = np.zeros((f.size, n_nodes, 8))
        dfdc = np.ones(f.size)
        for a, b, wgt in (
            (self.a0, self.i0, (1 - self.fu) * (1 - self.fv)),
            (self.a0, self.i1, self.fu * (1 - self.fv)),
            (self.a1, self.i0, (1 - self.fu) * self.fv),
            (self.a1, self.i1, self.fu * self.fv),
        ):
            active = (lobe[a, b] > 0) * wgt / self.norm
            Tab = T[a, b][:, None]
            qh = q_half[a]
            Bb = self.B[:, b].T  # (N, 8)
            dT = np.where(log_col[a][:, None], Tab * Bb / qh, Tab**2 * Bb / qh**2)
            G = active[:, None] * dT
            Jt += G[:, None, :] * self.P[a][:, :, None]
            dfdc += active * (dT.sum(axis=1) * self.Pw[a] - self.w_J[a])
        Jt *= np.exp(theta)[None, :, :]
        r = np.log(f + self.eps) - self.log_t
        _, dr = _robust(r, self.loss_scale)
        scale = dr / (f + self.eps)
        Jfree = (Jt @ self.S.T).reshape(f.size, -1) * scale[:, None]
        Jreg = self.reg @ np.kron(np.eye(n_nodes), self.S.T)
        if self.body_fixed is None:
            Jfree = np.hstack([Jfree, (dfdc * c * scale)[:, None]])
            Jreg = np.hstack([Jreg, np.zeros((Jreg.shape[0], 1))])
        return np.vstack([Jfree, Jreg])

    def solve(self, x0, max_nfev):
        least_squares = _scipy_optimize().least_squares
        # Levenberg-Marquardt (MINPACK): ten times faster than "trf" here, same optimum;
        # it needs at least as many residuals as parameters (no penalties, few samples)
        method = "lm" if self.log_t.size + self.reg.shape[0] >= x0.size else "trf"
        res = least_squares(self.residuals, x0, jac=self.jacobian, method=method, max_nfev=max_nfev,
                            x_scale=1.0, ftol=1e-8, xtol=1e-8, gtol=1e-10)
        return res


def _initial(problem: _Problem, f, body_fixed):
    """Start: isotropic lobe from the data's median, body at a third of the low quantile."""
    med = float(np.median(np.maximum(f, 0.0))) + problem.eps
    n = problem.gamma_nodes.size
    theta0 = np.full((n, problem.n_free), math.log(0.3 * med))
    x0 = theta0.ravel()
    if body_fixed is None:
        c0 = max(float(np.quantile(np.maximum(f, 0.0), 0.1)) * 0.5, problem.eps)
        x0 = np.append(x0, math.log(c0))
    return x0


def _broadcast_free(x_iso, problem: _Problem, body_fixed):
    """Parameters of an isotropic solution expanded to ``problem``'s symmetry."""
    n = problem.gamma_nodes.size
    theta = np.repeat(x_iso[:n][:, None], problem.n_free, axis=1).ravel()
    return theta if body_fixed is not None else np.append(theta, x_iso[-1])


def _azimuth_gap(phi, gamma) -> float:
    """Widest gap (radians) between the deviation azimuths of samples away from the mirror."""
    az = np.sort(np.mod(phi[gamma > math.radians(COVERAGE_MIN_GAMMA_DEG)], 2 * np.pi))
    if az.size < 2:
        return 2 * np.pi
    return float(np.max(np.diff(np.append(az, az[0] + 2 * np.pi))))


def _warp_label(theta_full, weight) -> int:
    """k ∈ 0..3 half-azimuth shift putting the narrowest-lobe axis at slot 0 (module docstring).

    ``weight`` (n_nodes,) says how much each γ node is determined by the data (samples
    near it, times the lobe's share of the signal there).
    """
    az = kes.HALF_AZIMUTHS
    centred = theta_full - theta_full.mean(axis=1, keepdims=True)
    a2 = np.sum(weight[:, None] * centred * np.exp(2j * az)[None, :])  # phase = 2 × wide axis
    if abs(a2) < 1e-12:
        return 0
    narrow = np.angle(a2) / 2 + np.pi / 2  # log lobe is largest along the wide axis
    return int(np.round(np.mod(narrow, np.pi) / (np.pi / 4))) % 4


def fit_scattered(
    m: Measurement,
    warp_deg: float | None = None,
    symmetry: str = "auto",
    body="fit",
    smooth_gamma: float = DEFAULT_SMOOTH_GAMMA,
    smooth_phi: float = DEFAULT_SMOOTH_PHI,
    loss_scale: float = DEFAULT_LOSS_SCALE,
    gamma_nodes_deg=GAMMA_NODES_DEG,
    offset_step_deg: float = DEFAULT_OFFSET_STEP_DEG,
    max_nfev: int = 200,
    mapping: str = "deviation",
) -> Model:
    """Fit the extended-KES model (lobe + body) to scattered samples (module docstring).

    Parameters
    ----------
    m : Measurement
        General (out-of-plane) samples; angles in the sample frame.  Rows with a
        non-finite value or a direction at or below the horizon are ignored.
    warp_deg : float or None
        Sample-frame azimuth of the warp, degrees.  None: estimated (grid over
        [0°, 45°) plus refinement, then the narrow-axis convention; module docstring).
    symmetry : {"auto", "none", "central", "isotropic"}
        Tying of the eight half-azimuths (module docstring); ``"isotropic"`` is the
        isotropic-curve baseline.  The choice made is ``parameters["symmetry"]``.
    body : "fit", "none" or float
        Lambertian body c in 1/sr: estimated (c > 0; ``"auto"`` is accepted as a synonym,
        as in :func:`kesbrdf.models.kes.fit`), zero (the paper's pure lobe) or given.
    smooth_gamma, smooth_phi : float
        Weights of the smoothness penalties over γ and over the half-azimuths.
    loss_scale : float
        Soft-L1 scale of the log residuals (natural-log units).
    gamma_nodes_deg : sequence of float
        Candidate γ nodes, degrees, increasing from 0; the nodes used stop at the first
        one at or beyond the largest γ in the data.
    offset_step_deg : float
        Grid step of the warp search.
    max_nfev : int
        Iteration cap of each least-squares solve.
    mapping : {"deviation", "halfvector"}
        The (wi, wr) → (φ, γ) mapping the table is fitted for and must be evaluated
        with (recorded in ``parameters["mapping"]``).  The renderer and the viewer use
        ``"deviation"``, the default.

    Returns
    -------
    Model
        Kind ``"kes"``; ``parameters["warp_offset_deg"]`` is the sample-frame azimuth of
        the warp (turn sample-frame directions by its negative before
        :func:`kesbrdf.models.brdf.evaluate`, or use :func:`evaluate_sample_frame`).

    Raises
    ------
    MeasurementError
        Too few usable samples for the parameters.
    KesbrdfError
        Unknown ``symmetry`` or ``body``.
    """
    if symmetry != "auto":
        _tying(symmetry)
    if mapping not in ("deviation", "halfvector"):
        raise KesbrdfError(f"expected mapping 'deviation' or 'halfvector', got {mapping!r}")
    if isinstance(body, str):
        if body not in ("fit", "auto", "none"):
            raise KesbrdfError(f"expected body 'fit' (or 'auto'), 'none' or a number, got {body!r}")
        body = "fit" if body == "auto" else body
    wi, wr = m.wi, m.wr
    usable = (wi[:, 2] > 0) & (wr[:, 2] > 0) & np.all(np.isfinite(m.values), axis=1)
    n_used = int(usable.sum())
    phi_s, gamma = to_phi_gamma(wi[usable], wr[usable], mapping)
    norm = foreshortening(wi[usable, 2], wr[usable, 2], NORMALISATION)
    values = m.values[usable]
    gap = _azimuth_gap(phi_s, gamma)
    symmetry_asked = symmetry
    if symmetry == "auto":
        symmetry = "none" if gap < math.radians(MAX_AZIMUTH_GAP_DEG) else "central"

    nodes_deg = np.asarray(gamma_nodes_deg, float)
    if nodes_deg.size < 2 or nodes_deg[0] != 0 or np.any(np.diff(nodes_deg) <= 0):
        raise KesbrdfError(f"expected increasing gamma nodes from 0, got {list(nodes_deg)}")
    gmax_deg = float(np.degrees(gamma.max())) if n_used else 0.0
    last = int(np.searchsorted(nodes_deg, gmax_deg - 1e-9))
    nodes_deg = nodes_deg[: min(max(last, 1), nodes_deg.size - 1) + 1]
    gamma_nodes = np.radians(nodes_deg)
    gamma_grid = np.arange(int(round(nodes_deg[-1] / math.degrees(GAMMA_STEP))) + 1) * GAMMA_STEP
    n_params = nodes_deg.size * _tying(symmetry).shape[0] + (body == "fit")
    if n_used < max(8, nodes_deg.size + 1):
        raise MeasurementError(
            f"{m.source or 'measurement'}: expected at least {max(8, nodes_deg.size + 1)} usable samples "
            f"(finite, above the horizon) to fit {n_params} regularised parameters, got {n_used}"
        )

    if isinstance(body, str):
        body_fixed = None if body == "fit" else 0.0
    else:
        body_fixed = float(body)
        if not (body_fixed >= 0 and math.isfinite(body_fixed)):
            raise KesbrdfError(f"expected a non-negative body term, got {body!r}")

    def problem(f, sym):
        return _Problem(phi_s, gamma, norm, f, gamma_nodes, gamma_grid, sym, body_fixed,
                        smooth_gamma, smooth_phi, loss_scale)

    # 1. warp search on the channel mean (an isotropic start, offset-independent)
    f_mean = values.mean(axis=1)
    iso = problem(f_mean, "isotropic")
    x_iso = iso.solve(_initial(iso, f_mean, body_fixed), max_nfev).x
    search = {}
    x_search = None
    if symmetry == "isotropic":
        delta = 0.0 if warp_deg is None else math.radians(warp_deg)
        search["identifiable"] = False
    elif warp_deg is not None:
        delta = math.radians(float(warp_deg))
        search["fixed"] = True
    else:
        minimize_scalar = _scipy_optimize().minimize_scalar
        p = problem(f_mean, symmetry)
        x_start = _broadcast_free(x_iso, p, body_fixed)
        cache = {}

        def cost(d_deg):
            p.set_offset(math.radians(d_deg))
            res = p.solve(x_start if not cache else cache[min(cache, key=lambda k: cache[k][0])][1], max_nfev)
            cache[d_deg] = (float(res.cost), res.x)
            return float(res.cost)

        grid = np.arange(0.0, 45.0 - 1e-9, offset_step_deg)
        costs = [cost(d) for d in grid]
        best = float(grid[int(np.argmin(costs))])
        minimize_scalar(cost, bounds=(best - offset_step_deg, best + offset_step_deg), method="bounded",
                        options={"xatol": OFFSET_XTOL_DEG, "maxiter": 12})
        d_best = min(cache, key=lambda k: cache[k][0])
        delta = math.radians(d_best)
        x_search = cache[d_best][1]
        search.update({
            "grid_deg": [float(g) for g in grid],
            "grid_cost": costs,
            "refined_deg": float(d_best),
            "evaluations": len(cache),
            "identifiable_mod_deg": 45.0,
        })

    # 2. per-channel fits at that warp
    C = m.n_channels
    thetas, bodies, costs, nfev, train_log_rmse = [], [], [], [], []
    for ch in range(C):
        p = problem(values[:, ch], symmetry)
        p.set_offset(delta)
        if C == 1 and x_search is not None:
            x0 = x_search  # the search already fitted this channel at this warp
        else:
            x0 = _broadcast_free(x_iso if C == 1 else _fit_isotropic(problem, values[:, ch], body_fixed, max_nfev),
                                 p, body_fixed)
        res = p.solve(x0, max_nfev)
        theta, c = p.unpack(res.x)
        f_hat, _ = p.predict(theta, c)
        thetas.append(theta)
        bodies.append(c)
        costs.append(float(res.cost))
        nfev.append(int(res.nfev))
        train_log_rmse.append(float(np.sqrt(np.mean((np.log(f_hat + p.eps) - p.log_t) ** 2))))

    # 3. warp labelling among δ + k·45° (module docstring), then the tables
    theta_all = np.stack(thetas, axis=-1)  # (n, 8, C)
    shift = 0
    if symmetry != "isotropic" and warp_deg is None:
        support = p.P.T @ np.bincount(np.concatenate([p.a0, p.a1]), minlength=p.J.size).astype(float)
        lobe_mean = np.exp(theta_all).mean(axis=(1, 2))
        share = lobe_mean / (lobe_mean + np.mean(bodies) * np.maximum(p.w_nodes, 0.1))
        shift = _warp_label(theta_all.mean(axis=2), support * share)
        delta = delta + shift * math.pi / 4
        theta_all = np.roll(theta_all, -shift, axis=1)
    if symmetry != "isotropic":
        # keep δ in [0, π): a half turn relabels the slots by 4
        while delta >= math.pi - 1e-12 or delta < 0:
            delta += -math.pi if delta > 0 else math.pi
            theta_all = np.roll(theta_all, 4, axis=1)
    delta = float(np.mod(delta, 2 * np.pi)) if symmetry == "isotropic" else float(delta)
    all_cols = np.arange(gamma_grid.size)
    tables, fallback_gamma, clamped = [], set(), 0
    for ch in range(C):
        lobe, T, _, fallback = p.table_columns(theta_all[:, :, ch], bodies[ch], all_cols)
        tables.append(lobe.T)
        fallback_gamma.update(int(i) for i in fallback)
        clamped += int(np.count_nonzero(T - bodies[ch] * line_weight(gamma_grid, LINE_SUM, NORMALISATION)[:, None] < 0))
    table = np.stack(tables, axis=-1)
    body_arr = np.asarray(bodies, float)
    if not (np.all(np.isfinite(table)) and np.all(table >= 0) and np.all(np.isfinite(body_arr))):
        raise RuntimeError("fit_scattered produced a non-finite or negative table; this is a bug")
    warp_out = math.degrees(delta) if symmetry != "isotropic" else 0.0
    fallback_deg = [round(float(np.degrees(gamma_grid[i])), 6) for i in sorted(fallback_gamma)]
    return Model(
        channels=tuple(m.channels),
        phi_grid=np.arange(N_PHI) * (2 * np.pi / N_PHI),
        gamma_grid=gamma_grid,
        table=np.ascontiguousarray(table),
        body=body_arr,
        gamma_nodes=gamma_nodes,
        q_nodes=np.exp(theta_all),
        parameters={
            "orientations": 4,
            "fallback": "log",
            "body": body if isinstance(body, str) else [float(body)] * C,
            "noise_floor": "none",
            "interpolation": "kes",
            "gamma_interpolation": "linear",
            "n_phi": N_PHI,
            "normalisation": NORMALISATION,
            "extrapolation": "fade",
            "fit": "scattered",
            "symmetry": symmetry,
            "symmetry_requested": symmetry_asked,
            "warp_offset_deg": round(float(warp_out), 6),
            "warp_offset_rule": (
                "given" if warp_deg is not None else
                "none (isotropic)" if symmetry == "isotropic" else
                "search mod 45 deg, then the narrowest-lobe axis is the warp"
            ),
            "smooth_gamma": smooth_gamma,
            "smooth_phi": smooth_phi,
            "loss": "soft_l1 on ln(f + eps)",
            "loss_scale": loss_scale,
            "log_eps_rel": LOG_EPS_REL,
            "incidence_line_deg": 90.0,
            "mapping": mapping,
        },
        diagnostics={
            "warnings": [fallback_warning("gamma", fallback_deg)] if fallback_deg else [],
            "floored": [],
            "fallback_gamma_deg": fallback_deg,
            "lobe_clamped": clamped,
            "n_used": n_used,
            "azimuth_gap_deg": round(math.degrees(gap), 3),
            "unused_rows": int(len(m) - n_used),
            "cost": costs,
            "nfev": nfev,
            "train_log_rmse": train_log_rmse,
            "warp_search": search,
            "warp_label_shift_slots": shift,
        },
        input_info=m.input_info(),
    )


@register_fitter("scattered")
class ScatteredFit:
    """The scattered fit as a fitter of :mod:`kesbrdf.models.base`: it produces a ``kes`` model.

    Decision (docs/decisions.md): not a kind of its own.  The table, the file and the
    evaluation are the ``kes`` kind's, so the renderer, the viewer and the exports read
    it unchanged; what is particular to it (the sample-frame warp, the symmetry, the
    loss) is recorded in ``parameters``.
    """

    kind = "kes"
    #: kind="auto" compares the scattered fit with the prior by k-fold cross-validation
    auto_compare = "kfold"
    fit_options = ("warp_deg", "symmetry", "body", "smooth_gamma", "smooth_phi", "loss_scale",
                   "gamma_nodes_deg", "offset_step_deg", "max_nfev", "mapping")

    @classmethod
    def fit_measurement(cls, measurement, **options) -> Model:
        check_fit_options("scattered", cls.fit_options, options)
        return fit_scattered(measurement, **options)

    @classmethod
    def auto_skip(cls, measurement):
        """Why ``kind="auto"`` does not consider this fit, or None: in-plane data only is
        the KES kinds' (a least-squares fit of a few planes would invent the rest)."""
        if len(measurement) and bool(np.all(measurement.is_in_plane)):
            return "in-plane data only: the KES kinds apply (ask for kind 'scattered' to force it)"
        return None

    @classmethod
    def sparse_rows(cls, measurement) -> str | None:
        """Why ``kind="auto"`` should not let this fit take the rows beyond a simpler kind's
        (or None): fewer than half the rows are out of the plane of incidence.

        The same reason as :meth:`auto_skip`, by degree: a least-squares table fitted
        mostly to planes (the paper's 116 samples and 8 out-of-plane ones) interpolates
        the planes worse than the KES kinds do and is pinned off them by a few samples; it
        predicted the hemispheres worse than ``kes`` on the in-plane rows alone on 5 of 6
        references (docs/decisions.md, "More rows never predict worse").
        """
        n = len(measurement)
        out = int(np.count_nonzero(~measurement.is_in_plane))
        if n and out * 2 < n:
            return f"only {out} of {n} rows are out of the plane of incidence (needs half: general geometries)"
        return None

    @classmethod
    def usable_rows(cls, measurement):
        """(mask, reason): finite rows with both directions above the horizon."""
        m = measurement
        above = (m.wi[:, 2] > 0) & (m.wr[:, 2] > 0)
        finite = np.all(np.isfinite(m.values), axis=1)
        mask = above & finite
        parts = []
        if np.any(~above):
            parts.append(f"{int(np.count_nonzero(~above))} with a direction at the horizon (theta = 90 deg)")
        if np.any(above & ~finite):
            parts.append(f"{int(np.count_nonzero(above & ~finite))} with non-finite values")
        if np.count_nonzero(mask) < 8:
            return np.zeros(len(m), bool), (
                f"the scattered fit needs at least 8 usable rows (finite, above the horizon), got "
                f"{int(np.count_nonzero(mask))}"
            )
        return mask, "; ".join(parts)


def _fit_isotropic(problem, f, body_fixed, max_nfev):
    """Isotropic start for one channel (used when C > 1)."""
    iso = problem(f, "isotropic")
    return iso.solve(_initial(iso, f, body_fixed), max_nfev).x


# ---------------------------------------------------------------------------------
def fit_ward(m: Measurement, warp_deg: float | None = None, loss_scale: float = DEFAULT_LOSS_SCALE,
             offset_step_deg: float = 15.0, channel: int = 0):
    """Anisotropic Ward (α_x, α_y, ρ_d, ρ_s, warp) by robust least squares on ln f_r.

    The baseline of the comparison in docs/method.md, "The body term", fitted on the same terms as
    :func:`fit_scattered` (same residual, ε and loss).  The warp azimuth is searched on a
    grid over [0°, 180°) (every start then refined jointly with the other parameters).

    Returns
    -------
    RotatedBRDF
        Wraps a :class:`kesbrdf.references.ward.AnisotropicWard`; call it with
        sample-frame directions.  ``.warp`` is the fitted warp azimuth (radians).
    """
    from kesbrdf.references.ward import AnisotropicWard

    least_squares = _scipy_optimize().least_squares

    wi, wr = m.wi, m.wr
    f = m.values[:, channel]
    usable = (wi[:, 2] > 0) & (wr[:, 2] > 0) & np.isfinite(f)
    wi, wr, f = wi[usable], wr[usable], f[usable]
    eps = LOG_EPS_REL * max(float(np.max(np.abs(f))), np.finfo(float).tiny)
    log_t = np.log(np.maximum(f, 0.0) + eps)

    def model(x):
        ax, ay, rd, rs = np.exp(x[:4])
        warp = x[4] if warp_deg is None else math.radians(warp_deg)
        return RotatedBRDF(AnisotropicWard(ax, ay, rho_d=rd, rho_s=rs), warp)

    def residuals(x):
        r = np.log(model(x)(wi, wr)[:, 0] + eps) - log_t
        return _robust(r, loss_scale)[0]

    med = float(np.median(np.maximum(f, 0.0))) + eps
    starts = np.arange(0.0, 180.0, offset_step_deg) if warp_deg is None else [warp_deg]
    best = None
    for d in starts:
        for ax, ay in ((0.2, 0.4), (0.4, 0.2)):
            x0 = np.array([math.log(ax), math.log(ay), math.log(math.pi * 0.7 * med), math.log(0.1), math.radians(d)])
            res = least_squares(residuals, x0, method="trf", max_nfev=300,
                                bounds=([math.log(WARD_ALPHA_BOUNDS[0])] * 2 + [-30, -30, -np.inf], [math.log(WARD_ALPHA_BOUNDS[1])] * 2 + [5, 5, np.inf]))
            if best is None or res.cost < best.cost:
                best = res
    out = model(best.x)
    out.warp = float(np.mod(out.warp, np.pi))
    return out
