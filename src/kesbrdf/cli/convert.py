"""``kesbrdf convert INPUT -o meas.csv``: any input kesbrdf reads, as a measurement CSV.

CUReT samples become a general-geometry CSV (their own 205 configurations); RGL
``.bsdf`` and MERL ``.binary`` tables are sampled at a protocol's geometries by the
virtual gonioreflectometer (:func:`kesbrdf.measure.gonio.measure`, as ``kesbrdf simulate``); a
measurement CSV is read, checked and written back.  The result is what ``kesbrdf fit``
would fit, so it can be inspected, edited or plotted first.
"""

from __future__ import annotations

from kesbrdf.cli._common import check_output, stderr

HELP = ("Convert a CUReT abrdf.dat, RGL .bsdf or MERL .binary into a measurement CSV "
        "(tables sampled at --protocol's geometries).")


def add_arguments(p):
    from kesbrdf.cli._protocol import add_protocol_arguments

    p.add_argument("input", metavar="INPUT",
                   help="CUReT abrdf.dat (table.txt beside it), RGL .bsdf, MERL .binary or a measurement CSV "
                   "(recognised by content and ending; docs/formats.md)")
    p.add_argument("-o", "--output", required=True, help="measurement CSV to write")
    p.add_argument("--sample", default=None,
                   help="CUReT input: the sample, by number (42) or fabric name (corduroy)")
    add_protocol_arguments(p, default=None, what="at which an RGL .bsdf / MERL .binary is sampled (default paper)")


def run(args) -> int:
    from kesbrdf.cli._protocol import orientations
    from kesbrdf.io.measurement_csv import write_measurement
    from kesbrdf.io.sources import read_source

    check_output(args.output, (".csv",))
    m = read_source(args.input, sample=args.sample, protocol=args.protocol, step_deg=args.step_deg,
                    orientations_deg=orientations(args.orientations_deg))
    for note in m.notes:
        stderr(f"note: {args.input}: {note}")
    write_measurement(args.output, m)
    geometry = "in-plane" if m.psi is not None else "general geometry"
    stderr(f"wrote {len(m)} samples ({', '.join(m.channels)}, {geometry}) of {m.metadata.get('sample', args.input)} "
           f"to {args.output}")
    return 0
