"""Regenerate the embedded sample ``src/kesbrdf/data/virtual_black_satin/``.

"Virtual black satin" is *simulated*: the Sadeghi et al. (2013) satin preset darkened
like the black satin of Takeda et al. (:func:`kesbrdf.references.sadeghi2013.black_satin`),
photographed by the virtual gonioreflectometer
(:func:`kesbrdf.measure.acquisition.camera.simulate_images`) under the paper's protocol:
4 orientations × 29 geometries of sample frames, a white-reference frame at each of
the 29 geometries, and one dark frame per exposure time.  Frames are 24×24-pixel
16-bit RGB TIFF (zlib) with a 16×16 ROI.  The seed is fixed, so running this script
again rewrites the same pixels.

Usage::

    PYTHONPATH=src python scripts/make_virtual_black_satin.py [--check]

``--check`` regenerates into a temporary folder and exits 1 if any frame's pixels or the
manifest differ from the committed ones.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

from kesbrdf.measure.acquisition.camera import simulate_images
from kesbrdf.measure.acquisition.images import read_image
from kesbrdf.references.sadeghi2013 import black_satin

SEED = 20130301  # fixed: the embedded frames are reproducible bit for bit
TARGET = Path(__file__).resolve().parent.parent / "src" / "kesbrdf" / "data" / "virtual_black_satin"
SETTINGS = dict(protocol="paper", size=24, margin=3, roi_inset=1, whites="all", file_format="tiff", seed=SEED)


def generate(outdir: Path) -> Path:
    """Write the frames and manifest into ``outdir`` (old frames removed first)."""
    outdir.mkdir(parents=True, exist_ok=True)
    for old in list(outdir.glob("*.tif")) + [outdir / "manifest.csv"]:
        if old.exists():
            old.unlink()
    return simulate_images(black_satin(), outdir, sample="virtual black satin (simulated)", **SETTINGS)


def same_as_committed(fresh: Path) -> bool:
    """True when every frame's pixels and the manifest equal the committed ones."""
    names = sorted(p.name for p in fresh.glob("*.tif"))
    if names != sorted(p.name for p in TARGET.glob("*.tif")):
        return False
    if (fresh / "manifest.csv").read_text() != (TARGET / "manifest.csv").read_text():
        return False
    return all(np.array_equal(read_image(fresh / n).pixels, read_image(TARGET / n).pixels) for n in names)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="compare with the committed frames, write nothing")
    args = parser.parse_args(argv)
    if args.check:
        with tempfile.TemporaryDirectory() as tmp:
            generate(Path(tmp))
            ok = same_as_committed(Path(tmp))
        print("embedded sample is up to date" if ok else "embedded sample differs from a fresh generation")
        return 0 if ok else 1
    manifest = generate(TARGET)
    size = sum(p.stat().st_size for p in TARGET.iterdir() if p.is_file())
    print(f"wrote {manifest} ({len(list(TARGET.glob('*.tif')))} frames, {size / 1024:.0f} KiB in the folder)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
