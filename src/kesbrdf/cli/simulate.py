"""``kesbrdf simulate``: measure a reference BRDF with the virtual gonioreflectometer."""

from __future__ import annotations

from kesbrdf.cli._common import REFERENCES, check_output, make_reference, stderr
from kesbrdf.cli._protocol import add_protocol_arguments, orientations

HELP = "Measure a reference BRDF in the paper's (or a denser) protocol; writes a measurement CSV."


def add_arguments(p):
    p.add_argument("-o", "--output", required=True, help="measurement CSV to write")
    p.add_argument("--reference", default="satin-ward",
                   help=f"reference BRDF: {', '.join(REFERENCES)}; or the path of any RGL .bsdf or MERL .binary "
                   "file. The irawan-* names are the Irawan & Marschner 2012 woven-cloth presets (numpy, no data file). "
                   "The rgl-felt-* names look for their files in $KESBRDF_RGL_DIR, then in the package's "
                   "data/rgl (white felt only); see docs/formats.md")
    p.add_argument("--params", help="JSON object of reference parameters, e.g. '{\"alpha_x\": 0.1}'")
    add_protocol_arguments(p)
    p.add_argument("--plan", metavar="PLAN.json",
                   help="measure the sample geometries of a plan written by kesbrdf plan (its recommended protocol, "
                        "exactly the rows the planner scored) instead of --protocol")
    p.add_argument("--plan-protocol", metavar="NAME",
                   help="with --plan: another protocol of the plan (e.g. paper+out-of-plane) instead of the recommended one")
    p.add_argument("--extras", metavar="GROUPS",
                   help="extra sample groups measured beside the protocol (or the plan), the names kesbrdf plan uses: "
                        "comma-separated specular:T, line:T, oop:T (0 <= T < 90 deg, each at psi = 0, 45, 90, 135), "
                        "paper or dense; e.g. line:30,oop:30,oop:60 (docs/planning.md)")
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
    # the synthetic fabric library of five families (kesbrdf.batch.fabric_library); -o is a folder
    p.add_argument("--fabric-library", type=int, metavar="N",
                   help="build the seeded library of N synthetic fabrics (five families, measurements and truths) "
                        "into the folder -o on a local Dask cluster; cached per shard (docs/validation.md)")
    p.add_argument("--families", metavar="A,B",
                   help="with --fabric-library: comma-separated families (default: irawan2012, sadeghi2013, ward, "
                        "ashikhmin_shirley, ggx)")
    p.add_argument("--shard-size", type=int, default=None, metavar="K",
                   help="with --fabric-library: fabrics per shard / Dask task (default 50)")
    p.add_argument("--workers", type=int, default=2,
                   help="with --fabric-library: local Dask worker processes (default 2; 0: serial in this process)")
    p.add_argument("--no-progress", action="store_true", help="with --fabric-library: no progress bar")


def run(args) -> int:
    if getattr(args, "fabric_library", None) is not None:
        return _run_fabric_library(args)
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
    chosen = _chosen_samples(args, orientations_deg)  # checked before the reference is built
    reference = make_reference(args.reference, args.params)
    if chosen is not None:
        import numpy as np

        from kesbrdf.measure.gonio import measure_samples

        geometry, how = chosen
        m = measure_samples(reference, geometry, noise=args.noise, noise_floor=args.noise_floor, rng=args.seed,
                            sample=f"simulated {args.reference}", generator=how)
        write_measurement(args.output, m)
        n_out = int(np.count_nonzero(np.isnan(geometry.psi)))
        stderr(f"wrote {len(m)} simulated samples ({', '.join(m.channels)}; {n_out} out of the plane of incidence) "
               f"of {', '.join(how['groups'])} to {args.output}")
        return 0
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


def _chosen_samples(args, orientations_deg):
    """(Geometry, generator record) of ``--plan`` and/or ``--extras``; None when neither is given."""
    from kesbrdf.errors import KesbrdfError
    from kesbrdf.measure import planning

    if args.plan_protocol and not args.plan:
        raise KesbrdfError(f"--plan-protocol {args.plan_protocol}: expected it with --plan PLAN.json, got no --plan")
    if not args.plan and args.extras is None:
        return None
    extras = planning.parse_groups(args.extras) if args.extras is not None else ()
    given = "--plan" if args.plan else "--extras"
    if args.images:
        raise KesbrdfError(f"--images: camera frames follow --protocol only; expected no {given}, got {given}")
    if args.plan:
        from kesbrdf.cli._protocol import PAPER_ORIENTATIONS_TEXT

        set_by_user = [f"{flag} {value}" for flag, value, on in (
            ("--protocol", args.protocol, args.protocol != "paper"),
            ("--step-deg", args.step_deg, args.step_deg is not None),
            ("--orientations-deg", args.orientations_deg, args.orientations_deg != PAPER_ORIENTATIONS_TEXT)) if on]
        if set_by_user:
            raise KesbrdfError("--plan: the plan's samples carry their own geometries; expected no --protocol, --step-deg "
                               f"or --orientations-deg with it, got {', '.join(set_by_user)}")
        base, groups = _plan_samples(args.plan, args.plan_protocol)
        how = {"plan": str(args.plan), "plan_protocol": args.plan_protocol or "recommended"}
    else:
        base = planning.base_geometry(args.protocol, args.step_deg, orientations_deg)
        groups = [args.protocol]
        how = {"protocol": args.protocol, "step_deg": args.step_deg,
               "orientations_deg": list(orientations_deg) if orientations_deg else None}
    geometry = planning.protocol_samples(extras, base=base) if extras else base
    how["groups"] = list(groups) + list(extras)
    return geometry, how


def _plan_samples(path, protocol=None):
    """(Geometry, groups) of a plan's recommended protocol, or of the protocol ``protocol``."""
    import json
    from pathlib import Path

    from kesbrdf.errors import KesbrdfError
    from kesbrdf.io.files import read_regular
    from kesbrdf.measure import planning

    try:
        doc = json.loads(read_regular(path).decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise KesbrdfError(f"--plan {path}: expected the JSON of kesbrdf plan, got unreadable JSON ({exc})") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("protocols"), dict):
        raise KesbrdfError(f"--plan {path}: expected the JSON of kesbrdf plan (with 'protocols'), got something else")
    if protocol is None:
        entry = doc.get("recommended")
        what = "its recommended protocol"
        if entry is None:
            raise KesbrdfError(f"--plan {path}: expected a recommended protocol, got none (the paper protocol was over "
                               "the budget); name one with --plan-protocol")
    else:
        entry = doc["protocols"].get(protocol)
        what = f"protocol {protocol}"
        if entry is None:
            raise KesbrdfError(f"--plan-protocol: expected one of {', '.join(doc['protocols'])}, got {protocol!r}")
        if entry.get("over_budget"):
            raise KesbrdfError(f"--plan-protocol {protocol}: expected a protocol within the plan's budget, "
                               f"got one of {entry.get('n_samples')} samples, over budget (not scored)")
    if not isinstance(entry, dict):
        raise KesbrdfError(f"--plan {path}: expected {what} as a JSON object, got {type(entry).__name__}")
    groups = [str(g) for g in entry.get("groups") or []]
    if "samples" not in entry:  # a plan written before plans recorded their geometries
        stderr(f"--plan {Path(path).name}: no sample table in {what}; measuring its groups {', '.join(groups)}")
        return planning.protocol_samples(groups), groups
    columns = doc.get("sample_columns", list(planning.SAMPLE_COLUMNS))
    return planning.geometry_from_table(entry["samples"], columns, source=f"--plan {path}"), groups


def _run_library(args) -> int:
    from kesbrdf.batch.library import simulate_library

    check_output(args.output, folder=True)
    catalog = simulate_library(args.library, args.output, seed=args.seed, broken=args.broken)
    stderr(f"wrote {args.library} fabric(s) + {args.broken} broken one(s) and the catalogue {catalog}")
    return 0


class _ShardBar:
    """tqdm bar over fabrics (the batch runner's kind of progress line)."""

    def __init__(self, enabled: bool):
        self.enabled = enabled
        self.bar = None

    def __call__(self, ev):
        if ev["event"] == "start":
            where = f"on {ev['workers']} Dask worker(s)" if ev["workers"] else "serially"
            todo = ev["shards"] - ev["cached"]
            stderr(f"fabric library: {ev['fabrics']} fabric(s) in {ev['shards']} shard(s), {ev['cached']} cached, "
                   f"{todo} to build" + (f" {where}" if todo else ""))
            if self.enabled and todo:
                from tqdm import tqdm

                self.bar = tqdm(total=ev["fabrics"], unit="fabric", dynamic_ncols=True, smoothing=0.1)
            return
        if self.bar is not None:
            self.bar.set_postfix(shards=f"{ev['done']}/{ev['total']}", refresh=False)
            self.bar.update(ev["fabrics"] - self.bar.n)

    def close(self):
        if self.bar is not None:
            self.bar.close()


def _run_fabric_library(args) -> int:
    from kesbrdf.batch.fabric_library import DEFAULT_SHARD_SIZE, build_fabric_library
    from kesbrdf.errors import KesbrdfError
    from kesbrdf.validate.library import LIBRARY_FAMILIES, check_families

    if args.library is not None:
        raise KesbrdfError("--fabric-library: expected it without --library (a batch catalogue), got both")
    check_output(args.output, folder=True)
    families = LIBRARY_FAMILIES
    if args.families is not None:
        families = check_families((f.strip() for f in args.families.split(",") if f.strip()), flag="--families")
    bar = _ShardBar(not args.no_progress)
    try:
        man = build_fabric_library(args.output, args.fabric_library, seed=args.seed, families=families,
                                   shard_size=DEFAULT_SHARD_SIZE if args.shard_size is None else args.shard_size,
                                   workers=args.workers, progress=bar)
    finally:
        bar.close()
    b = man["run"]
    stderr(f"fabric library {args.output}: {man['n']} fabric(s) of {len(man['families'])} families, "
           f"{b['shards_built']} shard(s) built, {b['shards_cached']} cached, {b['seconds']:.1f} s wall, "
           f"{b['cpu_seconds_shards'] + b['cpu_seconds_driver']:.1f} s CPU")
    stderr(f"sha256 {man['sha256']}")
    return 0
