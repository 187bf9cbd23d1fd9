"""Import Mitsuba 3 / Dr.Jit with an LLVM that works (docs/architecture.md, "Tools it runs on").

Dr.Jit's LLVM backend needs LLVM ≥ 17 (15 and 16 crash mid-render).  When
``DRJIT_LIBLLVM_PATH`` is unset (or empty) and Debian's ``libllvm19`` is installed, it is
pointed at that library before the first import.
"""

from __future__ import annotations

import os
from pathlib import Path

LLVM_CANDIDATES = (
    "/usr/lib/x86_64-linux-gnu/libLLVM-19.so",
    "/usr/lib/aarch64-linux-gnu/libLLVM-19.so",
    "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1",
)


def import_mitsuba(who: str):
    """Return ``(mitsuba, drjit)``; ``who`` names the caller in the ImportError."""
    if not os.environ.get("DRJIT_LIBLLVM_PATH"):
        for candidate in LLVM_CANDIDATES:
            if Path(candidate).exists():
                os.environ["DRJIT_LIBLLVM_PATH"] = candidate
                break
    try:
        import drjit as dr
        import mitsuba as mi
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError(f"{who} needs mitsuba and drjit ({exc}); install kesbrdf[render]") from exc
    return mi, dr


def load_dict(spec: dict):
    """``mitsuba.load_dict(spec)`` in one thread and unmerged, so a scene renders the same twice.

    By default Mitsuba loads a dict's children on several threads and merges identical
    objects through a hash map; both change the order of ``scene.shapes()`` and
    ``scene.emitters()`` from one load to the next.  Light sampling picks an emitter by that
    index, so the same scene with the same seed gave a different noise pattern each time it
    was loaded (the studio's four soft boxes: a colourway test's ratio moved by ±30 % between
    runs, and a render and its lobe-off twin did not share their random numbers).  With
    ``parallel=False, optimize=False`` the order is the dict's; the scenes here are a few
    shapes, so neither option bought anything.
    """
    import mitsuba as mi

    return mi.load_dict(spec, parallel=False, optimize=False)
