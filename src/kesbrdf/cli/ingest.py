"""``kesbrdf ingest MANIFEST.csv -o MEAS.csv``: camera frames -> measurement CSV.

Reads the manifest's frames, calibrates them (:func:`kesbrdf.measure.acquisition.ingest.ingest`),
writes the measurement atomically and prints a summary of the frames used, flagged
and rejected.  When any frame is rejected, the rejected frames are listed on stderr,
the first problem is reported on one line, nothing is written and the exit code is 2.
"""

from __future__ import annotations

import argparse
import sys

HELP = "turn gonioreflectometer photographs (a manifest of frames) into a measurement CSV"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("manifest", metavar="MANIFEST.csv", help="manifest of sample, white and dark frames")
    parser.add_argument("-o", "--output", metavar="MEAS.csv", required=True, help="measurement CSV to write")
    parser.add_argument(
        "--saturation",
        choices=("reject", "lower-bound"),
        default="reject",
        help="clipped pixels in a sample's ROI: reject the frame (default) or keep its value "
        "flagged as a lower bound",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="list every frame, not only flagged ones")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress bar and no summary")


def _table(rows, title: str, every: bool):
    """A rich table of the frames (all, or the flagged and rejected ones); a title alone if none."""
    from rich.table import Table
    from rich.text import Text

    if not any(every or r.status in ("flagged", "rejected") for r in rows):
        return Text(title)
    table = Table(title=title, title_justify="left")
    for name in ("line", "file", "kind", "status", "detail"):
        table.add_column(name, overflow="fold")
    style = {"used": "green", "flagged": "yellow", "rejected": "red", "unused": "dim"}
    for r in rows:
        if every or r.status in ("flagged", "rejected"):
            table.add_row(str(r.line), r.file, r.kind, f"[{style[r.status]}]{r.status}[/]", r.detail)
    return table


def _counts_line(rows) -> str:
    counts = {s: sum(r.status == s for r in rows) for s in ("used", "flagged", "rejected", "unused")}
    return ", ".join(f"{n} {s}" for s, n in counts.items() if n or s in ("used", "rejected"))


def _check_output(args) -> None:
    from kesbrdf.cli._common import check_output

    check_output(args.output, (".csv",))


def run(args) -> int:
    _check_output(args)
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from kesbrdf.measure.acquisition.ingest import IngestError, ingest
    from kesbrdf.io.measurement_csv import write_measurement

    saturation = args.saturation.replace("-", "_")
    out = Console()
    err = Console(stderr=True)
    progress_bar = Progress(
        TextColumn("ingest"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[file]}"),
        TimeElapsedColumn(),
        console=err,
        transient=True,
        disable=args.quiet or not sys.stderr.isatty(),
    )
    try:
        with progress_bar:
            task = progress_bar.add_task("ingest", total=None, file="")

            def progress(done: int, total: int, file: str) -> None:
                progress_bar.update(task, completed=done, total=total, file=file)

            result = ingest(args.manifest, saturation=saturation, progress=progress)
    except IngestError as exc:
        if exc.summary and not args.quiet:
            err.print(_table(exc.summary, f"{args.manifest}: {_counts_line(exc.summary)}", every=False))
        raise
    write_measurement(args.output, result.measurement)
    if not args.quiet:
        out.print(_table(result.summary, f"{args.manifest}: {_counts_line(result.summary)}", every=args.verbose))
        out.print(f"wrote {args.output}: {len(result.measurement)} samples, channels {', '.join(result.measurement.channels)}")
    return 0
