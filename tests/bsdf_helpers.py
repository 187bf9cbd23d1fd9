"""Shared by the Mitsuba BSDF tests (tests/render): random direction pairs and a plain
``bsdf.eval`` call in the paper's convention."""

import numpy as np

from kesbrdf.geometry import spherical_to_cartesian


def random_pairs(rng, n=4000, min_cos=0.05):
    """(ω_i, ω_r), each (n, 3), uniform in cos θ above ``min_cos``, rounded to float32:
    the directions the plugin actually receives."""
    wi = spherical_to_cartesian(np.arccos(rng.uniform(min_cos, 1, n)), rng.uniform(0, 2 * np.pi, n))
    wr = spherical_to_cartesian(np.arccos(rng.uniform(min_cos, 1, n)), rng.uniform(0, 2 * np.pi, n))
    return wi.astype(np.float32).astype(float), wr.astype(np.float32).astype(float)


def eval_cos(bsdf, wi, wr):
    """Mitsuba eval (f·cos θ_i) with si.wi = viewer ω_r and wo = light ω_i; (N, 3)."""
    import drjit as dr
    import mitsuba as mi

    si = dr.zeros(mi.SurfaceInteraction3f, len(wi))
    si.wi = mi.Vector3f(*wr.T)
    return np.array(bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(*wi.T))).T


def eval_fr(bsdf, wi, wr):
    """f_r (N, 3): Mitsuba's eval with the cosine divided out."""
    return eval_cos(bsdf, wi, wr) / wi[:, 2:3]
