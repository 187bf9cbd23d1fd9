"""Rendering kesbrdf models with Mitsuba 3 (install ``kesbrdf[render]``).

``import kesbrdf.render`` selects the ``llvm_ad_rgb`` variant when no variant is set
yet, and registers the BSDF plugins ``kesbrdf`` (:mod:`kesbrdf.render.bsdf`, kind ``kes``),
``kesbrdf_halfdiff`` (:mod:`~kesbrdf.render.halfdiff_bsdf`, kind ``kes-halfdiff``),
``kesbrdf_prior`` (:mod:`~kesbrdf.render.prior_bsdf`, kind ``fibre-prior``),
``kesbrdf_fibre_coord`` (:mod:`~kesbrdf.render.fibre_coord_bsdf`, kind ``fibre-coord``) and the
reference BSDFs (:mod:`~kesbrdf.render.reference_bsdf`).  Dr.Jit's
LLVM backend needs LLVM ≥ 17 (docs/architecture.md, "Tools it runs on"); when ``DRJIT_LIBLLVM_PATH`` is unset and
Debian's ``libllvm19`` is installed, it is pointed at that library.

Modules: :mod:`~kesbrdf.render.bsdf` (the plugin), :mod:`~kesbrdf.render.sampling`
(importance sampling), :mod:`~kesbrdf.render.scenes` (sphere, swatch, drape and dress
form scenes as Mitsuba scene dicts), :mod:`~kesbrdf.render.animation` (drape sequence
to MP4/GIF, resumable), :mod:`~kesbrdf.render.colourways` (contact sheet),
:mod:`~kesbrdf.render.studio` (soft boxes, procedural HDR room), :mod:`~kesbrdf.render.post`
(ACES tone curve, OIDN denoising).
"""

from __future__ import annotations

from kesbrdf._drjit import import_mitsuba

VARIANT = "llvm_ad_rgb"

mi, _ = import_mitsuba("kesbrdf.render")

if mi.variant() is None:
    mi.set_variant(VARIANT)
if not mi.variant().endswith("rgb"):  # pragma: no cover - user chose another variant
    raise ImportError(f"kesbrdf.render needs an RGB Mitsuba variant such as {VARIANT}, got {mi.variant()}")

from kesbrdf.render.bsdf import KesBSDF, register  # noqa: E402

register()

from kesbrdf.render import reference_bsdf as _reference_bsdf  # noqa: E402

_reference_bsdf.register()

from kesbrdf.render import halfdiff_bsdf as _halfdiff_bsdf  # noqa: E402

_halfdiff_bsdf.register()

from kesbrdf.render import prior_bsdf as _prior_bsdf  # noqa: E402

_prior_bsdf.register()

from kesbrdf.render import fibre_coord_bsdf as _fibre_coord_bsdf  # noqa: E402

_fibre_coord_bsdf.register()

__all__ = ["KesBSDF", "register", "VARIANT"]
