"""Microcylinder cloth BRDF of Sadeghi, Bisker, De Deken and Jensen (2013).

I. Sadeghi, O. Bisker, J. De Deken, H. W. Jensen, "A Practical Microcylinder
Appearance Model for Cloth Rendering", ACM Trans. Graph. 32(2), article 14, 2013.

Cloth is two families of dielectric threads, warp (family 1, along x) and weft
(family 2, along y). Each family covers an area fraction ``a_j`` of the surface. Its
tangent turns out of the cloth plane along a weave repeat, and the model describes that
turn with a piecewise-linear *tangent curve*. The BRDF averages a thread scattering
function f_s over samples of both tangent curves. Each sample is weighted by
shadowing/masking M and by a reweighting P. A view-dependent normaliser Q turns the sum
into an average over the visible area.

Source of the equations
-----------------------
The paper's full text could not be read for this implementation; only its abstract was
available. The equations follow implementation notes written for kesbrdf (kept out of
the repository; this docstring carries what the code depends on). Those notes rebuild
the model from several independent implementations and from one secondary transcription
that names the paper's equation numbers. The equation numbers quoted below are the
notes' numbers. The notes mark each statement as consensus [C],
single source [S], conflicting [⚠] or unverified [U]. Every [U]/[⚠] place, and the
choice made here:

* Longitudinal Gaussian ``g`` [⚠]: unit-area normal density with standard deviation γ,
  ``exp(-x²/2γ²)/(√(2π)γ)``. One source uses ``exp(-x²/γ²)/(γ√π)``; that form is not used.
* Transmission product F_t F_t' in Eq. 3 [⚠]: ``(1 - F_r)²``, both at the effective
  angle ``cos θ_d cos(φ_d/2)``. Other variants (Fresnel at the refracted angle, or at
  ``ω_r·n``) are not used.
* Correlated masking [⚠]: ``min`` of the two one-direction terms, not ``max``
  (Eqs. 7–9); σ of the unit-height Gaussian u is 20° [S: the paper gives 15°–25°].
  ``sigma_u`` changes it.
* Normaliser Q (Eq. 15) [⚠]: one-direction reweighting P(t, ω_r), plus the gap term
  ``(1 - a_1 - a_2) ω_r·n``. Some implementations sum the two-direction P or use
  ``ω_i·n``; that raises the white albedo at normal view by 1.5–1.9×.
* Equation numbers [U]. The area average is Eqs. 5–6, as the notes give them. The notes
  give reweighting and normaliser as one range, Eqs. 11–15. Within it, this module
  cites P as Eqs. 11–13, the per-tangent projection as Eq. 14 and Q as Eq. 15. Q = Eq. 15
  is the notes' [S] reading; the split of 11–14 is ours.
* Sign of the tangent offsets [U]: a positive offset α tilts the tangent toward +z for
  both families, ``t = cos α d_j + sin α z``. Only velvet's asymmetric warp curve
  (−90°, −50°) depends on it, and a flipped sign mirrors its pile direction.
* Tangent-curve segment lengths [S]: a single source. The offset varies linearly along
  each segment, and a zero-length segment is a jump.
* Sampling [S]: ``sampling="arclength"`` takes ``n_samples`` midpoint samples uniform in
  arclength along each curve. The notes describe this as the paper's scheme.
  ``sampling="control_points"`` uses each listed offset as one equally weighted sample
  and ignores the lengths, as two public implementations do.
* Table II [⚠]: satin weft ``A`` is 0.2 × colour, not 0.02 ×. Satin-back weft η is
  1.539 (polyester), not 1.46. Which physical family of each fabric is "warp" is [U];
  the first row of each fabric is put along x.
* Table I (fits to individual threads) [U]: not available. Only Table II is provided.
* Spatially varying (textured) use [U]: not modelled. This is a far-field BRDF
  averaged over one weave repeat.

Properties of the published model (as the notes list them), kept rather than fixed
----------------------------------------------------------------------
* **Not reciprocal.** The per-tangent kernel ``f_s M P`` is exactly symmetric, but Q
  reads ω_r alone and the projection factor is ``cos θ_i / (n·ω_i)``. Over random pairs,
  the middle 90 % of ``f(i, r)/f(r, i)`` spans about 0.3–3.4.
* **Not energy-bounded for A = 1.** Directional albedo for a white fabric reaches
  1.3–1.7. Table II's small ``A`` values absorb this, and the real presets stay at
  0.01–0.35 (velvet is the darkest).

**Reciprocity choice.** ``Sadeghi2013(..., reciprocal=True)`` is the default. It returns
the symmetrised ``(f(i, r) + f(r, i)) / 2``:

* a real fabric obeys Helmholtz reciprocity;
* every KES model (and the Ward and Ashikhmin–Shirley references) is reciprocal by
  construction, so comparisons with a non-reciprocal reference would count an
  artefact of the published model as KES error;
* the reference must pass a reciprocity check (issue 3).

The symmetrised form keeps energy: the real presets' albedo stays below 0.35 over the
tested view grid (tests/references/test_sadeghi2013.py).

``reciprocal=False`` gives the published forward model (ω_i = light, ω_r = viewer)
exactly as written. The golden values of the notes are for that form.

Numerics: the azimuth φ enters through cos φ = (ω·n_t)/ρ and
sin φ = (ω·b)/ρ, with ρ = |(ω·n_t, ω·b)| = cos θ. It is not computed as cos(atan2(·)),
which loses relative accuracy where cos φ is tiny. Near grazing the two differ by up to
1e-4 relative; elsewhere they agree to 1e-13. Inputs must be unit vectors.

Conventions: fabric frame x = warp, y = weft, z = normal; ``wi`` toward the light, ``wr``
toward the viewer; radians; f_r in 1/sr, never times a cosine. A pair with either
direction at or below the horizon gives 0, and a NaN in either direction gives NaN.

>>> import numpy as np
>>> brdf = Sadeghi2013("satin", reciprocal=False, n_samples=64)
>>> wi = np.array([-0.5, 0.0, np.sqrt(0.75)])  # light at 30° in the warp plane
>>> wr = np.array([0.5, 0.0, np.sqrt(0.75)])   # viewer at the mirror direction
>>> brdf(wi, wr).round(3).tolist()
[0.165, 0.142, 0.139]
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from kesbrdf.errors import KesbrdfError, validate_choice
from kesbrdf.optics import fresnel_dielectric
from kesbrdf.references.base import ReferenceBRDF

__all__ = [
    "Family",
    "ThreadFamily",
    "Fabric",
    "PRESETS",
    "PRESET_NAMES",
    "SAMPLING_METHODS",
    "SIGMA_U",
    "BLACK_SATIN_DYE_FACTOR",
    "Sadeghi2013",
    "Sadeghi2013Error",
    "black_satin",
    "black_satin_fabric",
    "fresnel_dielectric",
]

#: σ of the unit-height Gaussian u in the correlated masking and reweighting (Eqs. 9,
#: 13): 20°, as in most sources. The notes say the paper gives a range of 15°–25° [S].
SIGMA_U = math.radians(20.0)

#: Names accepted by ``Sadeghi2013(sampling=...)``.
SAMPLING_METHODS = ("arclength", "control_points")

# Numerical guards: cos θ_d → 0 and cos θ_i + cos θ_r → 0 occur only when light
# and view run along ±t in opposite senses. There the kernel is zero anyway through M, P
# or cos θ_i, so the guards only keep the arithmetic finite.
_COS_THETA_D_MIN = 1e-4
_COS_SUM_MIN = 1e-6


class Sadeghi2013Error(KesbrdfError):
    """Invalid parameters for the microcylinder cloth model."""


# ---------------------------------------------------------------------------------------
# Parameters
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Family:
    """One thread family (one row of Table II), in radians.

    Parameters
    ----------
    eta : float
        Relative index of refraction of the fibre, > 1.
    A : tuple of 3 floats
        Linear-RGB volume albedo (the thread colour), ≥ 0. This is a fitted scale, not a
        bounded albedo.
    kd : float
        Fraction of the volume scattering that is isotropic in θ, in [0, 1] (Eq. 3).
    gamma_s, gamma_v : float
        Standard deviations of the surface and volume longitudinal lobes (Eqs. 2–3), in
        radians, > 0.
    a : float
        Fraction of the cloth area covered by this family, in [0, 1] (Eq. 5).
    offsets : tuple of floats
        Tangent-offset control points of the tangent curve, in radians. A positive offset
        tilts the thread tangent toward +z.
    lengths : tuple of floats
        Arclength of each segment between consecutive control points, ≥ 0. There are
        ``len(offsets) - 1`` of them, in any one unit within the family. The offset
        varies linearly along a segment; a zero-length segment is a jump.
    """

    eta: float
    A: tuple[float, float, float]
    kd: float
    gamma_s: float
    gamma_v: float
    a: float
    offsets: tuple[float, ...]
    lengths: tuple[float, ...] = field(default=())

    def __post_init__(self) -> None:
        A = tuple(float(x) for x in np.ravel(self.A))
        offsets = tuple(float(x) for x in np.ravel(self.offsets))
        lengths = tuple(float(x) for x in np.ravel(self.lengths))
        object.__setattr__(self, "A", A)
        object.__setattr__(self, "offsets", offsets)
        object.__setattr__(self, "lengths", lengths)
        checks = [
            (self.eta > 1.0, "eta > 1", self.eta),
            (len(A) == 3 and all(x >= 0 for x in A), "A = three values >= 0", A),
            (0.0 <= self.kd <= 1.0, "kd in [0, 1]", self.kd),
            (self.gamma_s > 0.0, "gamma_s > 0 (radians)", self.gamma_s),
            (self.gamma_v > 0.0, "gamma_v > 0 (radians)", self.gamma_v),
            (0.0 <= self.a <= 1.0, "a in [0, 1]", self.a),
            (len(offsets) >= 1, "at least one tangent offset", offsets),
            (
                all(abs(x) <= math.pi / 2 + 1e-12 for x in offsets),
                "tangent offsets within ±pi/2 (radians)",
                offsets,
            ),
            (
                len(lengths) == max(len(offsets) - 1, 0) or (len(offsets) == 1 and not lengths),
                f"{max(len(offsets) - 1, 0)} segment lengths for {len(offsets)} offsets",
                lengths,
            ),
            (all(x >= 0 for x in lengths), "segment lengths >= 0", lengths),
            (
                len(offsets) == 1 or sum(lengths) > 0,
                "a tangent curve of positive total length",
                lengths,
            ),
        ]
        for ok, expected, got in checks:
            if not ok or not np.all(np.isfinite(np.ravel(got))):
                raise Sadeghi2013Error(
                    f"Sadeghi2013 thread family: expected {expected}, got {got!r}"
                )

    @classmethod
    def from_deg(
        cls,
        *,
        eta: float,
        A,
        kd: float,
        gamma_s_deg: float,
        gamma_v_deg: float,
        a: float,
        offsets_deg,
        lengths=(),
    ) -> Family:
        """Build a family from Table II's degree units.

        >>> Family.from_deg(eta=1.46, A=(0.06, 0.24, 0.3), kd=0.3, gamma_s_deg=12,
        ...                 gamma_v_deg=24, a=0.33, offsets_deg=(-25, 25),
        ...                 lengths=(1,)).tangent_offsets(2).round(4).tolist()
        [-0.2182, 0.2182]
        """
        return cls(
            eta=float(eta),
            A=tuple(A),
            kd=float(kd),
            gamma_s=math.radians(gamma_s_deg),
            gamma_v=math.radians(gamma_v_deg),
            a=float(a),
            offsets=tuple(math.radians(x) for x in np.ravel(offsets_deg)),
            lengths=tuple(np.ravel(lengths)),
        )

    def tangent_offsets(self, n_samples: int = 32, sampling: str = "arclength") -> np.ndarray:
        """Tangent-offset samples α of this family's tangent curve (radians).

        ``"arclength"``: ``n_samples`` midpoint samples uniform in arclength, with linear
        interpolation along each segment. ``"control_points"``: the control
        points themselves, with ``n_samples`` ignored.
        """
        offsets = np.asarray(self.offsets, float)
        if sampling == "control_points" or offsets.size == 1:
            if sampling == "control_points":
                return offsets.copy()
            return np.full(int(n_samples), offsets[0])
        lengths = np.asarray(self.lengths, float)
        cumulative = np.concatenate([[0.0], np.cumsum(lengths)])
        s = (np.arange(int(n_samples)) + 0.5) / int(n_samples) * cumulative[-1]
        # the last segment start at or before s; skips zero-length segments (jumps)
        segment = np.clip(np.searchsorted(cumulative, s, side="right") - 1, 0, lengths.size - 1)
        seg_len = lengths[segment]
        frac = np.where(seg_len > 0, (s - cumulative[segment]) / np.where(seg_len > 0, seg_len, 1.0), 0.0)
        return offsets[segment] + frac * (offsets[segment + 1] - offsets[segment])


#: Alias, for readers who look for the longer name.
ThreadFamily = Family


@dataclass(frozen=True)
class Fabric:
    """A woven cloth: a warp family (along x) and a weft family (along y).

    ``warp.a + weft.a`` must be at most 1; the remainder is gap (Eq. 15's gap term).
    """

    name: str
    warp: Family
    weft: Family

    def __post_init__(self) -> None:
        total = self.warp.a + self.weft.a
        if total > 1.0 + 1e-12:
            raise Sadeghi2013Error(
                f"Sadeghi2013 fabric {self.name!r}: expected warp.a + weft.a <= 1, got {total:g}"
            )

    @property
    def families(self) -> tuple[Family, Family]:
        return (self.warp, self.weft)

    def with_albedo(self, warp_A=None, weft_A=None, name: str | None = None) -> Fabric:
        """A copy with other volume albedos (thread colours); other parameters are unchanged."""
        warp = self.warp if warp_A is None else replace(self.warp, A=tuple(warp_A))
        weft = self.weft if weft_A is None else replace(self.weft, A=tuple(weft_A))
        return Fabric(name=name or self.name, warp=warp, weft=weft)


def _rgb(scale: float, rgb) -> tuple[float, float, float]:
    return tuple(scale * float(c) for c in rgb)


_LINEN = Family.from_deg(
    eta=1.46, A=_rgb(0.3, (0.2, 0.8, 1.0)), kd=0.3, gamma_s_deg=12, gamma_v_deg=24,
    a=0.33, offsets_deg=(-25, 25), lengths=(1,),
)
_SATIN_COLOUR = (1.0, 0.37, 0.3)

#: Table II of the paper (as the notes transcribe it), keyed by preset name.
PRESETS: dict[str, Fabric] = {
    "linen": Fabric("linen", warp=_LINEN, weft=_LINEN),
    "silk_crepe": Fabric(
        "silk_crepe",
        warp=Family.from_deg(
            eta=1.345, A=_rgb(0.12, (1.0, 0.95, 0.05)), kd=0.2, gamma_s_deg=5,
            gamma_v_deg=10, a=0.75, offsets_deg=(-35, -35, 35, 35), lengths=(1, 1, 1),
        ),
        weft=Family.from_deg(
            eta=1.345, A=_rgb(0.16, (1.0, 0.95, 0.05)), kd=0.3, gamma_s_deg=18,
            gamma_v_deg=32, a=0.25, offsets_deg=(0, 0), lengths=(1,),
        ),
    ),
    "satin": Fabric(
        "satin",
        warp=Family.from_deg(
            eta=1.539, A=_rgb(0.035, _SATIN_COLOUR), kd=0.1, gamma_s_deg=2.5,
            gamma_v_deg=5, a=0.9, offsets_deg=(-32, -32, -18, 0, 0, 18, 32, 32),
            lengths=(1.33, 0.66, 2.0, 2.0, 2.0, 0.66, 1.33),
        ),
        weft=Family.from_deg(
            eta=1.539, A=_rgb(0.2, _SATIN_COLOUR), kd=0.7, gamma_s_deg=30,
            gamma_v_deg=60, a=0.1, offsets_deg=(0, 0), lengths=(1,),
        ),
    ),
    "satin_back": Fabric(
        "satin_back",
        warp=Family.from_deg(
            eta=1.539, A=_rgb(0.035, _SATIN_COLOUR), kd=0.1, gamma_s_deg=2.5,
            gamma_v_deg=5, a=0.67, offsets_deg=(-30, -30, 30, 30, -5, -5, 5, 5),
            lengths=(1.33, 1.33, 1.33, 0, 0.67, 0.67, 0.67),
        ),
        weft=Family.from_deg(
            eta=1.539, A=_rgb(0.2, _SATIN_COLOUR), kd=0.7, gamma_s_deg=30,
            gamma_v_deg=60, a=0.33, offsets_deg=(0, 0), lengths=(3,),
        ),
    ),
    "silk_shot": Fabric(
        "silk_shot",
        warp=Family.from_deg(
            eta=1.345, A=_rgb(0.2, (0.1, 1.0, 0.4)), kd=0.1, gamma_s_deg=4,
            gamma_v_deg=8, a=0.86, offsets_deg=(-25, -25, 25, 25), lengths=(1.33, 2.67, 1.33),
        ),
        weft=Family.from_deg(
            eta=1.345, A=_rgb(0.6, (1.0, 0.0, 0.1)), kd=0.1, gamma_s_deg=5,
            gamma_v_deg=10, a=0.14, offsets_deg=(0, 0), lengths=(3,),
        ),
    ),
    "velvet": Fabric(
        "velvet",
        warp=Family.from_deg(
            eta=1.46, A=_rgb(0.3, (0.05, 0.02, 0.0)), kd=0.1, gamma_s_deg=6,
            gamma_v_deg=12, a=0.5, offsets_deg=(-90, -50), lengths=(1,),
        ),
        weft=Family.from_deg(
            eta=1.46, A=_rgb(0.3, (0.05, 0.02, 0.0)), kd=0.1, gamma_s_deg=6,
            gamma_v_deg=12, a=0.5, offsets_deg=(-90, -55, 55, 90), lengths=(0.5, 0, 0.5),
        ),
    ),
}

#: Preset names, in Table II order.
PRESET_NAMES = tuple(PRESETS)


def _validate_name(kind: str, name: object, valid: tuple[str, ...]) -> str:
    if not isinstance(name, str):
        name = repr(name)  # e.g. a number: still listed among the valid names
    return validate_choice(f"Sadeghi2013 {kind}", name, valid, error=Sadeghi2013Error)


# ---------------------------------------------------------------------------------------
# Thread scattering pieces
# ---------------------------------------------------------------------------------------


def _gaussian(gamma: float, x):
    """Unit-area normal density with standard deviation ``gamma``."""
    return np.exp(-x * x / (2.0 * gamma * gamma)) / (math.sqrt(2.0 * math.pi) * gamma)


def _wrap_pi(x):
    """Wrap to [−π, π)."""
    return (x + math.pi) % (2.0 * math.pi) - math.pi


def _correlated(cos_i, cos_r, u):
    """Blend of uncorrelated and fully correlated masking (Eqs. 7–9 and 12–13).

    .. math:: (1-u(\\delta))\\,m_i m_r + u(\\delta)\\,\\min(m_i, m_r),\\quad
              m = \\max(\\cos, 0),\\ u(x) = e^{-x^2/2\\sigma_u^2}

    ``u`` is the already evaluated u(δ) of the angle difference δ (φ_d or ψ_d).
    """
    m_i = np.maximum(cos_i, 0.0)
    m_r = np.maximum(cos_r, 0.0)
    return (1.0 - u) * m_i * m_r + u * np.minimum(m_i, m_r)


def _polar(x, y):
    """Return (ρ, cos, sin) of the 2-D vector (x, y), with atan2(0, 0) = 0 giving (0, 1, 0)."""
    radius = np.hypot(x, y)
    positive = radius > 0
    safe = np.where(positive, radius, 1.0)
    return radius, np.where(positive, x / safe, 1.0), np.where(positive, y / safe, 0.0)


# ---------------------------------------------------------------------------------------
# The BRDF
# ---------------------------------------------------------------------------------------


class Sadeghi2013(ReferenceBRDF):
    """Microcylinder cloth BRDF (Sadeghi et al. 2013), callable as ``f(wi, wr)``.

    .. math::
        f_r(\\omega_i,\\omega_r) = \\frac{1}{Q(\\omega_r)\\,(n\\cdot\\omega_i)}
        \\sum_{j=1}^{2}\\frac{a_j}{N_j}\\sum_{k=1}^{N_j}
        f_s(t_{jk})\\,M(t_{jk})\\,P(t_{jk})\\cos\\theta_{i,jk}

    This is the BRDF form of the shading model, Eqs. 5–6 and 14–15. The
    thread function f_s is Eqs. 2–4, M is Eqs. 7–9, P is Eqs. 11–13, and Q is Eq. 15.

    Parameters
    ----------
    preset : str or Fabric
        One of :data:`PRESET_NAMES` (``linen``, ``silk_crepe``, ``satin``,
        ``satin_back``, ``silk_shot``, ``velvet``: Table II), or a user-defined
        :class:`Fabric`.
    n_samples : int
        Number of tangent samples per family for ``sampling="arclength"`` (default 32).
        The notes find 16–64 converged.
    sampling : {"arclength", "control_points"}
        How the tangent curves are sampled; see :meth:`Family.tangent_offsets`.
    reciprocal : bool
        True (default): return the symmetrised ``(f(i, r) + f(r, i)) / 2``, which is
        exactly reciprocal. False: the published forward model (light → eye). See the
        module docstring for why the default is True.
    sigma_u : float
        σ of the correlation Gaussian u, in radians (default 20°).

    Attributes
    ----------
    channels : tuple of str
        ``("R", "G", "B")`` (linear RGB).
    fabric : Fabric
    alphas : tuple of ndarray
        Tangent-offset samples of the warp and weft families (radians).
    """

    channels = ("R", "G", "B")
    error = Sadeghi2013Error

    def __init__(
        self,
        preset: str | Fabric = "satin",
        *,
        n_samples: int = 32,
        sampling: str = "arclength",
        reciprocal: bool = True,
        sigma_u: float = SIGMA_U,
    ) -> None:
        if isinstance(preset, Fabric):
            self.fabric = preset
        else:
            self.fabric = PRESETS[_validate_name("preset", preset, PRESET_NAMES)]
        self.sampling = _validate_name("sampling", sampling, SAMPLING_METHODS)
        if isinstance(n_samples, bool) or not isinstance(n_samples, (int, np.integer)) or n_samples < 1:
            raise Sadeghi2013Error(f"Sadeghi2013 n_samples: expected an integer >= 1, got {n_samples!r}")
        if not (np.isfinite(sigma_u) and sigma_u > 0):
            raise Sadeghi2013Error(f"Sadeghi2013 sigma_u: expected > 0 radians, got {sigma_u!r}")
        self.n_samples = int(n_samples)
        self.reciprocal = bool(reciprocal)
        self.sigma_u = float(sigma_u)
        self.alphas = tuple(
            fam.tangent_offsets(self.n_samples, self.sampling) for fam in self.fabric.families
        )

    @property
    def name(self) -> str:
        return self.fabric.name

    def params(self) -> dict:
        """JSON-ready description of this reference (recorded by the virtual gonioreflectometer).

        Angles are given in degrees (keys ``*_deg``), so the record reads like Table II.
        """

        def family(f: Family) -> dict:
            return {
                "eta": f.eta,
                "A": list(f.A),
                "kd": f.kd,
                "gamma_s_deg": math.degrees(f.gamma_s),
                "gamma_v_deg": math.degrees(f.gamma_v),
                "a": f.a,
                "offsets_deg": [math.degrees(x) for x in f.offsets],
                "lengths": list(f.lengths),
            }

        return {
            "reference": "sadeghi2013",
            "fabric": self.fabric.name,
            "n_samples": self.n_samples,
            "sampling": self.sampling,
            "reciprocal": self.reciprocal,
            "sigma_u_deg": math.degrees(self.sigma_u),
            "warp": family(self.fabric.warp),
            "weft": family(self.fabric.weft),
        }

    def __repr__(self) -> str:
        return (
            f"Sadeghi2013({self.fabric.name!r}, n_samples={self.n_samples}, "
            f"sampling={self.sampling!r}, reciprocal={self.reciprocal})"
        )

    # -- per-tangent geometry -----------------------------------------------------------

    @staticmethod
    def _family_axes(w, family_index: int):
        """Return (ω·d_j, ω·b, ω·z) for family j (d_1 = x with b = −y; d_2 = y with b = +x).

        With t = cos α d_j + sin α z and n_t = −sin α d_j + cos α z, the frame's
        third axis is b = t × n_t, which is −y for the warp and +x for the weft.
        """
        if family_index == 0:
            return w[..., 0], -w[..., 1], w[..., 2]
        return w[..., 1], w[..., 0], w[..., 2]

    def _terms(self, wi, wr):
        """Yield, per tangent sample, its family index, weight a_j/N_j and angle pieces.

        Each item is a tuple ``(j, weight, surf_k, vol_k, cos_theta_i, cos_theta_r,
        cos_psi_i, cos_psi_r)``. ``surf_k`` and ``vol_k`` are the surface and volume parts
        of the kernel f_s·M·P: achromatic, with ``vol_k`` still to be multiplied by A_j.
        """
        two_sigma2 = 2.0 * self.sigma_u * self.sigma_u
        for j, (family, alphas) in enumerate(zip(self.fabric.families, self.alphas)):
            if alphas.size == 0 or family.a == 0.0:
                continue
            weight = family.a / alphas.size
            # Per family, before the tangent loop. Tilting the tangent by α rotates
            # (t, n_t) about b, so ψ = β + α, where β = atan2(ω·d_j, ω·z) does not depend on α.
            # Hence ψ_d = β_i − β_r and u(ψ_d) are the same for every sample, and
            # cos ψ = (ω·n_t)/r with r = |(ω·d_j, ω·z)|.
            along_i, across_i, z_i = self._family_axes(wi, j)
            along_r, across_r, z_r = self._family_axes(wr, j)
            # r ≥ ω·z > 0 above the horizon; the guard only keeps horizon pairs finite
            inv_r_i = 1.0 / np.maximum(np.hypot(along_i, z_i), 1e-300)
            inv_r_r = 1.0 / np.maximum(np.hypot(along_r, z_r), 1e-300)
            psi_d = _wrap_pi(np.arctan2(along_i, z_i) - np.arctan2(along_r, z_r))
            u_psi = np.exp(-psi_d * psi_d / two_sigma2)
            for alpha in alphas:
                cos_a, sin_a = math.cos(alpha), math.sin(alpha)
                # ω·t, ω·n_t (ω·b is `across`, the same for every α)
                t_i = cos_a * along_i + sin_a * z_i
                n_i = cos_a * z_i - sin_a * along_i
                t_r = cos_a * along_r + sin_a * z_r
                n_r = cos_a * z_r - sin_a * along_r
                # azimuth φ = atan2(ω·b, ω·n_t) around the thread, through its cosine and
                # sine; ρ = |(ω·n_t, ω·b)| is also cos θ, free of the cancellation in √(1 − t²)
                cos_theta_i, cos_phi_i, sin_phi_i = _polar(n_i, across_i)
                cos_theta_r, cos_phi_r, sin_phi_r = _polar(n_r, across_r)
                # longitudinal angles θ ∈ [−π/2, π/2] from the thread's normal plane (§2)
                theta_h = 0.5 * (np.arctan2(t_i, cos_theta_i) + np.arctan2(t_r, cos_theta_r))
                # cos θ_d = cos((θ_i − θ_r)/2) = √((1 + cos(θ_i − θ_r))/2)
                cos_theta_diff = np.clip(cos_theta_i * cos_theta_r + t_i * t_r, -1.0, 1.0)
                cos_theta_d = np.maximum(np.sqrt(0.5 * (1.0 + cos_theta_diff)), _COS_THETA_D_MIN)
                # φ_d ∈ [0, π] from cos φ_d (only even functions of φ_d are used)
                cos_phi_d = np.clip(cos_phi_i * cos_phi_r + sin_phi_i * sin_phi_r, -1.0, 1.0)
                phi_d = np.arccos(cos_phi_d)
                cos_half_phi_d = np.sqrt(0.5 * (1.0 + cos_phi_d))
                # Eq. 2: achromatic surface reflection at the effective angle
                F_r = fresnel_dielectric(cos_theta_d * cos_half_phi_d, family.eta)
                surf = F_r * cos_half_phi_d * _gaussian(family.gamma_s, theta_h)
                # Eq. 3: volume scattering, the whole bracket over cos θ_i + cos θ_r
                F_t = 1.0 - F_r
                vol = (
                    F_t * F_t
                    * ((1.0 - family.kd) * _gaussian(family.gamma_v, theta_h) + family.kd)
                    / np.maximum(cos_theta_i + cos_theta_r, _COS_SUM_MIN)
                )
                cos_psi_i = n_i * inv_r_i
                cos_psi_r = n_r * inv_r_r
                # Eqs. 7–9 (masking M) and 11–13 (reweighting P); Eq. 4's 1/cos² θ_d
                u_phi = np.exp(-phi_d * phi_d / two_sigma2)
                mp = (
                    _correlated(cos_phi_i, cos_phi_r, u_phi)
                    * _correlated(cos_psi_i, cos_psi_r, u_psi)
                    / (cos_theta_d * cos_theta_d)
                )
                yield (j, weight, surf * mp, vol * mp, cos_theta_i, cos_theta_r, cos_psi_i, cos_psi_r)

    @staticmethod
    def _directions(wi, wr):
        wi = np.asarray(wi, dtype=float)
        wr = np.asarray(wr, dtype=float)
        if wi.ndim == 0 or wr.ndim == 0 or wi.shape[-1] != 3 or wr.shape[-1] != 3:
            raise Sadeghi2013Error(
                f"Sadeghi2013: expected direction arrays of shape (..., 3), got "
                f"{np.shape(wi)} and {np.shape(wr)}"
            )
        return np.broadcast_arrays(wi, wr)

    # -- public evaluation --------------------------------------------------------------

    def kernel(self, wi, wr) -> np.ndarray:
        """Per-tangent kernel ``K = f_s·M·P`` (Eqs. 4, 9, 13), shape ``(S, ..., 3)``.

        Samples are the warp ones, then the weft ones; ``S`` is their total. K is exactly
        symmetric under ``wi ↔ wr``. The full f_r is not, because of Q and
        the projection factor.
        """
        wi, wr = self._directions(wi, wr)
        with np.errstate(invalid="ignore", divide="ignore"):
            out = [
                surf_k[..., None] + vol_k[..., None] * np.asarray(self.fabric.families[j].A)
                for j, _w, surf_k, vol_k, *_ in self._terms(wi, wr)
            ]
        return np.stack(out) if out else np.zeros((0,) + wi.shape[:-1] + (3,))

    def Q(self, wr) -> np.ndarray:
        """Visible-area normaliser Q(ω_r) of Eq. 15, shape ``(...)``.

        .. math:: Q = \\sum_j \\frac{a_j}{N_j}\\sum_k P(t_{jk},\\omega_r)
                      + (1 - a_1 - a_2)\\,(\\omega_r\\cdot n)

        P(t, ω) = max(cos ψ, 0) is the one-direction reweighting (Eq. 11).
        """
        wr = np.asarray(wr, dtype=float)
        q = (1.0 - self.fabric.warp.a - self.fabric.weft.a) * wr[..., 2]
        for j, (family, alphas) in enumerate(zip(self.fabric.families, self.alphas)):
            if alphas.size == 0:
                continue
            weight = family.a / alphas.size
            along, _, z = self._family_axes(wr, j)
            for alpha in alphas:
                t_r = math.cos(alpha) * along + math.sin(alpha) * z
                n_r = math.cos(alpha) * z - math.sin(alpha) * along
                q = q + weight * np.maximum(np.cos(np.arctan2(t_r, n_r)), 0.0)
        return q

    def core(self, wi, wr) -> np.ndarray:
        """f_r in 1/sr per RGB channel, (n, 3), of unit pairs above the horizon; 0 where
        Q ≤ 0.  The horizon, NaN and broadcasting are :class:`ReferenceBRDF`'s."""
        shape = wi.shape[:-1]
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            surf_i = np.zeros(shape)
            surf_r = np.zeros(shape)
            vol_i = [np.zeros(shape), np.zeros(shape)]
            vol_r = [np.zeros(shape), np.zeros(shape)]
            q_r = (1.0 - self.fabric.warp.a - self.fabric.weft.a) * wr[..., 2]
            q_i = (1.0 - self.fabric.warp.a - self.fabric.weft.a) * wi[..., 2]
            for j, weight, surf_k, vol_k, cos_ti, cos_tr, cos_psi_i, cos_psi_r in self._terms(wi, wr):
                # Eq. 14: projection by the per-tangent longitudinal cosine
                surf_i += weight * surf_k * cos_ti
                vol_i[j] += weight * vol_k * cos_ti
                q_r += weight * np.maximum(cos_psi_r, 0.0)  # Eq. 15
                if self.reciprocal:
                    surf_r += weight * surf_k * cos_tr
                    vol_r[j] += weight * vol_k * cos_tr
                    q_i += weight * np.maximum(cos_psi_i, 0.0)
            A_warp, A_weft = (np.asarray(f.A) for f in self.fabric.families)
            num_i = surf_i[..., None] + vol_i[0][..., None] * A_warp + vol_i[1][..., None] * A_weft
            f = num_i / (q_r * wi[..., 2])[..., None]
            f = np.where((q_r > 0)[..., None], f, 0.0)
            if self.reciprocal:
                num_r = surf_r[..., None] + vol_r[0][..., None] * A_warp + vol_r[1][..., None] * A_weft
                f_rev = num_r / (q_i * wr[..., 2])[..., None]
                f = 0.5 * (f + np.where((q_i > 0)[..., None], f_rev, 0.0))
        return f


# ---------------------------------------------------------------------------------------
# Virtual black satin
# ---------------------------------------------------------------------------------------

#: Neutral grey level that replaces the satin preset's salmon colour (1, 0.37, 0.3) in
#: both families' A. Each family keeps its Table II scale (0.035 warp, 0.2 weft). See
#: :func:`black_satin_fabric` for the derivation.
BLACK_SATIN_DYE_FACTOR = 0.25


def black_satin_fabric(dye_factor: float = BLACK_SATIN_DYE_FACTOR) -> Fabric:
    """The satin preset darkened like the black satin of Takeda et al. (a Fabric).

    A black-dyed polyester satin keeps what the dye cannot reach. Surface (Fresnel)
    reflection off the fibre (Eq. 2) is achromatic and unchanged: same η = 1.539, the
    same γ_s, and the same tangent curves. So the stretched warp-float highlight stays
    whole. The dye absorbs the light that enters the fibre. Only the volume term
    (Eq. 3) carries A, so A becomes a dark neutral grey:

    .. math:: A_j^{black} = s_j \\cdot d \\cdot (1, 1, 1)

    Here s_j is the family's Table II scale (0.035 warp, 0.2 weft) and d is
    ``dye_factor``.

    Where the default d = 0.25 (:data:`BLACK_SATIN_DYE_FACTOR`) comes from: the directional
    albedo at normal view, from a quadrature of this module:

    * Lit (salmon) satin: about (0.214, 0.169, 0.164). Of that, about 0.142 is the
      achromatic Fresnel sheen of Eq. 2. The volume ("body") part is (0.072, 0.027,
      0.022).
    * Volume part scales linearly with A, so d = 0.25 puts the black satin's body part
      at 0.25 × 0.072 ≈ 1.8 % in every channel. That is the diffuse reflectance of a
      black-dyed textile (reflectance factor about 1–3 %).
    * The sheen stays at about 14 %, so black satin is, as a real one is, seen almost
      entirely through its highlights.

    (The reciprocal form and arclength sampling change these numbers by less than 10 %.)
    The colour is neutral because a black dye absorbs the whole visible range.
    """
    if not (np.isfinite(dye_factor) and dye_factor >= 0):
        raise Sadeghi2013Error(f"black_satin dye_factor: expected >= 0, got {dye_factor!r}")
    satin = PRESETS["satin"]

    def grey(family: Family) -> tuple[float, float, float]:
        # the salmon colour's largest component is 1, so max(A) is the Table II scale s_j
        return (max(family.A) * dye_factor,) * 3

    return satin.with_albedo(grey(satin.warp), grey(satin.weft), name="black_satin")


def black_satin(dye_factor: float = BLACK_SATIN_DYE_FACTOR, **kwargs) -> Sadeghi2013:
    """``Sadeghi2013`` of :func:`black_satin_fabric`; ``kwargs`` go to the constructor.

    >>> brdf = black_satin()
    >>> brdf.fabric.name, [round(x, 5) for x in brdf.fabric.warp.A]
    ('black_satin', [0.00875, 0.00875, 0.00875])
    """
    return Sadeghi2013(black_satin_fabric(dye_factor), **kwargs)
