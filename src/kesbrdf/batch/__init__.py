"""Library scale: fit, validate, export and preview whole fabric catalogues on Dask.

``run_batch(catalog, out, steps=..., workers=N)`` processes every row of a catalogue
(:mod:`~kesbrdf.batch.catalog`) through the steps of :mod:`~kesbrdf.batch.steps`,
one Dask task per fabric (:mod:`~kesbrdf.batch.engine`), skipping every step whose
manifest matches (:mod:`~kesbrdf.batch.manifest`), and writes ``summary.csv``,
``summary.parquet`` and the ``index.html`` contact sheet (:mod:`~kesbrdf.batch.summary`).
:mod:`~kesbrdf.batch.library` writes a synthetic catalogue for tests, demo and benchmarks.
Install ``kesbrdf[batch]``; docs/batch.md has the details.
"""

from __future__ import annotations

from kesbrdf.batch.catalog import Fabric, read_catalog
from kesbrdf.batch.engine import DEFAULT_STEPS, BatchResult, run_batch
from kesbrdf.batch.steps import STEPS

__all__ = ["run_batch", "BatchResult", "Fabric", "read_catalog", "STEPS", "DEFAULT_STEPS"]
