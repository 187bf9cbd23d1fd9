"""A contact sheet of one garment in several colourways (docs/method.md, "Colour").

Every tile uses the same model, scene, light, camera and exposure (``opts.exposure``,
the scene's metered exposure in the demo: never one per tile); only ``base_color`` (the
Lambertian albedo of the dyed body) changes, so the measured lobe, which carries the
gloss and the anisotropy, is identical in every tile.

A colourway whose colour is ``None`` (written ``name=measured`` in
:func:`parse_colourways`) keeps the *measured* body: the default ``black`` tile is the
measured black satin itself, not a guessed near-black.  The lobe is neutral when the
measurement is (the virtual black satin's is, R = G = B), so a dyed satin keeps a white
sheen over its coloured body; :func:`colourway_values` returns the BSDF values the tests
check this on.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from kesbrdf._drjit import load_dict as _load_dict
from kesbrdf._atomic import atomic_path
from kesbrdf.errors import KesbrdfError
from kesbrdf.render import scenes as _scenes

__all__ = ["DEFAULT_COLOURWAYS", "parse_colourways", "render_colourways", "MIN_COLOURWAYS", "colourway_values"]

#: Body albedos (linear RGB) of the default colourways; None = the measured body.
DEFAULT_COLOURWAYS: list[tuple[str, tuple[float, float, float] | None]] = [
    ("ivory", (0.80, 0.74, 0.62)),
    ("crimson", (0.50, 0.02, 0.05)),
    ("emerald", (0.02, 0.32, 0.13)),
    ("navy", (0.02, 0.04, 0.22)),
    ("gold", (0.72, 0.45, 0.06)),
    ("plum", (0.28, 0.04, 0.22)),
    ("teal", (0.02, 0.28, 0.30)),
    ("black", None),
]
MIN_COLOURWAYS = 6
#: Height of a tile's label bar (pixels) on tiles at least 8 × as tall.
LABEL_BAR = 28


def _font(size: int):
    """Pillow's default font at ``size`` px (a scalable one from Pillow 10.1; else the bitmap)."""
    from PIL import ImageFont

    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # pragma: no cover - Pillow < 10.1
        return ImageFont.load_default()


def parse_colourways(text: str) -> list[tuple[str, tuple[float, float, float]]]:
    """``"name=r,g,b;name=r,g,b;..."`` → list of (name, rgb)."""
    from kesbrdf.render.bsdf import parse_rgb

    out = []
    for k, item in enumerate(t for t in text.split(";") if t.strip()):
        name, sep, rgb = item.partition("=")
        if not sep:
            name, rgb = f"colour {k + 1}", item
        if rgb.strip().lower() == "measured":
            out.append((name.strip(), None))
            continue
        albedo = parse_rgb(rgb, f"colourway {name.strip()!r}")
        if albedo.max() > 1:
            raise KesbrdfError(f"colourway {name.strip()!r}: expected a body albedo with R,G,B in [0, 1], got {rgb!r}")
        out.append((name.strip(), tuple(float(c) for c in albedo)))
    return out


def render_colourways(model_path, output, opts: "_scenes.RenderOptions", scene: str = "dressform", drape=None,
                      colourways=None, columns: int = 4, progress=None) -> Path:
    """Render ``scene`` once per colourway and write a labelled contact sheet (PNG).

    Parameters
    ----------
    colourways : list of (name, (r, g, b)), optional
        At least :data:`MIN_COLOURWAYS`; default :data:`DEFAULT_COLOURWAYS`.
    progress : callable(done, total, name), optional
    """
    from PIL import Image, ImageDraw
    from PIL.PngImagePlugin import PngInfo

    colourways = list(colourways or DEFAULT_COLOURWAYS)
    if len(colourways) < MIN_COLOURWAYS:
        raise KesbrdfError(f"colourways: expected at least {MIN_COLOURWAYS} colours, got {len(colourways)}")
    model_path = Path(model_path)
    if not model_path.is_file():
        raise FileNotFoundError(2, "No such file or directory", str(model_path))
    if isinstance(drape, (str, Path)):
        drape = _scenes.read_drape(drape)
    tiles = []
    for k, (name, rgb) in enumerate(colourways):
        o = replace(opts, base_color=None if rgb is None else tuple(rgb))
        img = _scenes.render_scene(_scenes.load_scene(model_path, scene, o, drape=drape), o)
        tile = Image.fromarray(_scenes.to_srgb8(img, opts.exposure, opts.tonemap))
        draw = ImageDraw.Draw(tile)
        label = f"{name}  (measured body)" if rgb is None else f"{name}  ({', '.join(f'{c:.2f}' for c in rgb)})"
        bar = LABEL_BAR if tile.height >= 8 * LABEL_BAR else 16
        draw.rectangle([0, tile.height - bar, tile.width, tile.height], fill=(0, 0, 0))
        draw.text((6, tile.height - bar + 2), label, fill=(235, 235, 235), font=_font(bar - 6))
        tiles.append(tile)
        if progress is not None:
            progress(k + 1, len(colourways), name)
    columns = max(1, min(int(columns), len(tiles)))
    rows = -(-len(tiles) // columns)
    w, h = tiles[0].size
    sheet = Image.new("RGB", (columns * w, rows * h), (20, 20, 20))
    for k, tile in enumerate(tiles):
        sheet.paste(tile, ((k % columns) * w, (k // columns) * h))
    meta = _scenes.provenance(model_path, scene, opts, drape)
    meta["colourways"] = [{"name": n, "base_color": None if c is None else list(c)} for n, c in colourways]
    info = PngInfo()
    info.add_text("kesbrdf", json.dumps(meta, default=str))
    output = Path(output)
    if output.suffix.lower() != ".png":
        raise KesbrdfError(f"colourways: expected an output file ending .png, got {output.name!r}")
    with atomic_path(output) as tmp:
        sheet.save(tmp, format="PNG", pnginfo=info)
    return output


def tile_means(sheet_path, n: int, columns: int = 4) -> np.ndarray:
    """Mean linear-ish sRGB colour of each tile of a sheet (for checks), shape (n, 3)."""
    from PIL import Image

    a = np.asarray(Image.open(sheet_path).convert("RGB"), float) / 255
    rows = -(-n // columns)
    h, w = a.shape[0] // rows, a.shape[1] // min(columns, n)
    return np.array([a[(k // columns) * h:(k // columns + 1) * h - (LABEL_BAR if h >= 8 * LABEL_BAR else 16), (k % columns) * w:(k % columns + 1) * w].reshape(-1, 3).mean(0) for k in range(n)])


def colourway_values(model_path, colourways, wi, wr, mapping: str | None = None) -> dict:
    """f_r of each colourway through the ``kesbrdf`` plugin, split into body and lobe.

    Parameters
    ----------
    colourways : list of (name, rgb or None)
    wi, wr : ndarray (N, 3)
        Light and viewer directions in the fabric frame (upper hemisphere).
    mapping : str, optional
        The plugin's KES mapping; default the model's own.

    Returns
    -------
    dict
        name -> {"f": (N, 3) f_r in 1/sr, "body": (3,) the body term used (base/π, or
        the measured body when rgb is None), "lobe": f − body}.
    """
    import drjit as dr
    import mitsuba as mi

    from kesbrdf.io.model_file import load_model as load
    from kesbrdf.render.bsdf import model_rgb

    _, measured = model_rgb(load(model_path), model_path)
    wi = np.asarray(wi, float)
    wr = np.asarray(wr, float)
    out = {}
    for name, rgb in colourways:
        d = {"type": "kesbrdf", "filename": str(model_path), **({} if mapping is None else {"mapping": mapping})}
        if rgb is not None:
            d["base_color"] = ",".join(f"{float(c):.9g}" for c in rgb)
        bsdf = _load_dict(d)
        si = dr.zeros(mi.SurfaceInteraction3f, len(wi))
        si.wi = mi.Vector3f(*wr.T)
        f = np.array(bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(*wi.T)), float).T / wi[:, 2:3]
        body = np.asarray(measured, float) if rgb is None else np.asarray(rgb, float) / np.pi
        out[name] = {"f": f, "body": body, "lobe": f - body}
    return out
