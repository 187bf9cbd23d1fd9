"""The reference chart: the measured fabric, a white fabric and an 18 % grey card in one
studio shot, at the exposure metered on the card (:func:`kesbrdf.render.exposure.meter_exposure`).

Two spheres of the same model side by side, the left with the measured body (the
demo's black satin), the right dyed white (:data:`WHITE_BODY`, same measured lobe),
and the grey card in the frame's lower left.  One light, one exposure: a black fabric
shows as dark as it is next to the card and the white fabric, which is the point of
fixing the exposure on a reference instead of on each image.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from kesbrdf._drjit import load_dict as _load_dict

__all__ = ["WHITE_BODY", "CHART_CENTER", "CHART_RADIUS", "SPHERE_X", "load_chart", "render_chart"]

#: Body albedo of the chart's white fabric (a bleached cotton/poly white, linear RGB).
WHITE_BODY = (0.85, 0.85, 0.85)
#: The two unit spheres stand at x = ∓SPHERE_X, on the floor (y up).
SPHERE_X = 1.15
#: Framing of the chart: centre and bounding radius of the two spheres.
CHART_CENTER = (0.0, 1.0, 0.0)
CHART_RADIUS = 2.3


def load_chart(model_path, opts, subject: bool = True, meter=None):
    """The chart scene (Mitsuba), the studio lights of ``opts`` around it."""
    import mitsuba as mi

    from kesbrdf.render import scenes as _s
    from kesbrdf.render.bsdf import check_model

    opts.validate()
    kind = check_model(model_path, opts.mapping).kind
    center, radius = np.asarray(CHART_CENTER, float), CHART_RADIUS
    view = (0.0, 0.35, 1.0)
    T = mi.ScalarTransform4f
    d = {"type": "scene"}
    if subject:
        for name, x, body in (("black", -SPHERE_X, None), ("white", SPHERE_X, WHITE_BODY)):
            b = _s.bsdf_dict(model_path, replace(opts, base_color=body), kind)
            d[f"sphere_{name}"] = {"type": "sphere", "to_world": T().translate([x, 1.0, 0.0]) @ T().rotate([1, 0, 0], -90),
                                   "bsdf": b}
    d["floor"] = {"type": "rectangle", "to_world": T().translate([0.0, -1e-3, 0.0]) @ T().rotate([1, 0, 0], -90)
                  @ T().scale(12.0), "bsdf": _s._diffuse(_s.STUDIO_FLOOR_ALBEDO)}
    if opts.grey_card:
        d["grey_card"] = _s._grey_card(opts, center, radius, view)
    d.update(_s._lights(opts, center, radius))
    d["sensor"] = _s._camera(opts, center, radius, view) if meter is None else _s._meter_camera(opts, center, radius,
                                                                                                 view, *meter)
    # as in scenes.load_scene: the studio's emitters are not seen directly by the camera
    integ = opts.integrator or {"type": "path", "max_depth": int(opts.max_depth),
                                "hide_emitters": opts.light == "studio"}
    if opts.denoise and meter is None:
        integ = {"type": "aov", "aovs": "albedo:albedo,nn:sh_normal", "integrator": integ}
    d["integrator"] = integ
    return _load_dict(d)


def meter_chart(model_path, opts) -> float:
    """Exposure (stops) of the chart, metered on its grey card without the spheres."""
    from kesbrdf.render import exposure as _ex

    o = _ex.meter_options(opts)
    return _ex.meter_reading(load_chart(model_path, o, subject=False, meter=(_ex.METER_SIZE, _ex.METER_SPP)), o)


def render_chart(model_path, output, opts, exposure: float | None = None) -> tuple[Path, np.ndarray]:
    """Render the chart to ``output`` (PNG); returns (path, linear image).

    ``exposure`` None meters it on the card (:func:`meter_chart`); the image always
    shows the card (``grey_card`` is forced on).
    """
    from kesbrdf.render import scenes as _s

    model_path = Path(model_path)
    if not model_path.is_file():
        raise FileNotFoundError(2, "No such file or directory", str(model_path))
    o = replace(opts, grey_card=True)
    if exposure is None:
        exposure = meter_chart(model_path, o)
    o = replace(o, exposure=float(exposure))
    img = _s.render_scene(load_chart(model_path, o), o)
    meta = _s.provenance(model_path, "chart", o)
    meta["chart"] = {"left": "measured body", "right": f"white body {WHITE_BODY}", "card": "18 % grey"}
    return _s.save_image(output, img, meta, o.exposure, o.tonemap), img
