"""A virtual gonioreflectometer: apply a measurement protocol to any BRDF callable.

Protocols
---------
``paper``
    The paper's STEP 1 (docs/method.md, "The paper's steps"): ψ = 0, 45, 90, 135°, θ_i = 90° − k·step,
    θ_r = k·step for k = 1 … 90/step − 1 (29 per orientation at 3°: 116 samples).
``dense``
    Every (θ_i, θ_r) pair on a grid of ``step_deg`` from 0 to below 90° at each
    orientation (at 6°: 15 × 15 × 4 = 900 samples).

Noise model: each value gets Gaussian noise of standard deviation
``noise * |f| + noise_floor`` (relative plus absolute, 1/sr), and the returned
uncertainty is that standard deviation.  Values can go negative, as dark noise does.
"""

from __future__ import annotations

import json
import math

import numpy as np

from kesbrdf.errors import KesbrdfError, validate_choice
from kesbrdf.geometry import in_plane_directions, spherical_to_cartesian
from kesbrdf.measure.measurement import PAPER_ORIENTATIONS_DEG, Measurement

__all__ = ["PROTOCOLS", "protocol_geometry", "measure", "measure_samples"]

PROTOCOLS = ("paper", "dense")

#: Finest angle step accepted (degrees): the dense protocol at 0.5° is already
#: 4 × 180² = 129,600 rows; finer steps grow as 1/step² without adding information
#: a gonioreflectometer of ~1° angular resolution could have.
MIN_STEP_DEG = 0.5

#: Most orientations ψ accepted in one simulated measurement.
MAX_ORIENTATIONS = 360


def protocol_geometry(protocol: str = "paper", step_deg: float | None = None, orientations_deg=PAPER_ORIENTATIONS_DEG):
    """(ψ, θ_i, θ_r) arrays in radians for a protocol (module docstring)."""
    validate_choice("protocol", protocol, PROTOCOLS)
    if step_deg is None:
        step_deg = 3.0 if protocol == "paper" else 6.0
    ok = isinstance(step_deg, (int, float, np.number)) and math.isfinite(step_deg)
    if not ok or not (MIN_STEP_DEG <= step_deg < 45) or abs(90.0 / step_deg - round(90.0 / step_deg)) > 1e-9:
        raise KesbrdfError(
            f"step_deg: expected a step that divides 90 deg, at least {MIN_STEP_DEG:g} (e.g. 3 or 6), got {step_deg!r}"
        )
    n = int(round(90.0 / step_deg))
    try:
        psi_deg = np.asarray(orientations_deg, float).reshape(-1)
    except (TypeError, ValueError):
        raise KesbrdfError(f"orientations_deg: expected a list of degrees, got {orientations_deg!r}") from None
    bad = ~np.isfinite(psi_deg) | (psi_deg < 0) | (psi_deg >= 180)
    if not 1 <= psi_deg.size <= MAX_ORIENTATIONS or bad.any():
        raise KesbrdfError(
            f"orientations_deg: expected 1 to {MAX_ORIENTATIONS} orientations psi in [0, 180) degrees, "
            f"got {', '.join(f'{v:g}' for v in psi_deg[:8])}{' ...' if psi_deg.size > 8 else ''}"
        )
    if np.unique(psi_deg).size != psi_deg.size:
        raise KesbrdfError(f"orientations_deg: expected distinct orientations, got {', '.join(f'{v:g}' for v in psi_deg)}")
    if protocol == "paper":
        k = np.arange(1, n)
        ti, tr = 90.0 - step_deg * k, step_deg * k
    else:
        grid = step_deg * np.arange(n)
        ti, tr = (a.ravel() for a in np.meshgrid(grid, grid, indexing="ij"))
    psi = np.repeat(psi_deg, ti.size)
    return np.radians(psi), np.radians(np.tile(ti, psi_deg.size)), np.radians(np.tile(tr, psi_deg.size))


def measure(
    brdf,
    protocol: str = "paper",
    step_deg: float | None = None,
    noise: float = 0.0,
    noise_floor: float = 0.0,
    rng=None,
    orientations_deg=PAPER_ORIENTATIONS_DEG,
    sample: str | None = None,
) -> Measurement:
    """Measure ``brdf`` (callable f(wi, wr) -> (..., C)) in a protocol.

    Returns
    -------
    Measurement
        Labelled ``simulated: true`` with the generator's parameters.
    """
    _check_noise(noise, noise_floor)
    psi, theta_i, theta_r = protocol_geometry(protocol, step_deg, orientations_deg)
    wi, wr = in_plane_directions(psi, theta_i, theta_r)
    values, uncertainty, channels = _read_values(brdf, wi, wr, noise, noise_floor, rng)
    metadata = _metadata(brdf, sample, {"protocol": protocol, "step_deg": step_deg, "noise": noise,
                                        "noise_floor": noise_floor})
    return Measurement.in_plane(psi, theta_i, theta_r, values, channels=channels, uncertainty=uncertainty, metadata=metadata)


def measure_samples(brdf, geometry, noise: float = 0.0, noise_floor: float = 0.0, rng=None,
                    sample: str | None = None, generator: dict | None = None) -> Measurement:
    """Measure ``brdf`` at given sample geometries, with the noise model of :func:`measure`.

    ``geometry`` has ``theta_i, phi_i, theta_r, phi_r, psi`` arrays in radians (ψ NaN
    out of the plane of incidence), e.g. a :class:`kesbrdf.measure.planning.Geometry` of
    a plan's samples or of a protocol with extra groups (``kesbrdf simulate --plan`` /
    ``--extras``).  ``generator`` is recorded beside the reference's parameters.
    """
    _check_noise(noise, noise_floor)
    g = geometry
    wi = spherical_to_cartesian(g.theta_i, g.phi_i)
    wr = spherical_to_cartesian(g.theta_r, g.phi_r)
    values, uncertainty, channels = _read_values(brdf, wi, wr, noise, noise_floor, rng)
    metadata = _metadata(brdf, sample, {**(generator or {}), "noise": noise, "noise_floor": noise_floor})
    return Measurement(theta_i=g.theta_i, phi_i=g.phi_i, theta_r=g.theta_r, phi_r=g.phi_r, values=values,
                       channels=channels, uncertainty=uncertainty, psi=g.psi, metadata=metadata)


def _check_noise(noise, noise_floor) -> None:
    for name, value in (("noise", noise), ("noise_floor", noise_floor)):
        if not (isinstance(value, (int, float, np.number)) and math.isfinite(value) and value >= 0):
            raise KesbrdfError(f"{name}: expected a finite number >= 0, got {value!r}")


def _read_values(brdf, wi, wr, noise, noise_floor, rng):
    """(values, uncertainty or None, channels) of ``brdf`` at (wi, wr) with the module's noise model."""
    values = np.asarray(brdf(wi, wr), float)
    if values.ndim == 1:
        values = values[:, None]
    channels = tuple(getattr(brdf, "channels", ("value",) if values.shape[1] == 1 else tuple(f"band_{k}" for k in range(values.shape[1]))))
    sigma = noise * np.abs(values) + noise_floor
    if noise > 0 or noise_floor > 0:
        rng = np.random.default_rng(rng)
        values = values + rng.normal(size=values.shape) * sigma
        uncertainty = sigma
    else:
        uncertainty = None
    return values, uncertainty, channels


def _metadata(brdf, sample, how: dict) -> dict:
    params = brdf.params() if hasattr(brdf, "params") else {"reference": type(brdf).__name__}
    generator = {**params, **how}
    return {
        "sample": sample or f"simulated {params.get('reference', 'reference')}",
        "instrument": "kesbrdf virtual gonioreflectometer",
        "quantity": "brdf",
        "simulated": "true",
        "generator": json.dumps(generator, sort_keys=True),
    }
