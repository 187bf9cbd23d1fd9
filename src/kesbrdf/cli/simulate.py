"""``kesbrdf simulate``: measure a reference BRDF with the virtual gonioreflectometer."""

from __future__ import annotations

from kesbrdf.cli._common import REFERENCES, check_output, make_reference, stderr
from kesbrdf.cli._protocol import add_protocol_arguments, orientations

HELP = "Measure a reference BRDF in the paper's (or a denser) protocol; writes a measurement CSV."


def add_arguments(p):
    p.add_argument("-o", "--output", required=True, help="measurement CSV to write")
    p.add_argument("--reference", default="satin-ward",
                   help=f"reference BRDF: {', '.join(REFERENCES)}; or the path of any RGL .bsdf or MERL .binary "
                   "file. The rgl-felt-* names look for their files in $KESBRDF_RGL_DIR, then in the source "
                   "tree's tests/data/rgl (white felt only); see docs/formats.md")
    p.add_argument("--params", help="JSON object of reference parameters, e.g. '{\"alpha_x\": 0.1}'")
    add_protocol_arguments(p)
    p.add_argument("--noise", type=float, default=0.0, help="relative noise (std / value)")
    p.add_argument("--noise-floor", type=float, default=0.0, help="absolute noise std, 1/sr")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--images", metavar="DIR", help="also write camera frames + manifest (image-based acquisition)")
    p.add_argument("--bit-depth", type=int, choices=(8, 16), default=16,
                   help="camera frames' bit depth (16: TIFF, 8: PNG)")
    p.add_argument("--vignetting", type=float, default=0.0, help="relative illumination fall-off k (1 - k r^2)")
    # batch: a synthetic fabric library (kesbrdf.batch.library); -o is then a folder
    p.add_argument("--library", type=int, metavar="N", help="write N varied fabrics + catalog.csv into the folder -o")
    p.add_argument("--broken", type=int, default=2, help="with --library: deliberately broken fabrics (default 2)")


def run(args) -> int:
    if getattr(args, "library", None) is not None:
        return _run_library(args)
    from kesbrdf.errors import KesbrdfError
    from kesbrdf.measure.gonio import measure
    from kesbrdf.io.measurement_csv import write_measurement

    check_output(args.output, (".csv",))
    if args.seed < 0:
        raise KesbrdfError(f"--seed: expected an integer >= 0, got {args.seed}")
    if args.vignetting and not args.images:
        raise KesbrdfError("--vignetting: applies to camera frames only; add --images DIR")
    orientations_deg = orientations(args.orientations_deg)
    reference = make_reference(args.reference, args.params)
    if args.images:
        from kesbrdf.measure.acquisition.camera import simulate_images
        from kesbrdf.measure.acquisition.sensor import Sensor

        manifest = simulate_images(
            reference,
            args.images,
            protocol=args.protocol,
            step_deg=args.step_deg,
            orientations_deg=orientations_deg,
            seed=args.seed,
            sensor=Sensor(bit_depth=args.bit_depth, vignetting=args.vignetting),
            file_format="tiff" if args.bit_depth == 16 else "png",
            sample=f"simulated {args.reference}",
        )
        stderr(f"wrote frames and manifest {manifest}")
    m = measure(
        reference,
        protocol=args.protocol,
        step_deg=args.step_deg,
        noise=args.noise,
        noise_floor=args.noise_floor,
        rng=args.seed,
        orientations_deg=orientations_deg,
        sample=f"simulated {args.reference}",
    )
    write_measurement(args.output, m)
    stderr(f"wrote {len(m)} simulated samples ({', '.join(m.channels)}) to {args.output}")
    return 0


def _run_library(args) -> int:
    from kesbrdf.batch.library import simulate_library

    check_output(args.output, folder=True)
    catalog = simulate_library(args.library, args.output, seed=args.seed, broken=args.broken)
    stderr(f"wrote {args.library} fabric(s) + {args.broken} broken one(s) and the catalogue {catalog}")
    return 0
