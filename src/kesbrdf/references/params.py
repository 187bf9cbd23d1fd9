"""Reference parameters given as JSON (``simulate --params``), checked before building.

Each reference of :data:`kesbrdf.references.registry.REFERENCES` declares the parameters a
user may set, with their type and range (:data:`PARAMETERS`).  Unknown names, wrong
JSON types, non-finite numbers and out-of-range values are refused with one line
naming the parameter, the expected type/range and what arrived, before any
reference is built.
"""

from __future__ import annotations

import json
import math

from kesbrdf.errors import KesbrdfError, validate_choice

__all__ = ["PARAMETERS", "parse_params"]

#: Most channels a per-channel parameter (rho_d, R_d, ...) may list.
MAX_CHANNELS = 64


def _number(lo, hi, lo_open=False):
    return ("number", lo, hi, lo_open)


def _channels(lo, hi):
    return ("channels", lo, hi, False)


#: Smallest lobe width accepted (Ward alpha, Sadeghi sigma_u, radians): below it the
#: lobe's 1/alpha^2 overflows in double precision (alpha = 1e-301 evaluated to NaN).
MIN_WIDTH = 1e-4

_WARD = {
    "alpha_x": _number(MIN_WIDTH, 1.0),
    "alpha_y": _number(MIN_WIDTH, 1.0),
    "rho_d": _channels(0.0, 1.0),
    "rho_s": _channels(0.0, 1.0),
}
_SADEGHI = {
    "n_samples": ("integer", 1, 1024, False),
    "sampling": ("choice", ("arclength", "control_points"), None, False),
    "reciprocal": ("boolean", None, None, False),
    "sigma_u": _number(MIN_WIDTH, math.pi / 2),
}

#: Reference name -> {parameter: (type, lo, hi, lo_open)}; ranges are inclusive unless lo_open.
PARAMETERS: dict[str, dict[str, tuple]] = {
    "ward": _WARD,
    "satin-ward": _WARD,
    "isotropic": _WARD,
    "ashikhmin-shirley": {
        "n_u": _number(0.0, 1e6),
        "n_v": _number(0.0, 1e6),
        "R_s": _channels(0.0, 1.0),
        "R_d": _channels(0.0, 1.0),
    },
    "ggx": {
        "alpha_x": _number(1e-3, 1.0),
        "alpha_y": _number(1e-3, 1.0),
        "eta": _number(1.0, 3.0, lo_open=True),
        "rho_d": _channels(0.0, 1.0),
        "k_s": _channels(0.0, 1.0),
    },
    "sadeghi-satin": _SADEGHI,
    "sadeghi-black-satin": {**_SADEGHI, "dye_factor": _number(0.0, 1.0)},
    **{f"sadeghi-{p}": _SADEGHI for p in ("linen", "silk-crepe", "satin-back", "silk-shot", "velvet")},
    **{f"irawan-{p}": {} for p in ("cotton-denim", "silk-shantung", "silk-charmeuse", "cotton-twill",
                                    "wool-gabardine", "polyester-lining")},
    **{f"rgl-felt-{c}": {"parameterised_by": ("choice", ("light", "viewer"), None, False)}
       for c in ("white", "pink", "purple")},
    # references given as a file path (kesbrdf.references.registry.is_reference_path)
    "rgl-file": {"parameterised_by": ("choice", ("light", "viewer"), None, False)},
    "merl-file": {},
}


def _is_number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _range_text(lo, hi, lo_open) -> str:
    return f"{'(' if lo_open else '['}{lo:g}, {hi:g}]"


def _check(reference: str, name: str, value, spec, flag: str = "--params") -> None:
    kind, lo, hi, lo_open = spec
    where = f"{flag} {name} (reference {reference})"
    shown = json.dumps(value)[:60]

    def in_range(x) -> bool:
        return math.isfinite(x) and (x > lo if lo_open else x >= lo) and x <= hi

    if kind == "number":
        if not (_is_number(value) and in_range(float(value))):
            raise KesbrdfError(f"{where}: expected a number in {_range_text(lo, hi, lo_open)}, got {shown}")
    elif kind == "integer":
        if not (isinstance(value, int) and not isinstance(value, bool) and lo <= value <= hi):
            raise KesbrdfError(f"{where}: expected an integer in [{lo}, {hi}], got {shown}")
    elif kind == "boolean":
        if not isinstance(value, bool):
            raise KesbrdfError(f"{where}: expected true or false, got {shown}")
    elif kind == "choice":
        validate_choice(where, value if isinstance(value, str) else shown, lo)
    elif kind == "channels":
        items = value if isinstance(value, list) else [value]
        ok = 1 <= len(items) <= MAX_CHANNELS and all(_is_number(x) and in_range(float(x)) for x in items)
        if not ok:
            raise KesbrdfError(
                f"{where}: expected a number or a list of 1 to {MAX_CHANNELS} numbers (one per channel) in "
                f"{_range_text(lo, hi, lo_open)}, got {shown}"
            )
    else:  # pragma: no cover - a typo in PARAMETERS
        raise RuntimeError(f"unknown parameter type {kind!r} in PARAMETERS[{reference!r}]")


def parse_params(reference: str, text: str | None, flag: str = "--params") -> dict:
    """The checked keyword arguments of ``--params`` for ``reference`` ({} when not given).

    >>> parse_params("ward", '{"alpha_x": 0.1, "rho_d": [0.2, 0.1, 0.05]}')
    {'alpha_x': 0.1, 'rho_d': [0.2, 0.1, 0.05]}
    >>> parse_params("ward", '{"alpha": 0.1}')
    Traceback (most recent call last):
    ...
    kesbrdf.errors.KesbrdfError: --params: unknown parameter 'alpha' of reference ward; expected some of alpha_x, alpha_y, rho_d, rho_s
    """
    if text is None or not text.strip():
        return {}
    spec = PARAMETERS.get(reference)
    if spec is None:  # pragma: no cover - REFERENCES and PARAMETERS are kept in step by a test
        raise RuntimeError(f"reference {reference!r} has no parameter list")
    try:
        doc = json.loads(text, parse_constant=_reject_constant)
    except (json.JSONDecodeError, RecursionError) as exc:
        msg = exc.msg if isinstance(exc, json.JSONDecodeError) else "nested too deeply"
        raise KesbrdfError(f"{flag}: expected a JSON object such as '{{\"alpha_x\": 0.1}}', got invalid JSON ({msg})") from None
    except ValueError as exc:  # NaN / Infinity, refused by _reject_constant
        raise KesbrdfError(f"{flag}: {exc}") from None
    if not isinstance(doc, dict):
        raise KesbrdfError(f"{flag}: expected a JSON object of parameter names and values, got {type(doc).__name__}")
    for name, value in doc.items():
        if name not in spec:
            expected = f"expected some of {', '.join(spec)}" if spec else "it takes none"
            raise KesbrdfError(f"{flag}: unknown parameter {name!r} of reference {reference}; {expected}")
        _check(reference, name, value, spec[name], flag)
    if reference in ("ward", "satin-ward", "isotropic", "ashikhmin-shirley", "ggx"):
        per_channel = [k for k, s in spec.items() if s[0] == "channels" and isinstance(doc.get(k), list)]
        sizes = {len(doc[k]) for k in per_channel if len(doc[k]) > 1}
        if len(sizes) > 1:
            raise KesbrdfError(
                f"{flag} {', '.join(per_channel)} (reference {reference}): expected the same number of channels, "
                f"got {', '.join(str(len(doc[k])) for k in per_channel)}"
            )
    return doc


def _reject_constant(name: str):
    raise ValueError(f"expected finite numbers, got {name}")
