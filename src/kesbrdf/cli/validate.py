"""``kesbrdf validate MODEL MEAS.csv``: per-channel error metrics."""

from __future__ import annotations

import json

from kesbrdf.cli._common import check_output, print_metrics, stderr

HELP = "Compare a model with a measurement CSV; prints per-channel RMSE, relative, log and max errors."


def add_arguments(p):
    p.add_argument("model", help="model file")
    p.add_argument("measurement", help="measurement CSV")
    p.add_argument("--json", dest="json_out", help="also write the metrics as JSON")
    p.add_argument("--mapping", choices=("paper", "deviation", "halfvector"), default=None,
                   help="default: the model's own (deviation unless fitted otherwise)")


def run(args) -> int:
    from kesbrdf._atomic import write_text
    from kesbrdf.io.measurement_csv import read_measurement
    from kesbrdf.model import load
    from kesbrdf.validation import validate

    if args.json_out:
        check_output(args.json_out, (".json",), "--json")
    model = load(args.model)
    m = read_measurement(args.measurement)
    result = validate(model, m, args.mapping)
    args.mapping = result["mapping"]
    result.update({"model": args.model, "measurement": args.measurement, "measurement_sha256": m.sha256})
    print_metrics(result, title=f"{args.model} vs {args.measurement} ({args.mapping})")
    if args.json_out:
        write_text(args.json_out, json.dumps(result, indent=1) + "\n")
        stderr(f"wrote {args.json_out}")
    return 0
