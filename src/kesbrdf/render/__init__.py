"""Rendering kesbrdf models with Mitsuba 3 (install ``kesbrdf[render]``).

``import kesbrdf.render`` selects the ``llvm_ad_rgb`` variant when no variant is set
yet, and registers the BSDF plugin ``kesbrdf`` (:mod:`kesbrdf.render.bsdf`).  Dr.Jit's
LLVM backend needs LLVM ≥ 17 (DESIGN §7); when ``DRJIT_LIBLLVM_PATH`` is unset and
Debian's ``libllvm19`` is installed, it is pointed at that library.

Modules: :mod:`~kesbrdf.render.bsdf` (the plugin), :mod:`~kesbrdf.render.sampling`
(importance sampling), :mod:`~kesbrdf.render.scenes` (sphere, swatch, drape and dress
form scenes as Mitsuba scene dicts), :mod:`~kesbrdf.render.animation` (drape sequence
to MP4/GIF, resumable), :mod:`~kesbrdf.render.colourways` (contact sheet).
"""

from __future__ import annotations

import os
from pathlib import Path

VARIANT = "llvm_ad_rgb"
_LLVM_CANDIDATES = (
    "/usr/lib/x86_64-linux-gnu/libLLVM-19.so",
    "/usr/lib/aarch64-linux-gnu/libLLVM-19.so",
    "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1",
)

if not os.environ.get("DRJIT_LIBLLVM_PATH"):
    for _candidate in _LLVM_CANDIDATES:
        if Path(_candidate).exists():
            os.environ["DRJIT_LIBLLVM_PATH"] = _candidate
            break

try:
    import drjit  # noqa: F401
    import mitsuba as mi
except ImportError as exc:  # pragma: no cover - depends on the environment
    raise ImportError(
        f"kesbrdf.render needs mitsuba and drjit ({exc}); install kesbrdf[render]"
    ) from exc

if mi.variant() is None:
    mi.set_variant(VARIANT)
if not mi.variant().endswith("rgb"):  # pragma: no cover - user chose another variant
    raise ImportError(f"kesbrdf.render needs an RGB Mitsuba variant such as {VARIANT}, got {mi.variant()}")

from kesbrdf.render.bsdf import KesBSDF, register  # noqa: E402

register()

__all__ = ["KesBSDF", "register", "VARIANT"]
