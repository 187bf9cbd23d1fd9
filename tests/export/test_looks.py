"""Exports' looks in the renderers that read them (kesbrdf.export.looks).

The glTF export is imported by Blender's own glTF importer and rendered in Cycles
(``bpy``, the ``blender`` extra); the image is compared with the kesbrdf Mitsuba
plugin's render of the model in the same scene (sphere + folded cloth, studio soft
boxes).  A frame error in the export, here the anisotropy direction turned by 90° in
``KHR_materials_anisotropy.anisotropyRotation``, must fail the same bound: the bound is
there to catch that class of error, not only to pass.

Small images (128x96, 16 spp + OIDN) keep each render to a few seconds.
"""

from __future__ import annotations

import importlib.util
import json
import math

import numpy as np
import pytest

pytestmark = [
    pytest.mark.render,
    pytest.mark.skipif(importlib.util.find_spec("mitsuba") is None, reason="needs mitsuba (kesbrdf[render])"),
    pytest.mark.skipif(importlib.util.find_spec("flip_evaluator") is None, reason="needs flip-evaluator"),
]

needs_bpy = pytest.mark.skipif(importlib.util.find_spec("bpy") is None, reason="needs bpy (kesbrdf[blender])")

#: Test renders: small and few samples, denoised on both sides.
RESOLUTION = (128, 96)
SPP = 32
#: Mean FLIP of the glTF in Blender against the plugin, on the fabric pixels, for the
#: Ward fabric of conftest.py (glTF fit NRMSE 0.17 on the tests' small grid).
#: Measured: 0.152 as exported, 0.168 with the anisotropy turned by 90°; the noise floor
#: (two plugin seeds) is 0.071.  Both renderers are seeded, so these numbers repeat on
#: one machine.  The margin is small because Blender's glTF importer maps
#: anisotropyStrength s straight onto the Principled "Anisotropic" input, which stretches
#: the lobe far less than glTF's α_t = mix(α, 1, s²) (docs/exports.md): in Blender a 90°
#: turn of this fabric's anisotropy moves FLIP by 10 % only.  The bound is the midpoint.
GLTF_FLIP_BOUND = 0.160
#: Blender's render must be a render: fabric pixels lit, as bright as the plugin's to within
#: a factor 2 on average (a missing light, a black material or a wrong exposure fails).
MEAN_RATIO_RANGE = (0.5, 2.0)


@pytest.fixture(scope="module")
def setup(tmp_path_factory, kes_model, fits):
    from kesbrdf.export import gltf, looks

    d = tmp_path_factory.mktemp("looks")
    model_path = d / "model.kes.json"
    kes_model.save(model_path)
    gltf.export(kes_model, d / "fabric.gltf", fit=fits["gltf_pbr"])
    opts = looks.LookOptions(resolution=RESOLUTION, spp=SPP, blender_spp=SPP)
    scene = looks.studio_scene(opts.resolution)
    ref = looks.PluginReference(model_path, scene, opts)
    return {"dir": d, "model": model_path, "opts": opts, "scene": scene, "ref": ref}


def _turned(src, dst, degrees: float):
    doc = json.loads(src.read_text())
    ext = doc["materials"][0]["extensions"]["KHR_materials_anisotropy"]
    ext["anisotropyRotation"] = float(ext["anisotropyRotation"]) + math.radians(degrees)
    dst.write_text(json.dumps(doc))
    return dst


def test_scene_is_the_same_in_both_renderers(setup):
    """The fabric covers a good part of the frame and the noise floor is small."""
    ref = setup["ref"]
    assert ref.mask.mean() > 0.15
    assert ref.noise["flip"] < 0.1 and ref.noise["rel_rmse"] < 0.1


@needs_bpy
def test_gltf_in_blender_matches_the_plugin_and_a_turned_anisotropy_does_not(setup):
    from kesbrdf.export import looks

    ref, d = setup["ref"], setup["dir"]
    good = looks.compare_export(ref, "gltf", d / "fabric.gltf", setup["scene"], setup["opts"], d / "b0")
    turned = looks.compare_export(ref, "gltf", _turned(d / "fabric.gltf", d / "turned.gltf", 90.0),
                                  setup["scene"], setup["opts"], d / "b1")
    ratio = float(np.mean(good["_image"][ref.mask]) / np.mean(ref.image[ref.mask]))
    assert MEAN_RATIO_RANGE[0] < ratio < MEAN_RATIO_RANGE[1]
    assert good["flip"] < GLTF_FLIP_BOUND
    assert turned["flip"] > GLTF_FLIP_BOUND
    # the importer follows the UV map's tangent (the warp), not its radial default: the
    # export's constant anisotropyTexture is what makes it do so
    assert good["_info"]["principled"]["Tangent"].startswith("ShaderNodeTangent:UV_MAP:UVMap")
