"""The embedded sample the demo runs on (no input needed).

Two forms, both simulated and labelled so in their headers:

* ``data/virtual_black_satin/``: camera frames + manifest of the Sadeghi et al. 2013
  satin, darkened like the paper's black satin, taken by the virtual camera in the
  paper's protocol (when the acquisition package is installed);
* ``data/satin_ward_paper.csv``: 116 samples of a satin-like anisotropic Ward BRDF
  through the virtual gonioreflectometer (always available).
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

__all__ = ["embedded_measurement", "embedded_manifest", "embedded_reference", "SATIN_WARD"]

#: Generator parameters of ``satin_ward_paper.csv`` (see scripts/make_embedded_sample.py).
SATIN_WARD = {"alpha_x": 0.08, "alpha_y": 0.22, "rho_d": [0.02, 0.02, 0.02], "rho_s": 0.12}


def _data() -> Path:
    return Path(str(resources.files("kesbrdf") / "data"))


def embedded_measurement() -> Path:
    """Path of the 116-sample simulated satin measurement CSV."""
    return _data() / "satin_ward_paper.csv"


def embedded_manifest() -> Path | None:
    """Manifest of the image-based virtual black satin, if shipped and ingest is available."""
    import importlib.util

    path = _data() / "virtual_black_satin" / "manifest.csv"
    try:
        import kesbrdf.measure.acquisition.ingest  # noqa: F401
    except ImportError:
        return None
    if importlib.util.find_spec("tifffile") is None:  # the frames are 16-bit TIFF
        return None
    return path if path.exists() else None


def embedded_reference():
    """The reference BRDF the embedded sample was simulated from (for validation)."""
    if embedded_manifest() is not None:
        try:
            from kesbrdf.references.sadeghi2013 import black_satin

            return black_satin()
        except ImportError:
            pass
    from kesbrdf.references.ward import AnisotropicWard

    return AnisotropicWard(**SATIN_WARD)
