"""Image-based acquisition: from gonioreflectometer photographs to a measurement.

* :mod:`~kesbrdf.measure.acquisition.manifest`: the manifest of frames (file, kind, geometry,
  exposure, ROI) and its validation.
* :mod:`~kesbrdf.measure.acquisition.images`: reading 8/16-bit PNG/TIFF and OpenEXR frames
  (needs ``kesbrdf[images]``), linearisation.
* :mod:`~kesbrdf.measure.acquisition.sensor`: the camera sensor model (photon and read noise,
  clipping, vignetting, 8/16-bit quantisation).
* :mod:`~kesbrdf.measure.acquisition.camera`: :func:`simulate_images`, a virtual
  gonioreflectometer that writes frames and a manifest for any reference BRDF.
* :mod:`~kesbrdf.measure.acquisition.ingest`: :func:`ingest`, frames -> calibrated f_r with
  uncertainty and provenance.

The embedded default sample, "virtual black satin" (simulated), is found with
:func:`embedded_manifest`.
"""

from __future__ import annotations

from pathlib import Path

# The functions shadow their submodules' names on purpose: ``kesbrdf.measure.acquisition.ingest``
# is the function; the module stays importable as ``kesbrdf.measure.acquisition.ingest``.
# Imaging libraries are imported only when a frame is read or written.
from kesbrdf.measure.acquisition.camera import simulate_images
from kesbrdf.measure.acquisition.ingest import ingest

__all__ = ["ingest", "simulate_images", "embedded_manifest", "EMBEDDED_SAMPLE"]

#: Folder name of the embedded sample under ``kesbrdf/data``.
EMBEDDED_SAMPLE = "virtual_black_satin"


def embedded_manifest() -> Path:
    """Path of the embedded "virtual black satin" manifest (simulated frames).

    The frames are the Sadeghi et al. (2013) satin preset darkened like the paper's
    black satin, photographed by :func:`simulate_images` under the paper's protocol;
    ``scripts/make_virtual_black_satin.py`` regenerates them bit for bit.
    """
    path = Path(__file__).resolve().parents[2] / "data" / EMBEDDED_SAMPLE / "manifest.csv"
    if not path.is_file():
        raise FileNotFoundError(2, "embedded sample missing (run scripts/make_virtual_black_satin.py)", str(path))
    return path
