"""Original-format files of the public databases, written by tests into tmp_path.

Users and CI do not have the databases, so tests rebuild them:

* CUReT ``table.txt`` + ``abrdf.dat`` from the committed extract
  ``tests/data/curet_fabrics.csv`` (tests/data/README.md), in CUReT's own layout;
* a full-size MERL ``.binary`` (90 × 90 × 180 float64 × 3, 35 MB) of a known analytic
  BRDF, each bin holding the BRDF at the bin centre.
"""

from pathlib import Path

import numpy as np

from kesbrdf.references.registry import SHIPPED_RGL_DIR

DATA = Path(__file__).resolve().parent / "data"
CURET_EXTRACT = DATA / "curet_fabrics.csv"
RGL_FELT = SHIPPED_RGL_DIR / "acrylic_felt_white_rgb.bsdf"


def write_curet(folder, extract=None, samples=(1, 42), negative_at=None):
    """``table.txt`` and ``abrdf.dat`` in CUReT's layout (six decimals of radians, azimuths
    in (−π, π], three decimals of values), from the extract; returns their paths."""
    from kesbrdf.io.measurement_csv import read_measurement

    folder = Path(folder)
    extract = read_measurement(CURET_EXTRACT) if extract is None else extract
    th_v, ph_v = extract.theta_r, extract.phi_r
    th_i, ph_i = extract.theta_i, extract.phi_i
    wrap = lambda p: np.where(p > np.pi, p - 2 * np.pi, p)  # noqa: E731
    lines = [
        f"{k + 1}     {th_v[k]:.6f}   {wrap(ph_v[k]):.6f}   {th_i[k]:.6f}   {wrap(ph_i[k]):.6f}"
        for k in range(len(extract))
    ]
    (folder / "table.txt").write_text("\n".join(lines) + "\n")
    rows = []
    for s in samples:
        col = [c for c in extract.channels if c.startswith(f"band_s{s:02d}_")][0]
        v = extract.values[:, extract.channels.index(col)].copy()
        if negative_at is not None and s == samples[0]:
            v[negative_at] = -0.016
        rows.append(f"{s}    " + "   ".join(f"{x:.3f}" for x in v))
    (folder / "abrdf.dat").write_text("\n".join(rows) + "\n")
    return folder / "table.txt", folder / "abrdf.dat"


def merl_bin_centres():
    """(θ_h, θ_d, φ_d) at every bin centre, each (90, 90, 180), inverting the bin mapping."""
    from kesbrdf.references.merl import DIMS

    i = (np.arange(DIMS[0]) + 0.5) / DIMS[0]
    j = (np.arange(DIMS[1]) + 0.5) / DIMS[1]
    k = (np.arange(DIMS[2]) + 0.5) / DIMS[2]
    return np.meshgrid(i**2 * np.pi / 2, j * np.pi / 2, k * np.pi, indexing="ij")


def pairs_from_half_diff(theta_h, theta_d, phi_d):
    """ω_i, ω_r (n, 3) with φ_h = 0: ω_i = R_y(θ_h) d, ω_r = reflect(ω_i, h)."""
    th, td, pd = (np.ravel(a) for a in (theta_h, theta_d, phi_d))
    d = np.stack([np.sin(td) * np.cos(pd), np.sin(td) * np.sin(pd), np.cos(td)], -1)
    c, s = np.cos(th), np.sin(th)
    wi = np.stack([c * d[:, 0] + s * d[:, 2], d[:, 1], -s * d[:, 0] + c * d[:, 2]], -1)
    h = np.stack([s, np.zeros_like(s), c], -1)
    wr = 2 * np.sum(wi * h, -1, keepdims=True) * h - wi
    return wi, wr


def write_merl(path, brdf):
    """A MERL ``.binary`` of the isotropic ``brdf`` (f(wi, wr) -> (n, 3)) at the bin centres;
    bins with a direction below the horizon are marked missing (−1), as in the database.
    Returns the share of missing bins."""
    from kesbrdf.references.merl import DIMS, SCALE

    wi, wr = pairs_from_half_diff(*merl_bin_centres())
    values = np.asarray(brdf(wi, wr), float) / SCALE
    below = (wi[:, 2] <= 0) | (wr[:, 2] <= 0)
    values[below] = -1.0
    Path(path).write_bytes(np.array(DIMS, "<i4").tobytes() + np.ascontiguousarray(values.T, "<f8").tobytes())
    return float(below.mean())
