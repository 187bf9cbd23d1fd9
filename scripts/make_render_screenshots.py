"""Regenerate the reference-vs-model panels and the satin diagnosis strip in docs/screenshots/.

Usage::

    PYTHONPATH=src python scripts/make_render_screenshots.py

Writes ``compare-*.png`` (+ ``.json`` numbers, kept out of the repo by the caller if
unwanted) and ``satin-diagnosis.png``; prints the numbers.  About two minutes.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path


OUT = Path(__file__).resolve().parent.parent / "docs" / "screenshots"

PANELS = [
    ("sadeghi-black-satin", "paper", "sphere"),
    ("sadeghi-black-satin", "dense", "sphere"),
    ("sadeghi-black-satin", "paper", "drape"),
    ("satin-ward", "paper", "sphere"),
    ("rgl-felt-white", "paper", "sphere"),
]


def diagnosis_strip(path: Path) -> list[dict]:
    """The demo's sphere, then each fix in turn, on the virtual black satin's KES model."""
    import tempfile

    from PIL import Image, ImageDraw

    from kesbrdf.measure.gonio import measure
    from kesbrdf.models.kes import fit
    from kesbrdf.references.sadeghi2013 import black_satin
    from kesbrdf.render import scenes as S
    from kesbrdf.render.compare import auto_exposure, cloth_mask
    from kesbrdf.render.highlight import highlight_stats
    from kesbrdf.render.reference_bsdf import reference_bsdf_dict

    demo_colour = (0.45, 0.03, 0.06)  # kesbrdf.render.demo.DEMO_COLOUR before this change
    base = S.RenderOptions(spp=64, resolution=(160, 120), env="studio", light="area", extrapolation="hold")
    with tempfile.TemporaryDirectory() as tmp:
        model = Path(tmp) / "black_satin.kes.json"
        fit(measure(black_satin()), fallback="log").save(model)
        steps = [
            ("1 demo: red body, studio", replace(base, base_color=demo_colour), None, False),
            ("2 measured body", base, None, False),
            ("3 + one small light", replace(base, env="none"), None, False),
            ("4 + auto exposure", replace(base, env="none"), None, True),
            ("5 + fade beyond 84 deg", replace(base, env="none", extrapolation="fade"), None, True),
            ("reference (Sadeghi)", replace(base, env="none"), reference_bsdf_dict("sadeghi-black-satin"), True),
        ]
        tiles, rows = [], []
        for label, o, bsdf, auto in steps:
            sc = S.load_scene(model, "sphere", o, cloth_bsdf=bsdf or S.bsdf_dict(model, o))
            mask = cloth_mask(sc)
            img = S.render_scene(sc, o)
            st = highlight_stats(img, mask)
            ev = auto_exposure(img, mask) if auto else 0.0
            tile = Image.fromarray(S.to_srgb8(img, ev))
            d = ImageDraw.Draw(tile)
            d.rectangle([0, 0, tile.width, 13], fill=(0, 0, 0))
            d.text((2, 1), label, fill=(235, 235, 235))
            d.text((2, tile.height - 12), f"peak/median {st['contrast']:.1f}", fill=(235, 235, 235))
            tiles.append(tile)
            rows.append({"step": label, "contrast": st["contrast"], "elongation": st["elongation"],
                         "highlight_area": st["highlight_area"], "exposure_stops": ev,
                         "mean_srgb8": S.to_srgb8(img, ev)[mask].mean(0).round(1).tolist()})
    strip = Image.new("RGB", (tiles[0].width * len(tiles), tiles[0].height))
    for k, t in enumerate(tiles):
        strip.paste(t, (k * t.width, 0))
    strip.save(path, optimize=True)
    _shrink(path)
    return rows


def _shrink(path: Path) -> None:
    """Re-save as a 256-colour palette PNG (docs copies only: a third of the size)."""
    from PIL import Image

    Image.open(path).convert("RGB").quantize(256, dither=Image.Dither.NONE).save(path, optimize=True)


def main() -> int:
    import kesbrdf.render  # noqa: F401
    from kesbrdf.render import compare

    OUT.mkdir(parents=True, exist_ok=True)
    numbers = {}
    for name, protocol, scene in PANELS:
        short = name.replace("sadeghi-", "").replace("rgl-", "")
        path = OUT / f"compare-{short}-{protocol}-{scene}.png"
        r = compare.compare_render(name, protocol, scene, compare.default_options(), output=path)
        path.with_suffix(".json").unlink()
        _shrink(path)
        numbers[path.name] = {k: round(float(r[k]), 4) for k in ("flip", "rel_rmse", "noise_flip", "noise_rel_rmse")}
        print(path.name, numbers[path.name])
    rows = diagnosis_strip(OUT / "satin-diagnosis.png")
    for r in rows:
        print(json.dumps(r))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
