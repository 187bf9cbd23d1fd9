r"""Format ``mitsuba-scene``: Mitsuba 3 XML scenes that render the model.

``kesbrdf export MODEL --format mitsuba-scene -o fabric.xml`` writes, side by side:

``fabric.xml``
    The model on a sphere (warp around the vertical axis) over a grey floor, lit by a
    rectangular key light and a dim constant environment, with the ``kesbrdf`` plugin
    (:mod:`kesbrdf.render.bsdf`) reading ``fabric.kes.json``.  The plugin is Python, so
    load it from Python after ``import kesbrdf.render`` (which registers it)::

        import kesbrdf.render, mitsuba as mi
        img = mi.render(mi.load_file("fabric.xml"))

``fabric.kes.json``
    The model file the plugin reads (exact: it is the model).
``fabric_measured.xml`` and ``fabric.bsdf``
    The same scene with Mitsuba's built-in ``measured`` plugin reading the RGL tensor
    export (:mod:`kesbrdf.export.rgl_bsdf`, approximate: interpolated between grid
    nodes).  Runs in the ``mitsuba`` command-line renderer too:
    ``mitsuba -m scalar_rgb fabric_measured.xml``.

Models of other kinds (``kes-halfdiff``, ...), which the plugin does not read, get only
the ``measured`` scene, written as ``fabric.xml``.

Filenames inside the scenes are relative to the XML file (Mitsuba resolves them from
the scene's folder).  Resolution and sample count are scene defaults, overridable at
load time (``mi.load_file(path, spp=256)``, ``mitsuba -Dspp=256``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from kesbrdf.export._framework import ExportResult

__all__ = ["export", "scene_xml", "EXTENSIONS", "HELP"]

EXTENSIONS = (".xml",)
HELP = "Mitsuba 3 XML scenes: the model with the kesbrdf plugin, and with `measured` reading the .bsdf export"

#: Sphere centre and radius, world y-up (as kesbrdf.render.scenes' sphere scene).
CENTER = (0.0, 1.0, 0.0)
RADIUS = 1.0
FOV_DEG = 32.0


def _v(x) -> str:
    return ", ".join(f"{float(c):.6g}" for c in x)


def scene_xml(bsdf_xml: str, *, width: int = 320, height: int = 240, spp: int = 64, max_depth: int = 4,
              title: str = "") -> str:
    """The scene text around a ``<bsdf id="fabric">`` element."""
    c = np.array(CENTER)
    r = 2.0 * RADIUS  # bounding radius of sphere + contact with the floor
    view = np.array([0.0, 0.55, 1.0]) / np.linalg.norm([0.0, 0.55, 1.0])
    dist = 0.95 * r / np.sin(np.radians(FOV_DEG) / 2)
    origin = c + dist * view
    key = np.array([0.45, 0.72, 0.6]) / np.linalg.norm([0.45, 0.72, 0.6])
    light = c + 3.6 * r * key
    size = 0.6 * r
    return f"""<?xml version="1.0" encoding="utf-8"?>
<!-- {title} -->
<scene version="3.0.0">
    <default name="spp" value="{int(spp)}"/>
    <default name="width" value="{int(width)}"/>
    <default name="height" value="{int(height)}"/>
    <default name="max_depth" value="{int(max_depth)}"/>

    <integrator type="path">
        <integer name="max_depth" value="$max_depth"/>
    </integrator>

    <sensor type="perspective">
        <float name="fov" value="{FOV_DEG:g}"/>
        <string name="fov_axis" value="y"/>
        <transform name="to_world">
            <lookat origin="{_v(origin)}" target="{_v(c)}" up="0, 1, 0"/>
        </transform>
        <sampler type="independent">
            <integer name="sample_count" value="$spp"/>
        </sampler>
        <film type="hdrfilm">
            <integer name="width" value="$width"/>
            <integer name="height" value="$height"/>
            <string name="pixel_format" value="rgb"/>
            <rfilter type="gaussian"/>
        </film>
    </sensor>

{bsdf_xml}
    <!-- the fabric: a sphere whose UV u (the warp, fabric x) runs around the vertical axis -->
    <shape type="sphere">
        <transform name="to_world">
            <rotate x="1" angle="-90"/>
            <translate value="{_v(c)}"/>
        </transform>
        <ref id="fabric"/>
    </shape>

    <shape type="rectangle">
        <transform name="to_world">
            <scale value="12"/>
            <rotate x="1" angle="-90"/>
            <translate value="{_v((c[0], c[1] - RADIUS - 1e-3, c[2]))}"/>
        </transform>
        <bsdf type="diffuse">
            <rgb name="reflectance" value="0.42, 0.42, 0.42"/>
        </bsdf>
    </shape>

    <shape type="rectangle">
        <transform name="to_world">
            <scale value="{size:.6g}"/>
            <lookat origin="{_v(light)}" target="{_v(c)}" up="0, 1, 0"/>
        </transform>
        <emitter type="area">
            <rgb name="radiance" value="9.0, 8.8, 8.4"/>
        </emitter>
    </shape>

    <emitter type="constant">
        <rgb name="radiance" value="0.25, 0.25, 0.25"/>
    </emitter>
</scene>
"""


def _kesbrdf_bsdf(model_name: str, plugin: str, props: dict) -> str:
    """The kesbrdf plugin entry ``model.render_plugin()`` names, with its properties."""
    extra = "".join(f'        <string name="{k}" value="{v}"/>\n' for k, v in props.items())
    return f"""    <!-- kesbrdf plugin: register it first (import kesbrdf.render) -->
    <bsdf type="{plugin}" id="fabric">
        <string name="filename" value="{model_name}"/>
{extra}        <boolean name="two_sided" value="false"/>
    </bsdf>
"""


def _measured_bsdf(bsdf_name: str) -> str:
    return f"""    <!-- Mitsuba's measured plugin reading the RGL tensor export -->
    <bsdf type="measured" id="fabric">
        <string name="filename" value="{bsdf_name}"/>
    </bsdf>
"""


def export(model, out, *, width: int = 320, height: int = 240, spp: int = 64, mapping: str | None = None,
           measured: bool = True, check: bool = True, **bsdf_options) -> ExportResult:
    """Write ``out`` (kesbrdf plugin scene), the model file, and (``measured``) the
    ``measured`` scene with its ``.bsdf``; ``bsdf_options`` go to :mod:`~kesbrdf.export.rgl_bsdf`.
    ``mapping``: the KES mapping of a table (default: the model's own, ``default_mapping``)."""
    from kesbrdf._atomic import write_text
    from kesbrdf.errors import ExportError

    plugin, props = model.render_plugin(mapping=mapping)  # the kesbrdf plugin drawing this model
    kes_mapping = mapping if "mapping" in props else None  # the KES mapping applies to it
    # a scene of the (φ, γ) table plugin, which every kind's table view feeds; a kind
    # with its own plugin gets the measured scene only (as before: one scene per file)
    table_plugin = plugin == "kesbrdf"
    if table_plugin:
        model.table_view()  # a kind that cannot be tabulated says so before anything is written
    import inspect

    from kesbrdf.export import rgl_bsdf

    known = [k for k in inspect.signature(rgl_bsdf.export).parameters if k not in ("model", "out", "mapping", "check")]
    unknown = [k for k in bsdf_options if k not in known]
    if unknown:
        raise ExportError(f"mitsuba-scene: unknown option(s) {', '.join(map(repr, unknown))}; expected width, height, "
                          f"spp, mapping, measured, check or a .bsdf option ({', '.join(known)})")
    from kesbrdf._version import __version__

    out = Path(out)
    stem = out.name[: -len(".xml")]
    size = dict(width=width, height=height, spp=spp)
    origin = f"kesbrdf {__version__}, model sha256 {rgl_bsdf.model_sha256(model)[:16]}"
    paths, agreement, notes = [], {}, []
    measured = measured or not table_plugin
    if measured:  # the slow part first: a failure leaves no scene pointing at a missing file
        bsdf_path = out.with_name(f"{stem}.bsdf")
        r = rgl_bsdf.export(model, bsdf_path, mapping=kes_mapping, check=check, **bsdf_options)
        agreement = {f"bsdf_{k}": v for k, v in r.agreement.items()}
    if table_plugin:
        model_path = out.with_name(f"{stem}.kes.json")
        model.save(model_path)
        text = scene_xml(_kesbrdf_bsdf(model_path.name, plugin, props), title=f"{stem}: kesbrdf plugin ({origin})", **size)
        write_text(out, text)
        paths += [out, model_path]
        notes.append("the kesbrdf-plugin scene renders the model itself (exact)" if model.has_table else
                     f"the kesbrdf-plugin scene renders the (phi, gamma) table tabulated from the {model.kind!r} model")
    else:
        notes.append(f"the {plugin} plugin draws this {model.kind!r} model in kesbrdf renders; "
                     f"{out.name} uses Mitsuba's measured plugin on the .bsdf export")
    if measured:
        measured_path = out.with_name(f"{stem}_measured.xml") if table_plugin else out
        text = scene_xml(_measured_bsdf(bsdf_path.name), title=f"{stem}: measured plugin ({origin})", **size)
        write_text(measured_path, text)
        paths += [measured_path, bsdf_path]
        notes.append(f"{measured_path.name} renders {bsdf_path.name} with Mitsuba's measured plugin (approximate)")
    open_with = "; ".join(
        ([f"Python: import kesbrdf.render, mitsuba as mi; mi.render(mi.load_file('{out.name}'))"] if table_plugin else [])
        + ([f"command line: mitsuba -m scalar_rgb {measured_path.name}"] if measured else []))
    return ExportResult("mitsuba-scene", paths, agreement=agreement, notes=notes, open_with=open_with)
