"""The embedded "virtual black satin" frames: present, small, ingestible, reproducible."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
from acq_helpers import exposures, predicted_sigma

from kesbrdf.measure.acquisition import embedded_manifest, ingest
from kesbrdf.measure.acquisition.manifest import read_manifest
from kesbrdf.measure.acquisition.sensor import Sensor

ROOT = Path(__file__).resolve().parents[2]
#: What may be committed for the embedded sample (issue: "keep the images small").
MAX_BYTES = 2 * 1024 * 1024
#: As in test_end_to_end: 4.5 predicted standard deviations.
Z_MAX = 4.5
N_ROI = 16 * 16  # 24-pixel frames, margin 3, inset 1


def test_embedded_manifest_has_the_paper_protocol():
    m = read_manifest(embedded_manifest())
    assert len(m.of_kind("sample")) == 4 * 29
    assert len(m.of_kind("white")) == 29
    assert m.header["simulated"] == "true" and "black satin" in m.header["sample"]
    folder = embedded_manifest().parent
    assert sum(p.stat().st_size for p in folder.iterdir()) < MAX_BYTES
    assert (folder / "README.md").is_file()


def test_embedded_frames_ingest_to_the_black_satin():
    from kesbrdf.references.sadeghi2013 import black_satin

    result = ingest(embedded_manifest())
    m = result.measurement
    assert result.counts()["rejected"] == 0 and set(m.provenance["flag"]) == {"ok"}
    reference = black_satin()(m.wi, m.wr)
    t_s, t_w = exposures(result)
    sigma = predicted_sigma(Sensor(), reference, m.theta_i, t_s, t_w, N_ROI)
    assert np.abs((m.values - reference) / sigma).max() < Z_MAX


def test_generator_script_reproduces_the_committed_frames():
    script = ROOT / "scripts" / "make_virtual_black_satin.py"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT / "src"), os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, str(script), "--check"], capture_output=True, text=True, env=env, timeout=120)
    # Fails when the reference BRDF, the camera or the sensor model changed since the
    # frames were made: regenerate them with the script (the README says how).
    assert done.returncode == 0, (
        "embedded frames are stale: run 'PYTHONPATH=src python scripts/make_virtual_black_satin.py'\n"
        + done.stdout
        + done.stderr
    )
