"""Goniometric reflectance samples: the input of every kesbrdf model.

A :class:`Measurement` holds N samples of C channels.  Each sample is a pair of
directions in the fabric frame (x = warp, y = weft, z = normal) and its BRDF value
f_r in 1/sr.  Samples taken in the paper's in-plane protocol also carry ``psi``, the
angle between the plane of incidence and the warp (docs/method.md, "The paper's steps" and "Conventions"); general samples
have ``psi = NaN``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from kesbrdf.errors import MeasurementError
from kesbrdf.geometry import spherical_to_cartesian

__all__ = ["Measurement", "PAPER_ORIENTATIONS", "PAPER_ORIENTATIONS_DEG"]

#: The paper's four orientations ψ (warp, bias, weft, other bias), degrees (file and CLI edge).
PAPER_ORIENTATIONS_DEG = (0.0, 45.0, 90.0, 135.0)

#: The same orientations in radians.
PAPER_ORIENTATIONS = np.radians(PAPER_ORIENTATIONS_DEG)


@dataclass
class Measurement:
    """Reflectance samples in the fabric frame.

    Attributes
    ----------
    theta_i, phi_i, theta_r, phi_r : ndarray, shape (N,)
        Light and viewer directions, radians.
    values : ndarray, shape (N, C)
        f_r in 1/sr (converted from the file's quantity at the reader).
    channels : tuple of str
        Channel names, e.g. ``("value",)`` or ``("R", "G", "B")``.
    uncertainty : ndarray (N, C) or None
        One standard deviation of ``values``, 1/sr.
    psi : ndarray (N,) or None
        In-plane orientation, radians in [0, π); NaN for general samples.
    metadata : dict
        ``# key: value`` header lines (sample, instrument, quantity, ...).
    provenance : dict of str -> list of str
        Optional per-row text columns (file, file_sha256, flag).
    source, sha256 : str or None
        Input file and the SHA-256 of its bytes.
    notes : list of str
        Warnings the reader found (e.g. negative values from dark noise).
    """

    theta_i: np.ndarray
    phi_i: np.ndarray
    theta_r: np.ndarray
    phi_r: np.ndarray
    values: np.ndarray
    channels: tuple[str, ...] = ("value",)
    uncertainty: np.ndarray | None = None
    psi: np.ndarray | None = None
    metadata: dict = field(default_factory=dict)
    provenance: dict = field(default_factory=dict)
    source: str | None = None
    sha256: str | None = None
    notes: list = field(default_factory=list)

    def __post_init__(self) -> None:
        for name in ("theta_i", "phi_i", "theta_r", "phi_r"):
            setattr(self, name, np.asarray(getattr(self, name), float).reshape(-1))
        n = self.theta_i.size
        values = np.asarray(self.values, float)
        if values.ndim == 1:
            values = values[:, None]
        self.values = values
        self.channels = tuple(self.channels)
        if values.shape != (n, len(self.channels)):
            raise MeasurementError(
                f"expected values of shape ({n}, {len(self.channels)}) for channels "
                f"{self.channels}, got {values.shape}"
            )
        if self.uncertainty is not None:
            unc = np.asarray(self.uncertainty, float)
            if unc.ndim == 1:
                unc = unc[:, None]
            if unc.shape != values.shape:
                raise MeasurementError(
                    f"expected uncertainty of shape {values.shape}, got {unc.shape}"
                )
            self.uncertainty = unc
        if self.psi is not None:
            self.psi = np.asarray(self.psi, float).reshape(-1)
            if self.psi.size != n:
                raise MeasurementError(f"expected {n} psi values, got {self.psi.size}")

    # -- construction -------------------------------------------------------------
    @classmethod
    def in_plane(
        cls,
        psi,
        theta_i,
        theta_r,
        values,
        channels=("value",),
        uncertainty=None,
        metadata=None,
        **kwargs,
    ) -> "Measurement":
        """Samples in the paper's protocol: light at azimuth ψ + π, viewer at ψ."""
        psi, theta_i, theta_r = np.broadcast_arrays(
            np.asarray(psi, float), np.asarray(theta_i, float), np.asarray(theta_r, float)
        )
        return cls(
            theta_i=theta_i,
            phi_i=np.mod(psi + np.pi, 2 * np.pi),
            theta_r=theta_r,
            phi_r=np.mod(psi, 2 * np.pi),
            values=values,
            channels=channels,
            uncertainty=uncertainty,
            psi=psi,
            metadata=dict(metadata or {}),
            **kwargs,
        )

    # -- views --------------------------------------------------------------------
    def __len__(self) -> int:
        return self.theta_i.size

    @property
    def n_channels(self) -> int:
        return len(self.channels)

    @property
    def wi(self) -> np.ndarray:
        """Light directions, (N, 3)."""
        return spherical_to_cartesian(self.theta_i, self.phi_i)

    @property
    def wr(self) -> np.ndarray:
        """Viewer directions, (N, 3)."""
        return spherical_to_cartesian(self.theta_r, self.phi_r)

    @property
    def is_in_plane(self) -> np.ndarray:
        """Boolean (N,): rows that carry an in-plane orientation ψ."""
        if self.psi is None:
            return np.zeros(len(self), bool)
        return np.isfinite(self.psi)

    @property
    def gamma(self) -> np.ndarray:
        """Signed deviation from the mirror direction γ = θ_r − θ_i (in-plane rows)."""
        return self.theta_r - self.theta_i

    @property
    def q(self) -> np.ndarray:
        """The KES quantity q = f_r·√(cos θ_i cos θ_r) (paper eq. 3), shape (N, C)."""
        return self.values * np.sqrt(np.cos(self.theta_i) * np.cos(self.theta_r))[:, None]

    def orientations(self, decimals: int = 6) -> np.ndarray:
        """The distinct in-plane orientations ψ present, radians, sorted."""
        if self.psi is None or not np.any(self.is_in_plane):
            return np.empty(0)
        return np.unique(np.round(self.psi[self.is_in_plane], decimals))

    def input_info(self) -> dict:
        """What a model records of its input: file, SHA-256, sample, quantity."""
        return {
            "name": self.source,
            "sha256": self.sha256,
            "sample": self.metadata.get("sample"),
            "quantity": self.metadata.get("quantity", "brdf"),
            "simulated": self.metadata.get("simulated"),
            "n_samples": len(self),
        }

    def subset(self, mask) -> "Measurement":
        """A new measurement holding only the rows where ``mask`` is true."""
        mask = np.asarray(mask)
        return Measurement(
            theta_i=self.theta_i[mask],
            phi_i=self.phi_i[mask],
            theta_r=self.theta_r[mask],
            phi_r=self.phi_r[mask],
            values=self.values[mask],
            channels=self.channels,
            uncertainty=None if self.uncertainty is None else self.uncertainty[mask],
            psi=None if self.psi is None else self.psi[mask],
            metadata=dict(self.metadata),
            provenance={k: list(np.asarray(v, dtype=object)[mask]) for k, v in self.provenance.items()},
            source=self.source,
            sha256=self.sha256,
            notes=list(self.notes),
        )
