"""Per-fabric numbers as opaque kernel parameters, so one compiled kernel serves many fabrics.

Dr.Jit traces a render into one kernel and compiles it with LLVM (a few seconds of CPU
for a studio scene).  A Python float or a ``mi.Color3f`` built from floats is a
*literal*: its value is part of the kernel's code, so a scene whose only change is the
fabric's body colour, lobe weight or table extent traces a different kernel and is
compiled again, where the compiled one could have been reused from Dr.Jit's kernel cache.
An *opaque* variable (``dr.opaque``) is a kernel parameter instead: the
batch's previews (one per fabric) and a colourway sheet (one body colour per tile) then
compile their scene once.  The values are the same single-precision numbers either way,
so the images are identical.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

__all__ = ["opaque_float", "opaque_rgb"]


def opaque_float(x: float):
    """``x`` as an opaque ``mi.Float`` (a kernel parameter, not a literal)."""
    return dr.opaque(mi.Float, float(x))


def opaque_rgb(rgb):
    """``(r, g, b)`` as an opaque ``mi.Color3f``."""
    c = mi.Color3f(*(float(v) for v in rgb))
    dr.make_opaque(c)
    return c
