"""Fixtures of the batch tests: a small synthetic library and one real LocalCluster.

The cluster is the production one (:func:`kesbrdf.batch.engine.start_local_cluster`):
2 spawned worker processes, one thread each, on 127.0.0.1, no dashboard.  Its workers
read the test-hook file named by ``$KESBRDF_BATCH_TEST_HOOKS``; a test writes the hooks
it needs into it and the ``hooks`` fixture empties it afterwards.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

pytest.importorskip("distributed")
pytest.importorskip("fsspec")

from batch_helpers import LIBRARY_KIND, N_BROKEN, N_GOOD


@pytest.fixture(scope="session")
def library(tmp_path_factory) -> Path:
    from kesbrdf.batch.library import simulate_library

    # kind kes, asked for in the catalogue: these tests are about orchestration, and
    # kesbrdf fit's rule (~8 s CPU a fabric) in each of ~10 fresh runs would cost minutes;
    # that a batch fits by that rule is test_batch.py::test_a_batch_fits_by_kesbrdf_fits_rule
    return simulate_library(N_GOOD, tmp_path_factory.mktemp("library"), seed=7, broken=N_BROKEN, images_every=3,
                            kind=LIBRARY_KIND)


@pytest.fixture(scope="session")
def hook_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("hooks") / "hooks.json"
    path.write_text("{}")
    return path


@pytest.fixture(scope="session")
def cluster(hook_file):
    from distributed import Client

    from kesbrdf.batch.engine import start_local_cluster
    from kesbrdf.batch.runner import TEST_HOOKS_ENV

    os.environ[TEST_HOOKS_ENV] = str(hook_file)  # serial runs in this process see it too
    cl = start_local_cluster(2, env={TEST_HOOKS_ENV: str(hook_file)})
    client = Client(cl)
    yield client
    client.close()
    cl.close()
    os.environ.pop(TEST_HOOKS_ENV, None)


@pytest.fixture
def hooks(hook_file):
    def set_hooks(doc: dict):
        hook_file.write_text(json.dumps(doc))

    yield set_hooks
    hook_file.write_text("{}")
