"""The protocol options shared by commands that sample a BRDF at gonio geometries.

``kesbrdf simulate`` measures a reference, ``kesbrdf convert`` and ``kesbrdf fit``
sample a BRDF table (RGL ``.bsdf``, MERL ``.binary``); all three go through
:func:`kesbrdf.measure.gonio.measure` with the same ``--protocol``, ``--step-deg`` and
``--orientations-deg``.
"""

from __future__ import annotations

from kesbrdf.measure.measurement import PAPER_ORIENTATIONS_DEG

PAPER_ORIENTATIONS_TEXT = ",".join(f"{v:g}" for v in PAPER_ORIENTATIONS_DEG)


def add_protocol_arguments(p, default: str | None = "paper", what: str = "") -> None:
    """Declare ``--protocol``, ``--step-deg`` and ``--orientations-deg``.

    ``default=None`` leaves all three unset unless given (``fit``/``convert``: they apply
    to BRDF tables only, and giving one for a measurement is an error).
    """
    suffix = f" {what}" if what else ""
    p.add_argument("--protocol", default=default, choices=("paper", "dense"),
                   help=f"gonio geometries{suffix}: paper (one incidence line per orientation) or dense"
                   + ("" if default is None else f" (default {default})"))
    p.add_argument("--step-deg", type=float, default=None, help="angle step (paper: 3, dense: 6)")
    p.add_argument("--orientations-deg", default=PAPER_ORIENTATIONS_TEXT if default is not None else None,
                   help=f"comma-separated ψ values (default: the paper's {PAPER_ORIENTATIONS_TEXT})")


def orientations(text: str | None):
    """``"0,45,90,135"`` -> ``(0.0, 45.0, 90.0, 135.0)``; None stays None (the default applies)."""
    from kesbrdf.errors import KesbrdfError

    if text is None:
        return None
    try:
        return tuple(float(x) for x in text.split(","))
    except ValueError:
        raise KesbrdfError(f"--orientations-deg: expected comma-separated degrees, got {text!r}") from None
