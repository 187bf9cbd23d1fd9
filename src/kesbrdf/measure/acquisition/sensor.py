r"""The camera sensor model of the virtual gonioreflectometer.

A pixel that receives an expected photoelectron rate :math:`r` (e⁻/s) during an
exposure :math:`t` records, in order:

1. **Photon (shot) noise and dark current**: :math:`n_e \sim \mathrm{Poisson}(r t + d t)`
   with dark current :math:`d` (e⁻/s).
2. **Read noise**: :math:`+\,\mathcal{N}(0, \sigma_{read}^2)` electrons.
3. **Clipping**: :math:`n_e \leftarrow \min(n_e, N_{fw})`: the full well and the ADC's
   full scale coincide, so an exposure that is too long clips, exactly as a real
   sensor does.
4. **Analogue-to-digital conversion**: :math:`DN = n_e / g + b`, with the gain
   :math:`g = N_{fw} / (DN_{max} - b)` (e⁻/DN) chosen so that a full well reads
   exactly the largest code :math:`DN_{max} = 2^{bits} - 1`, and a black level
   :math:`b` (DN), then rounded and clipped to ``[0, DN_max]`` (8- or 16-bit output).
   A saturated pixel therefore always reads :math:`DN_{max}`.
5. **Response**: ``"linear"`` stores DN as is; ``"srgb"`` stores the sRGB encoding
   (IEC 61966-2-1) of :math:`DN / DN_{max}`, as consumer cameras do.

Optional **vignetting** multiplies the rate by :math:`V = 1 - k\,\rho^2`, with
:math:`\rho` the distance from the frame centre relative to the corner.

The predicted standard deviation of one linear pixel, in DN, is

.. math::
    \sigma_{DN} = \sqrt{s + (1 - e^{-2\pi^2 s})/12},
    \qquad s = (r t + d t + \sigma_{read}^2) / g^2

(photon + dark shot noise, read noise, and rounding, which adds 1/12 DN² once the
noise spans a code and nothing to a noiseless signal), see
:meth:`Sensor.pixel_sigma_dn`. Tests derive their tolerances from it.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from kesbrdf.errors import KesbrdfError, validate_choice

__all__ = ["Sensor", "RESPONSES", "srgb_encode", "srgb_decode", "vignetting_map"]

#: Camera responses a frame can be stored with.
RESPONSES = ("linear", "srgb")


def srgb_encode(x) -> np.ndarray:
    """sRGB transfer function (IEC 61966-2-1): linear [0, 1] -> encoded [0, 1].

    >>> float(srgb_encode(0.5).round(4))
    0.7354
    """
    x = np.clip(np.asarray(x, float), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def srgb_decode(y) -> np.ndarray:
    """Inverse sRGB transfer function: encoded [0, 1] -> linear [0, 1].

    >>> float(srgb_decode(srgb_encode(0.25)).round(12))
    0.25
    """
    y = np.clip(np.asarray(y, float), 0.0, 1.0)
    return np.where(y <= 0.04045, y / 12.92, np.power((y + 0.055) / 1.055, 2.4))


def vignetting_map(height: int, width: int, strength: float) -> np.ndarray:
    """Relative illumination ``1 − k·ρ²`` of a (height, width) frame (1 at the centre)."""
    y, x = np.mgrid[0:height, 0:width].astype(float)
    cy, cx = (height - 1) / 2.0, (width - 1) / 2.0
    rho2 = ((y - cy) ** 2 + (x - cx) ** 2) / max(cy**2 + cx**2, 1e-12)
    return 1.0 - strength * rho2


@dataclass(frozen=True)
class Sensor:
    """A linear photon-counting sensor with 8- or 16-bit output (module docstring).

    Parameters
    ----------
    full_well_e : float
        Full-well capacity, electrons.
    read_noise_e : float
        Read noise, electrons (one standard deviation).
    dark_current_e_per_s : float
        Dark current, electrons per second.
    bit_depth : {8, 16}
        Output bit depth.
    black_level_dn : float or None
        Black level (DN); default 1/64 of the code range (1024 at 16 bit, 4 at 8 bit).
    response : {"linear", "srgb"}
        How the stored code values encode the linear signal.
    vignetting : float
        Strength k of the relative illumination 1 − k·ρ² (0: none; 0.3: 30 % darker
        corners).
    """

    full_well_e: float = 30000.0
    read_noise_e: float = 3.0
    dark_current_e_per_s: float = 0.5
    bit_depth: int = 16
    black_level_dn: float | None = None
    response: str = "linear"
    vignetting: float = 0.0

    def __post_init__(self) -> None:
        validate_choice("sensor bit_depth", self.bit_depth, (8, 16))
        validate_choice("sensor response", self.response, RESPONSES)
        if not (self.full_well_e > 0 and self.read_noise_e >= 0 and self.dark_current_e_per_s >= 0):
            raise KesbrdfError(
                "sensor: expected full_well_e > 0, read_noise_e >= 0, dark_current_e_per_s >= 0, "
                f"got {self.full_well_e}, {self.read_noise_e}, {self.dark_current_e_per_s}"
            )
        if not (0.0 <= self.vignetting < 1.0):
            raise KesbrdfError(f"sensor vignetting: expected 0 <= k < 1, got {self.vignetting!r}")
        if not (0 <= self.black_level < self.max_code):
            raise KesbrdfError(f"sensor black_level_dn: expected in [0, {self.max_code}), got {self.black_level}")

    # -- derived constants --------------------------------------------------------------
    @property
    def max_code(self) -> int:
        """Largest code value, 2**bit_depth − 1 (the saturation level)."""
        return (1 << self.bit_depth) - 1

    @property
    def black_level(self) -> float:
        """Black level in DN."""
        if self.black_level_dn is None:
            return float((1 << self.bit_depth) // 64)
        return float(self.black_level_dn)

    @property
    def gain_e_per_dn(self) -> float:
        """Electrons per DN: a full well maps exactly onto the largest code."""
        return self.full_well_e / (self.max_code - self.black_level)

    @property
    def dtype(self) -> np.dtype:
        return np.dtype(np.uint8 if self.bit_depth == 8 else np.uint16)

    def params(self) -> dict:
        """Parameters as a plain dict (for provenance headers)."""
        return asdict(self)

    # -- noise prediction ---------------------------------------------------------------
    def pixel_sigma_dn(self, signal_e, exposure_s) -> np.ndarray:
        """Predicted standard deviation of one linear pixel in DN (module docstring).

        Parameters
        ----------
        signal_e : array_like
            Expected photoelectrons from the scene (rate × exposure), before clipping.
        exposure_s : array_like
            Exposure time, s (sets the dark-current electrons).
        """
        variance_e = (
            np.asarray(signal_e, float)
            + self.dark_current_e_per_s * np.asarray(exposure_s, float)
            + self.read_noise_e**2
        )
        variance_dn = variance_e / self.gain_e_per_dn**2
        # Rounding adds 1/12 DN² once the noise spans a code; a nearly noiseless signal
        # (a dark frame at 8 bits) rounds to a constant.  The factor is the leading
        # term of the rounding error's variance for Gaussian noise (Sheppard; the
        # neglected term oscillates with the mean's offset from a code).
        rounding = (1.0 - np.exp(-2.0 * np.pi**2 * variance_dn)) / 12.0
        return np.sqrt(variance_dn + rounding)

    # -- taking a frame -----------------------------------------------------------------
    def expose(self, rate_e_per_s, exposure_s: float, rng) -> np.ndarray:
        """Record one frame.

        Parameters
        ----------
        rate_e_per_s : array_like, shape (H, W, C)
            Expected photoelectron rate of every pixel (before vignetting).
        exposure_s : float
            Exposure time, s.
        rng : numpy.random.Generator

        Returns
        -------
        ndarray, shape (H, W, C), dtype uint8 or uint16
            Stored code values (sRGB-encoded when ``response == "srgb"``).
        """
        rate = np.asarray(rate_e_per_s, float)
        if rate.ndim != 3:
            raise KesbrdfError(f"expected a rate array of shape (H, W, C), got {rate.shape}")
        if self.vignetting:
            rate = rate * vignetting_map(rate.shape[0], rate.shape[1], self.vignetting)[..., None]
        expected_e = np.maximum(rate, 0.0) * exposure_s + self.dark_current_e_per_s * exposure_s
        electrons = rng.poisson(expected_e) + rng.normal(0.0, self.read_noise_e, size=expected_e.shape)
        electrons = np.minimum(electrons, self.full_well_e)
        dn = electrons / self.gain_e_per_dn + self.black_level
        if self.response == "srgb":
            dn = srgb_encode(dn / self.max_code) * self.max_code
        return np.clip(np.rint(dn), 0, self.max_code).astype(self.dtype)

    def expected_dn(self, signal_e) -> np.ndarray:
        """Noise-free linear DN above the black level for ``signal_e`` electrons."""
        return np.minimum(np.asarray(signal_e, float), self.full_well_e) / self.gain_e_per_dn

