"""Small helpers shared by CLI commands (terminal output only lives in the CLI)."""

from __future__ import annotations

import json
import sys

from kesbrdf.errors import validate_choice

REFERENCES = ("ward", "satin-ward", "isotropic", "ashikhmin-shirley", "sadeghi-satin", "sadeghi-black-satin")


def make_reference(name: str, params: str | None = None):
    """Build a reference BRDF by name (one registry; the error lists the names)."""
    extra = json.loads(params) if params else {}
    if name == "ward":
        from kesbrdf.references.ward import AnisotropicWard

        kw = {"alpha_x": 0.12, "alpha_y": 0.3, "rho_d": [0.25, 0.2, 0.15], "rho_s": 0.15, **extra}
        return AnisotropicWard(**kw)
    if name == "satin-ward":
        from kesbrdf.references.ward import AnisotropicWard

        # satin-like: narrow across the warp floats' highlight direction, long along it
        kw = {"alpha_x": 0.08, "alpha_y": 0.22, "rho_d": [0.02, 0.02, 0.02], "rho_s": 0.12, **extra}
        return AnisotropicWard(**kw)
    if name == "isotropic":
        from kesbrdf.references.ward import AnisotropicWard

        kw = {"alpha_x": 0.2, "alpha_y": 0.2, "rho_d": [0.3, 0.3, 0.3], "rho_s": 0.1, **extra}
        return AnisotropicWard(**kw)
    if name == "ashikhmin-shirley":
        from kesbrdf.references.ashikhmin_shirley import AshikhminShirley

        kw = {"n_u": 50.0, "n_v": 400.0, "R_s": 0.1, "R_d": [0.3, 0.25, 0.2], **extra}
        return AshikhminShirley(**kw)
    if name in ("sadeghi-satin", "sadeghi-black-satin"):
        from kesbrdf.references import sadeghi2013

        if name == "sadeghi-black-satin":
            return sadeghi2013.black_satin(**extra)
        return sadeghi2013.Sadeghi2013(preset="satin", **extra)
    validate_choice("reference", name, REFERENCES)
    raise RuntimeError(f"reference {name!r} is listed in REFERENCES but has no constructor")


def stderr(text: str) -> None:
    print(text, file=sys.stderr)


def print_metrics(result: dict, title: str = "") -> None:
    """Print a per-channel metrics table (rich if available)."""
    rows = result["metrics"] if "metrics" in result else result
    try:
        from rich.console import Console
        from rich.table import Table
    except ImportError:  # pragma: no cover - rich is in the cli extra
        for ch, m in rows.items():
            print(ch, " ".join(f"{k}={v:.4g}" for k, v in m.items()))
        return
    table = Table(title=title or None)
    for col in ("channel", "n", "rmse [1/sr]", "nrmse", "log_rmse", "max_abs [1/sr]"):
        table.add_column(col, justify="right")
    for ch, m in rows.items():
        table.add_row(ch, str(m["n"]), f"{m['rmse']:.4g}", f"{m['nrmse']:.4g}", f"{m['log_rmse']:.4g}", f"{m['max_abs']:.4g}")
    Console().print(table)
