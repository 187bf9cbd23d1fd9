"""The one registry of reference BRDFs: names, defaults and constructors.

Every part of kesbrdf that builds a reference by name (``kesbrdf simulate``, ``plot``,
``report``, ``plan``, the reference-vs-model renders, the benchmarks) goes through
:func:`make_reference`, so a name means the same BRDF everywhere.

Names
-----
``ward``, ``satin-ward``, ``isotropic``
    Anisotropic Ward (:mod:`kesbrdf.references.ward`) with the defaults below.
``ashikhmin-shirley``
    :mod:`kesbrdf.references.ashikhmin_shirley`.
``ggx``
    Anisotropic GGX microfacet lobe over a Lambertian body
    (:mod:`kesbrdf.references.ggx`), a non-fibre control.
``sadeghi-<preset>``
    Sadeghi et al. 2013 microcylinder presets (Table II), and ``sadeghi-black-satin``,
    the embedded demo fabric (:func:`kesbrdf.references.sadeghi2013.black_satin`).
``irawan-<preset>``
    Irawan & Marschner 2012 far-field woven cloth, the six weaves of Irawan's data
    (:data:`kesbrdf.references.irawan2012.PRESET_NAMES`, ``_`` written ``-``:
    ``irawan-cotton-denim``, ``irawan-silk-charmeuse``, ...); numpy only, not rendered
    by the ``kesbrdf_reference`` plugin (:data:`RENDERABLE_REFERENCES`).
``rgl-felt-<colour>``
    RGL-EPFL measured felts read through Mitsuba's ``measured`` plugin; the white felt
    ships with the package (CC0), the others are found through ``$KESBRDF_RGL_DIR``.
A path
    Any RGL tensor file (``.bsdf``) or MERL ``.binary``
    (:func:`kesbrdf.io.sources.reference_from_file`, numpy readers, recognised by
    content).  ``--params`` as for ``rgl-felt-*`` (``parameterised_by``) or none (MERL).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from kesbrdf.errors import KesbrdfError, validate_choice
from kesbrdf.references.params import parse_params

__all__ = ["REFERENCES", "ANALYTIC_REFERENCES", "IRAWAN_REFERENCES", "RENDERABLE_REFERENCES", "RGL_FILES", "RGL_DIRS",
           "SHIPPED_RGL_DIR", "make_reference", "rgl_path",
           "is_reference_path"]

_SADEGHI_PRESETS = ("linen", "silk_crepe", "satin", "satin_back", "silk_shot", "velvet")

#: RGL measured materials by name: file name under a search directory.
RGL_FILES = {
    "rgl-felt-white": "acrylic_felt_white_rgb.bsdf",
    "rgl-felt-pink": "acrylic_felt_pink_rgb.bsdf",
    "rgl-felt-purple": "acrylic_felt_purple_rgb.bsdf",
}
#: The RGL files that ship inside the package (the white felt, CC0; its README there).
SHIPPED_RGL_DIR = Path(__file__).resolve().parents[1] / "data" / "rgl"
#: Where RGL files are looked for: ``$KESBRDF_RGL_DIR`` when set, then the package's own.
RGL_DIRS = tuple(Path(p) for p in (os.environ.get("KESBRDF_RGL_DIR", ""), str(SHIPPED_RGL_DIR)) if p)

#: References that need no data file and no renderer (numpy only).
ANALYTIC_REFERENCES = (
    ("ward", "satin-ward", "isotropic", "ashikhmin-shirley", "ggx", "sadeghi-satin", "sadeghi-black-satin")
    + tuple(f"sadeghi-{p.replace('_', '-')}" for p in _SADEGHI_PRESETS if p != "satin")
)
#: The Irawan–Marschner woven-cloth presets by name (numpy only; the same weaves as the
#: fabric library's ``irawan2012`` family, at their preset parameters).
IRAWAN_PRESETS = ("cotton_denim", "silk_shantung", "silk_charmeuse", "cotton_twill", "wool_gabardine", "polyester_lining")
IRAWAN_REFERENCES = tuple(f"irawan-{p.replace('_', '-')}" for p in IRAWAN_PRESETS)
#: Every reference name, in the order the CLI lists them.
REFERENCES = ANALYTIC_REFERENCES + IRAWAN_REFERENCES + tuple(RGL_FILES)
#: The references the Mitsuba ``kesbrdf_reference`` plugin (or ``measured``) can render.
RENDERABLE_REFERENCES = tuple(r for r in REFERENCES if r not in IRAWAN_REFERENCES)


def rgl_path(name: str) -> Path:
    """The tensor file of an RGL reference name; KesbrdfError when it is not available."""
    for d in RGL_DIRS:
        p = d / RGL_FILES[name]
        if p.is_file():
            return p
    raise KesbrdfError(
        f"reference {name!r}: expected {RGL_FILES[name]} in {', '.join(str(d) for d in RGL_DIRS)} "
        "(set KESBRDF_RGL_DIR to the folder holding it, or give the file's path as the reference), found none"
    )


#: Endings that make a reference name a file path even when the file is missing (so the
#: error is "no such file", not "unknown reference").
FILE_ENDINGS = (".bsdf", ".binary")


def is_reference_path(name) -> bool:
    """True when ``name`` is meant as a file (not a built-in name): a path separator, a
    table ending (:data:`FILE_ENDINGS`), or an existing file."""
    text = str(name)
    if text in REFERENCES:
        return False
    return os.sep in text or "/" in text or text.lower().endswith(FILE_ENDINGS) or Path(text).is_file()


def _reference_from_path(path: str, params, flag: str):
    from kesbrdf.io.sources import detect, reference_from_file

    kind = detect(path)  # FileNotFoundError / one-line FormatError
    spec_name = {"rgl-bsdf": "rgl-file", "merl-binary": "merl-file"}.get(kind)
    if spec_name is None:
        raise KesbrdfError(
            f"reference {path}: expected a built-in name ({', '.join(REFERENCES)}) or an RGL .bsdf / "
            f"MERL .binary file, got a {kind} file (fit or convert reads measurements)"
        )
    extra = parse_params(spec_name, params, flag)
    return reference_from_file(path, parameterised_by=extra.get("parameterised_by", "viewer"))


def make_reference(name: str, params=None, flag: str = "--params"):
    """Build the reference BRDF ``name`` (callable ``f(wi, wr) -> (..., C)``).

    Parameters
    ----------
    name : str
        One of :data:`REFERENCES`, or the path of an RGL ``.bsdf`` / MERL ``.binary`` file
        (:func:`is_reference_path`); anything else is a one-line error listing the names.
    params : dict, JSON text or None
        Overrides of the defaults, checked against the reference's parameters
        (:mod:`kesbrdf.references.params`).
    flag : str
        The option the parameters came from, for error messages.
    """
    if isinstance(params, dict):
        params = json.dumps(params) if params else None
    if is_reference_path(name):
        return _reference_from_path(str(name), params, flag)
    validate_choice("reference", name, REFERENCES)
    extra = parse_params(name, params, flag)
    try:
        return _build(name, extra)
    except KesbrdfError:
        raise
    except (TypeError, ValueError) as exc:  # a combination the per-parameter checks cannot see
        raise KesbrdfError(f"{flag} for reference {name}: {' '.join(str(exc).split())}") from None


def _build(name: str, extra: dict):
    if name in ("ward", "satin-ward", "isotropic"):
        from kesbrdf.references.ward import AnisotropicWard

        defaults = {
            "ward": {"alpha_x": 0.12, "alpha_y": 0.3, "rho_d": [0.25, 0.2, 0.15], "rho_s": 0.15},
            # satin-like: narrow across the warp floats' highlight direction, long along it
            "satin-ward": {"alpha_x": 0.08, "alpha_y": 0.22, "rho_d": [0.02, 0.02, 0.02], "rho_s": 0.12},
            "isotropic": {"alpha_x": 0.2, "alpha_y": 0.2, "rho_d": [0.3, 0.3, 0.3], "rho_s": 0.1},
        }[name]
        return AnisotropicWard(**{**defaults, **extra})
    if name == "ashikhmin-shirley":
        from kesbrdf.references.ashikhmin_shirley import AshikhminShirley

        return AshikhminShirley(**{"n_u": 50.0, "n_v": 400.0, "R_s": 0.1, "R_d": [0.3, 0.25, 0.2], **extra})
    if name == "ggx":
        from kesbrdf.references.ggx import AnisotropicGGX

        return AnisotropicGGX(**{"alpha_x": 0.15, "alpha_y": 0.35, "eta": 1.5, "rho_d": [0.3, 0.22, 0.15],
                                 "k_s": 1.0, **extra})
    if name == "sadeghi-black-satin":
        from kesbrdf.references import sadeghi2013

        return sadeghi2013.black_satin(**extra)
    if name.startswith("sadeghi-"):
        from kesbrdf.references.sadeghi2013 import Sadeghi2013

        return Sadeghi2013(preset=name[len("sadeghi-"):].replace("-", "_"), **extra)
    if name in IRAWAN_REFERENCES:
        from kesbrdf.references.irawan2012 import Irawan2012

        return Irawan2012(name[len("irawan-"):].replace("-", "_"), **extra)
    if name in RGL_FILES:
        from kesbrdf.references.rgl import RGLMeasured

        return RGLMeasured(rgl_path(name), parameterised_by=extra.get("parameterised_by", "viewer"))
    raise RuntimeError(f"reference {name!r} is listed in REFERENCES but has no constructor")
