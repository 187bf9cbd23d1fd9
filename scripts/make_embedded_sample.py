"""Regenerate src/kesbrdf/data/satin_ward_paper.csv (deterministic).

116 samples (paper protocol: psi = 0, 45, 90, 135 deg; theta_i = 90 - 3k, theta_r = 3k,
k = 1..29) of a satin-like anisotropic Ward BRDF (kesbrdf.measure.demo_data.SATIN_WARD) with 1 %
relative noise plus an absolute floor of 2e-4 1/sr, seed 2026.  SIMULATED data.
"""

from pathlib import Path

from kesbrdf.measure.demo_data import SATIN_WARD
from kesbrdf.measure.gonio import measure
from kesbrdf.io.measurement_csv import write_measurement
from kesbrdf.references.ward import AnisotropicWard

ROOT = Path(__file__).resolve().parents[1]

if __name__ == "__main__":
    m = measure(AnisotropicWard(**SATIN_WARD), noise=0.01, noise_floor=2e-4, rng=2026,
                sample="simulated satin-like anisotropic Ward (NOT a real fabric)")
    write_measurement(ROOT / "src/kesbrdf/data/satin_ward_paper.csv", m)
    print(len(m), "samples")
