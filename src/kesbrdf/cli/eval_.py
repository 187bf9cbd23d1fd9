"""``kesbrdf eval MODEL --pairs PAIRS.csv -o OUT.csv``: f_r at direction pairs."""

from __future__ import annotations

import csv
import io

import numpy as np

from kesbrdf.cli._common import check_output, stderr
from kesbrdf.io.pairs_csv import PAIR_COLUMNS, read_pairs  # noqa: F401  (read_pairs: kept importable here)

HELP = "Evaluate a model's BRDF at direction pairs (theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg)."


def add_arguments(p):
    p.add_argument("model", help="model file")
    p.add_argument("--pairs", required=True, help="CSV with theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg")
    p.add_argument("-o", "--output", required=True, help="CSV to write (pairs + f_r per channel, 1/sr)")
    p.add_argument("--mapping", choices=("paper", "deviation", "halfvector", "halfdiff"), default=None,
                   help="direction mapping (default: the model kind's own, deviation for kes); "
                   "one the model's kind lacks is an error")
    p.add_argument("--uncertainty", action="store_true",
                   help="add a sigma column per channel (1/sr): for kes, kes-halfdiff, fibre-prior and fibre-coord models "
                        "fitted by this version (docs/models.md, sigma of a kes model; docs/prior.md section 5); a "
                        "baseline or an older kes or kes-halfdiff file refuses in one line")


def run(args) -> int:
    from kesbrdf._atomic import write_text
    from kesbrdf.models.brdf import evaluate
    from kesbrdf.geometry import spherical_to_cartesian
    from kesbrdf.io.model_file import load_model as load

    check_output(args.output, (".csv",))
    model = load(args.model)
    mapping = model.check_mapping(args.mapping)  # before reading the pairs: fail fast
    pairs = read_pairs(args.pairs)
    rad = np.radians(pairs)
    wi = spherical_to_cartesian(rad[:, 0], rad[:, 1])
    wr = spherical_to_cartesian(rad[:, 2], rad[:, 3])
    sigma = None
    if args.uncertainty:
        from kesbrdf.validate.uncertainty import predict_sigma

        f, sigma, _ = predict_sigma(model, wi, wr, source=args.model)
    else:
        f = evaluate(model, wi, wr, mapping)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    header = list(PAIR_COLUMNS) + list(model.channels)
    if sigma is not None:
        header += [f"sigma_{c}" for c in model.channels]
        f = np.concatenate([f, sigma], axis=1)
    w.writerow(header)
    for p, v in zip(pairs, f):
        w.writerow([repr(float(x)) for x in p] + [repr(float(x)) for x in v])
    write_text(args.output, buf.getvalue())
    stderr(f"wrote {len(pairs)} BRDF values ({mapping} mapping{', with sigma' if sigma is not None else ''}) to {args.output}")
    return 0
