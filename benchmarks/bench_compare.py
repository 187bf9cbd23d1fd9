"""Reference vs model renders (issue 12): FLIP and relative RMSE per reference and protocol.

For each reference of :data:`kesbrdf.render.compare.DEFAULT_REFERENCES` and each protocol
(``paper``: 116 samples; ``dense``: 6° in-plane grid) the sphere is rendered with the
reference BRDF itself and with models fitted from its virtual measurements (480x360,
64 spp denoised, area light in a dark room, :func:`kesbrdf.render.compare.default_options`):
``kesbrdf fit``'s default model (``flip``, ``rel_rmse``, ``model_kind``), the protocol's
KES kind (``kes`` on the paper line, ``kes-halfdiff`` dense: ``kes_flip``,
``kes_rel_rmse``), the fibre prior times its residual (kind ``fibre-prior``, rendered by
the ``kesbrdf_prior`` plugin: ``prior_flip``, ``prior_rel_rmse``), and the pure prior of
that fit (``residual=False``: ``prior_only_flip``, ``prior_only_rel_rmse``), which tells the prior's error from the
residual's.  ``noise_*`` is the same comparison between
two seeds of the reference: the floor below which a model error is not measurable.

Also, on the two Sadeghi satins, the paper-protocol model with the lobe held beyond the
last measured deviation (``extrapolation="hold"``, docs/formats.md) against the renderer's
default ``fade``.  A few minutes on one core.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))


def run() -> dict:
    import kesbrdf.render  # noqa: F401
    from kesbrdf.render import compare

    out: dict = {"scene": "sphere", "options": compare.default_options().to_json()}
    for name in compare.DEFAULT_REFERENCES:
        try:
            compare.make_reference(name)
        except Exception as exc:  # an RGL file may be missing on this machine
            out[name] = {"error": str(exc)}
            continue
        for protocol in compare.PROTOCOLS:
            t0 = time.perf_counter()
            r = compare.compare_render(name, protocol, "sphere", compare.default_options(),
                                       models=("default", "kes", "fibre-prior", "prior-only"))
            prior, pure, kes = r["models"]["fibre-prior"], r["models"]["prior-only"], r["models"]["kes"]
            out[f"{name}/{protocol}"] = {
                "flip": r["flip"], "rel_rmse": r["rel_rmse"],
                "kes_flip": kes["flip"], "kes_rel_rmse": kes["rel_rmse"],
                "prior_flip": prior["flip"], "prior_rel_rmse": prior["rel_rmse"],
                "prior_only_flip": pure["flip"], "prior_only_rel_rmse": pure["rel_rmse"],
                "noise_flip": r["noise_flip"], "noise_rel_rmse": r["noise_rel_rmse"],
                "samples": r["samples"], "model_kind": r["model_kind"],
                "seconds": time.perf_counter() - t0,
            }
    for name in ("sadeghi-satin", "sadeghi-black-satin"):
        r = compare.compare_render(name, "paper", "sphere", compare.default_options(extrapolation="hold"),
                                   noise_floor=False, models=("kes",))
        out[f"{name}/paper/extrapolation=hold"] = {"flip": r["flip"], "rel_rmse": r["rel_rmse"]}
    return out


if __name__ == "__main__":  # pragma: no cover
    import json

    print(json.dumps(run(), indent=1))
