"""``kesbrdf eval MODEL --pairs PAIRS.csv -o OUT.csv``: f_r at direction pairs."""

from __future__ import annotations

import csv
import io

import numpy as np

from kesbrdf.cli._common import stderr

HELP = "Evaluate a model's BRDF at direction pairs (theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg)."
PAIR_COLUMNS = ("theta_i_deg", "phi_i_deg", "theta_r_deg", "phi_r_deg")


def add_arguments(p):
    p.add_argument("model", help="model file")
    p.add_argument("--pairs", required=True, help="CSV with theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg")
    p.add_argument("-o", "--output", required=True, help="CSV to write (pairs + f_r per channel, 1/sr)")
    p.add_argument("--mapping", choices=("paper", "deviation", "halfvector", "halfdiff"), default=None,
                   help="direction mapping (default: the model kind's own, deviation for kes); "
                   "one the model's kind lacks is an error")


def read_pairs(path):
    """Read a pairs CSV; returns (header, rows as float array (N, 4), raw rows)."""
    from kesbrdf.errors import FormatError, where

    lines = [(n, l) for n, l in enumerate(open(path, encoding="utf-8").read().splitlines(), 1)
             if l.strip() and not l.lstrip().startswith("#")]
    if not lines:
        raise FormatError(f"{where(path)}expected a header {','.join(PAIR_COLUMNS)}, got an empty file")
    n0, head = lines[0]
    header = [h.strip() for h in next(csv.reader([head]))]
    missing = [c for c in PAIR_COLUMNS if c not in header]
    if missing:
        raise FormatError(f"{where(path, n0)}missing column(s) {', '.join(missing)}; expected {','.join(PAIR_COLUMNS)}")
    idx = [header.index(c) for c in PAIR_COLUMNS]
    out = []
    for n, line in lines[1:]:
        fields = next(csv.reader([line]))
        row = []
        for c, k in zip(PAIR_COLUMNS, idx):
            try:
                v = float(fields[k])
            except (ValueError, IndexError):
                got = fields[k] if k < len(fields) else "nothing"
                raise FormatError(f"{where(path, n)}column {c}: expected a number, got {got!r}") from None
            if not np.isfinite(v):
                raise FormatError(f"{where(path, n)}column {c}: expected a finite number, got {fields[k]!r}")
            row.append(v)
        if not (0 <= row[0] <= 90 and 0 <= row[2] <= 90):
            raise FormatError(f"{where(path, n)}theta: expected degrees in [0, 90], got {row[0]:g}, {row[2]:g}")
        out.append(row)
    return np.array(out, float).reshape(-1, 4)


def run(args) -> int:
    from kesbrdf._atomic import write_text
    from kesbrdf.brdf import evaluate
    from kesbrdf.geometry import spherical_to_cartesian
    from kesbrdf.model import load

    model = load(args.model)
    mapping = model.check_mapping(args.mapping)  # before reading the pairs: fail fast
    pairs = read_pairs(args.pairs)
    rad = np.radians(pairs)
    wi = spherical_to_cartesian(rad[:, 0], rad[:, 1])
    wr = spherical_to_cartesian(rad[:, 2], rad[:, 3])
    f = evaluate(model, wi, wr, mapping)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(list(PAIR_COLUMNS) + list(model.channels))
    for p, v in zip(pairs, f):
        w.writerow([repr(float(x)) for x in p] + [repr(float(x)) for x in v])
    write_text(args.output, buf.getvalue())
    stderr(f"wrote {len(pairs)} BRDF values ({mapping} mapping) to {args.output}")
    return 0
