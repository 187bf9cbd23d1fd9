"""``kesbrdf validate MODEL MEAS.csv``: per-channel error metrics."""

from __future__ import annotations

import json

from kesbrdf.cli._common import check_output, print_metrics, stderr

HELP = ("Compare a model with a measurement CSV; prints per-channel RMSE, relative, log and max errors, "
        "and where the error is by deviation from the mirror direction.")


def add_arguments(p):
    p.add_argument("model", help="model file")
    p.add_argument("measurement", help="measurement CSV")
    p.add_argument("--json", dest="json_out", help="also write the metrics as JSON")
    p.add_argument("--mapping", choices=("paper", "deviation", "halfvector"), default=None,
                   help="default: the model's own (deviation unless fitted otherwise)")


#: Below this overall NRMSE the model returns the samples (round-off): no band to point at.
ROUND_OFF_NRMSE = 1e-9


def print_bands(bands, nrmse: float) -> None:
    """Where the error lives, by deviation γ from the mirror direction
    (:func:`kesbrdf.validate.compare.deviation_bands`): one row per band with samples."""
    if nrmse < ROUND_OFF_NRMSE:
        print("where the error is: nowhere above round-off (the model returns these samples)")
        return
    print("where the error is, by deviation from the mirror direction:")
    for b in bands:
        print(f"  {b['lo']:3.0f}-{b['hi']:3.0f} deg  n={b['n']:<5d} {b['share']:6.1%} of the squared error  "
              f"NRMSE {b['nrmse']:.3f}  model/measured x{b['ratio']:.2f} (median)")


def run(args) -> int:
    from kesbrdf._atomic import write_text
    from kesbrdf.io.measurement_csv import read_measurement
    from kesbrdf.io.model_file import load_model as load
    from kesbrdf.validate.compare import validate

    if args.json_out:
        check_output(args.json_out, (".json",), "--json")
    model = load(args.model)
    m = read_measurement(args.measurement)
    result = validate(model, m, args.mapping)
    args.mapping = result["mapping"]
    result.update({"model": args.model, "measurement": args.measurement, "measurement_sha256": m.sha256})
    print_metrics(result, title=f"{args.model} vs {args.measurement} ({args.mapping})")
    print_bands(result["by_deviation"], result["metrics"]["all"]["nrmse"])
    from kesbrdf.validate.uncertainty import coverage, has_uncertainty, predict_sigma

    if has_uncertainty(model):
        wi, wr = m.wi, m.wr
        warp = model.sample_frame_warp
        if warp:  # fitted in a sample frame: evaluate as validate() does
            from kesbrdf.models.scattered import to_fabric_frame

            wi, wr = to_fabric_frame(wi, warp), to_fabric_frame(wr, warp)
        pred, _, sigma_log = predict_sigma(model, wi, wr, source=args.model)
        if pred.shape == m.values.shape:
            cov = coverage(pred, sigma_log, m.values)
            result["uncertainty"] = cov
            fitted_to = (model.input_info or {}).get("sha256")
            if fitted_to and fitted_to == m.sha256:
                caveat = ("these are the samples the model was fitted to: a check, not a calibration; give validate "
                          "held-out data to calibrate")
            else:
                caveat = ("not the file the model was fitted to: on rows it was not fitted to this tests the sigma, "
                          "which is the model's error and leaves out this file's own noise")
            result["uncertainty_on"] = "fitted samples" if fitted_to and fitted_to == m.sha256 else "other data"
            print(f"uncertainty: {cov['within_1sigma']:.0%} of the samples within 1 sigma, "
                  f"{cov['within_2sigma']:.0%} within 2 sigma (Gaussian: 68%, 95%); "
                  f"median sigma of ln f {cov['median_sigma_log']:.3f} ({caveat})")
    else:
        print(f"uncertainty: none (this {model.kind!r} model file holds no sigma: older than the sigma of its kind, "
              "or a kind or interpolation without one)")
    if args.json_out:
        write_text(args.json_out, json.dumps(result, indent=1) + "\n")
        stderr(f"wrote {args.json_out}")
    return 0
