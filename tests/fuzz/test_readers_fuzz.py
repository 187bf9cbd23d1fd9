"""Property: every reader either loads a mutated file or raises a KesbrdfError.

Each test mutates valid files with :func:`mutations.mutated` (truncation, byte flips,
random columns, huge numbers, unicode, CRLF, long lines, empty fields, NaN/inf
text) and feeds them to one reader.  Anything but success or a
:class:`kesbrdf.errors.KesbrdfError` (a ``ValueError`` subclass with a one-line
message) fails the test; a file that loads must also satisfy the format's
invariants (finite values, angles in range).

Examples per reader: a few thousand in the suite, 100,000 under
``HYPOTHESIS_PROFILE=fuzz`` (``make fuzz``).  With ``KESBRDF_FUZZ_STATS=FILE`` the
counts of accepted / typed-error / untyped inputs are written to FILE (JSON).
"""

from __future__ import annotations

import json
import os
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mutations import examples, mutated

from kesbrdf.errors import KesbrdfError

pytestmark = pytest.mark.fuzz

#: Examples per text reader in the normal suite: a derandomized regression sweep
#: (each ~5-10 ms with the reader's checks; 2,000 made this file ~15 % of `make test`'s
#: CPU).  The search for new failures is `make fuzz` (100,000 per reader).
TEXT_EXAMPLES = 1000
#: Examples of the image readers (four formats share them) and of the model-file and
#: simulate-parameter sweeps (each example parses and evaluates or simulates).
IMAGE_EXAMPLES = 2000
SMALL_EXAMPLES = 500

TALLY: dict[str, Counter] = {}


@pytest.fixture(autouse=True)
def _write_stats():
    """After each test (so an interrupted sweep keeps its counts), merge the tallies into the file."""
    yield
    target = os.environ.get("KESBRDF_FUZZ_STATS")
    if target:
        old = json.loads(Path(target).read_text()) if Path(target).is_file() else {}
        old.update({name: dict(c) for name, c in TALLY.items()})
        Path(target).write_text(json.dumps(old, indent=1, sort_keys=True) + "\n")


def _run(reader_name: str, call):
    """Call ``call()``; count and return its result, or None for a typed error. Untyped errors fail."""
    tally = TALLY.setdefault(reader_name, Counter())
    tally["tried"] += 1
    try:
        result = call()
    except KesbrdfError as exc:
        tally["typed_error"] += 1
        message = str(exc)
        assert message and "\n" not in message, f"typed error message must be one line: {message!r}"
        return None
    except Exception as exc:  # the property under test: no other exception type
        tally["untyped"] += 1
        raise AssertionError(f"{reader_name}: untyped {type(exc).__name__}: {exc}") from exc
    tally["accepted"] += 1
    return result


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    return tmp_path_factory.mktemp("fuzz")


# -- measurement CSV ---------------------------------------------------------------
MEASUREMENT_SEEDS = [
    b"""# kesbrdf-measurement: 1
# sample: fuzz satin
# quantity: brdf
psi_deg,theta_i_deg,theta_r_deg,R,G,B,R_unc,G_unc,B_unc,flag,file
0,87,3,0.11,0.12,0.13,0.01,0.01,0.01,ok,a.tif
0,60,30,0.21,0.22,0.23,0.01,0.01,0.01,lower_bound,b.tif
45,45,45,0.31,0.32,0.33,0.02,0.02,0.02,ok,c.tif
90,30,60,0.41,0.42,0.43,0.02,0.02,0.02,flagged,"d,e.tif"
135,3,87,0.51,0.52,0.53,0.03,0.03,0.03,ok,f.tif
""",
    b"""# quantity: radiance_ratio
theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg,value
10,0,20,180,0.5
40,-90,40,90,0.25
89.5,350,5,10,0.125
70,360,0,0,1e-3
""",
    b"""# quantity: reflectance_factor
psi_deg,theta_i_deg,theta_r_deg,nm450,nm550,nm650
0,60,30,0.1,0.2,0.3
90,60,30,0.3,0.2,0.1
""",
]


@settings(max_examples=examples(TEXT_EXAMPLES))
@given(data=mutated(MEASUREMENT_SEEDS))
def test_measurement_csv_loads_or_raises_typed_error(work, data):
    from kesbrdf.io.measurement_csv import read_measurement

    path = work / "m.csv"
    path.write_bytes(data)
    m = _run("measurement_csv", lambda: read_measurement(path))
    if m is not None:
        assert len(m) > 0
        assert np.all(np.isfinite(m.values))
        assert m.uncertainty is None or np.all(np.isfinite(m.uncertainty))
        for angle in (m.theta_i, m.theta_r):
            assert np.all((angle >= 0) & (angle <= np.pi / 2))
        for angle in (m.phi_i, m.phi_r):
            assert np.all(np.isfinite(angle))


# -- acquisition manifest -----------------------------------------------------------
MANIFEST_SEEDS = [
    b"""# kesbrdf-manifest: 1
# sample: fuzz
# white_reflectance: 0.99
# response: linear
# saturation_level: 60000
file,kind,psi_deg,theta_i_deg,theta_r_deg,phi_i_deg,phi_r_deg,exposure_s,roi
dark_0.tif,dark,,,,,,0.004,
white_87_03.tif,white,,87,3,,,0.512,"4,4,28,28"
s000_87_03.tif,sample,0,87,3,,,4.096,"4,4,28,28"
s045_60_30.tif,sample,45,60,30,,,1.5,4;4;28;28
g_1.tif,sample,,40,40,10,200,2,
""",
    b"""# kesbrdf-manifest: 1
# response: srgb
file,kind,psi_deg,theta_i_deg,theta_r_deg,exposure_s
a.png,sample,90,30,60,0.25
b.png,dark,,,,0.25
""",
]


@settings(max_examples=examples(TEXT_EXAMPLES))
@given(data=mutated(MANIFEST_SEEDS))
def test_manifest_loads_or_raises_typed_error(work, data):
    from kesbrdf.measure.acquisition.manifest import read_manifest

    path = work / "manifest.csv"
    path.write_bytes(data)
    manifest = _run("manifest", lambda: read_manifest(path))
    if manifest is not None:
        assert manifest.rows
        for row in manifest.rows:
            assert row.exposure_s > 0 and np.isfinite(row.exposure_s)
            for name in ("psi_deg", "theta_i_deg", "theta_r_deg", "phi_i_deg", "phi_r_deg"):
                value = getattr(row, name)
                assert np.isnan(value) or -360 <= value <= 360


# -- pairs CSV (kesbrdf eval --pairs) --------------------------------------------------
PAIRS_SEEDS = [
    b"""# pairs
theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg
30,0,30,180
60,45,10,-90
0,0,90,360
""",
    b"""phi_r_deg,theta_r_deg,extra,phi_i_deg,theta_i_deg\r\n10,20,x,30,40\r\n""",
]


@settings(max_examples=examples(TEXT_EXAMPLES))
@given(data=mutated(PAIRS_SEEDS))
def test_pairs_csv_loads_or_raises_typed_error(work, data):
    from kesbrdf.io.pairs_csv import read_pairs

    path = work / "pairs.csv"
    path.write_bytes(data)
    pairs = _run("pairs_csv", lambda: read_pairs(path))
    if pairs is not None:
        assert pairs.ndim == 2 and pairs.shape[1] == 4
        assert np.all(np.isfinite(pairs))
        assert np.all((pairs[:, [0, 2]] >= 0) & (pairs[:, [0, 2]] <= 90))


# -- CUReT table.txt / abrdf.dat ------------------------------------------------------
CURET_TABLE = b"""1 0.1 0.0 0.5 3.14
2 0.5 1.0 0.2 -1.0
3 1.2 6.0 1.5707963 0.0
"""
CURET_ABRDF = b"""1 0.10 0.20 0.30
42 0.5 -0.001 0.7
"""


@settings(max_examples=examples(TEXT_EXAMPLES))
@given(table=mutated([CURET_TABLE]), which=st.sampled_from([1, 42]))
def test_curet_table_loads_or_raises_typed_error(work, table, which):
    from kesbrdf.io.curet import read_curet

    (work / "table.txt").write_bytes(table)
    (work / "abrdf.dat").write_bytes(CURET_ABRDF)
    m = _run("curet_table", lambda: read_curet(work / "table.txt", work / "abrdf.dat", which))
    if m is not None:
        assert np.all(np.isfinite(m.values)) and np.all(np.isfinite(m.phi_i))


@settings(max_examples=examples(TEXT_EXAMPLES))
@given(abrdf=mutated([CURET_ABRDF]), which=st.sampled_from([1, 42]))
def test_curet_abrdf_loads_or_raises_typed_error(work, abrdf, which):
    from kesbrdf.io.curet import read_curet

    (work / "table.txt").write_bytes(CURET_TABLE)
    (work / "abrdf.dat").write_bytes(abrdf)
    m = _run("curet_abrdf", lambda: read_curet(work / "table.txt", work / "abrdf.dat", which))
    if m is not None:
        assert m.values.shape == (3, 1) and np.all(np.isfinite(m.values))


# -- camera frames ----------------------------------------------------------------------
@pytest.fixture(scope="module")
def image_seeds(work):
    from kesbrdf.measure.acquisition.images import write_image

    rng = np.random.default_rng(7)
    seeds = {}
    for name, pixels in (
        ("rgb8.png", rng.integers(0, 255, (6, 5, 3), dtype=np.uint8)),
        ("grey16.png", rng.integers(0, 65535, (6, 5), dtype=np.uint16)),
        ("rgb16.tif", rng.integers(0, 65535, (6, 5, 3), dtype=np.uint16)),
        ("rgb.exr", rng.random((6, 5, 3)).astype(np.float32)),
    ):
        write_image(work / name, pixels)
        seeds[name] = (work / name).read_bytes()
    return seeds


@pytest.mark.parametrize("name", ["rgb8.png", "grey16.png", "rgb16.tif", "rgb.exr"])
def test_images_load_or_raise_typed_error(work, image_seeds, name):
    from kesbrdf.measure.acquisition.images import read_image

    @settings(max_examples=examples(IMAGE_EXAMPLES) // 4)  # four image formats share the count
    @given(data=mutated([image_seeds[name]], text=False))
    def check(data):
        path = work / f"fuzz_{name}"
        path.write_bytes(data)
        frame = _run("images", lambda: read_image(path))
        if frame is not None:
            assert frame.pixels.ndim == 3 and frame.pixels.shape[-1] in (1, 3)

    check()


# -- simulate --params ------------------------------------------------------------------
PARAMS_SEEDS = [
    b'{"alpha_x": 0.1, "alpha_y": 0.3, "rho_d": [0.2, 0.1, 0.05], "rho_s": 0.04}',
    b'{"n_u": 10, "n_v": 100.5, "R_s": [0.1, 0.1, 0.1], "R_d": 0.3}',
    b'{"n_samples": 8, "sampling": "control_points", "reciprocal": false, "sigma_u": 0.3}',
    b'{"dye_factor": 0.5, "n_samples": 4}',
]


@settings(max_examples=examples(SMALL_EXAMPLES))
@given(
    data=mutated(PARAMS_SEEDS),
    reference=st.sampled_from(["ward", "ashikhmin-shirley", "sadeghi-satin", "sadeghi-black-satin"]),
)
def test_simulate_params_accepted_or_typed_error(data, reference):
    from kesbrdf.cli._common import make_reference

    def build():
        text = data.decode("utf-8", "replace")
        brdf = make_reference(reference, text)
        wi = np.array([[0.3, 0.1, 0.95]])
        wr = np.array([[-0.2, 0.2, 0.96]])
        return np.asarray(brdf(wi / np.linalg.norm(wi), wr / np.linalg.norm(wr)))

    f = _run("simulate_params", build)
    if f is not None:
        assert np.all(np.isfinite(f)) and np.all(f >= 0)


# -- any input by path (kesbrdf.io.sources: fit / convert) ------------------------------
def _source_seeds():
    from kesbrdf.io.tensor_file import tensor_file_bytes
    from kesbrdf.references.merl import DIMS

    tensor = tensor_file_bytes({"theta_i": np.linspace(0, 1.5, 3).astype("<f4"), "description": "fuzz"})
    merl = np.array(DIMS, "<i4").tobytes() + np.zeros(8, "<f8").tobytes()  # right header, truncated body
    return [MEASUREMENT_SEEDS[1], CURET_ABRDF, tensor, merl]


@settings(max_examples=examples(TEXT_EXAMPLES))
@given(data=mutated(_source_seeds()), name=st.sampled_from(["in.csv", "abrdf.dat", "in.bsdf", "in.binary", "in"]))
def test_any_input_loads_or_raises_typed_error(work, data, name):
    from kesbrdf.io.sources import detect, read_source

    folder = work / "sources"
    folder.mkdir(exist_ok=True)
    for old in folder.iterdir():
        old.unlink()
    (folder / "table.txt").write_bytes(CURET_TABLE)
    path = folder / name
    path.write_bytes(data)

    def read():
        return read_source(path, sample=42 if detect(path) == "curet" else None)

    m = _run("sources", read)
    if m is not None:
        assert len(m) > 0 and np.all(np.isfinite(m.values))


# -- model files (kesbrdf.io.model_file) ------------------------------------------------
def _model_seeds() -> dict:
    """Small valid model files of the table kinds (written with the writer's indent)."""
    from kesbrdf.measure.gonio import measure
    from kesbrdf.models.halfdiff import fit_halfdiff
    from kesbrdf.io.model_file import model_to_dict
    from kesbrdf.models.kes import fit
    from kesbrdf.references.ward import AnisotropicWard

    ref = AnisotropicWard(0.15, 0.3, rho_d=0.1, rho_s=0.1)
    models = {"kes": fit(measure(ref), n_phi=8, gamma_step=np.radians(12.0)),
              "kes-halfdiff": fit_halfdiff(measure(ref, protocol="dense", step_deg=18), n_phi=8)}
    return {k: (json.dumps(model_to_dict(m), indent=1) + "\n").encode() for k, m in models.items()}


MODEL_SEEDS = _model_seeds()
#: Array values that broke (or could break) evaluation and export: overflow on the
#: way (1e308 / cos θ), NaN, inf, values past float32 (1e50), past the reader's bound
#: (1e101), negative, subnormal.
EXTREME_VALUES = (1e308, -1e308, float("nan"), float("inf"), -float("inf"), 1e101, 1e100, 1e50, 3.5e38,
                  -1.0, 5e-324, 0.0)


@st.composite
def extreme_array_value(draw):
    """A model file with one element of one array replaced by an extreme value."""
    import base64

    doc = json.loads(MODEL_SEEDS[draw(st.sampled_from(sorted(MODEL_SEEDS)))])
    entry = doc["arrays"][draw(st.sampled_from(sorted(doc["arrays"])))]
    a = np.frombuffer(base64.b64decode(entry["data"]), "<f8").copy()
    if a.size:
        a[draw(st.integers(0, a.size - 1))] = draw(st.sampled_from(EXTREME_VALUES))
    entry["data"] = base64.b64encode(a.tobytes()).decode("ascii")
    return (json.dumps(doc, indent=1) + "\n").encode()


PAIRS_WI = np.array([[0.3, 0.1, 0.95], [-0.7, 0.2, 0.05], [0.0, 0.0, 1.0], [0.999, 0.0, 1e-3]])
PAIRS_WR = np.array([[-0.2, 0.2, 0.96], [0.6, -0.1, 0.08], [0.0, 0.0, 1.0], [-0.999, 0.0, 1e-3]])


@settings(max_examples=examples(SMALL_EXAMPLES))
@given(data=st.one_of(mutated(list(MODEL_SEEDS.values())), extreme_array_value()))
def test_model_file_loads_or_raises_typed_error(work, data):
    """A model file loads or gives one line; what loads evaluates finite and >= 0, and
    every export either accepts it or refuses it in one line (never a crash)."""
    from kesbrdf.io.model_file import load_model

    path = work / "m.kes.json"
    path.write_bytes(data)
    model = _run("model_file", lambda: load_model(path))
    if model is not None:
        wi = PAIRS_WI / np.linalg.norm(PAIRS_WI, axis=1, keepdims=True)
        wr = PAIRS_WR / np.linalg.norm(PAIRS_WR, axis=1, keepdims=True)
        for mapping in model.mappings:
            f = model.evaluate(wi, wr, mapping)
            assert np.all(np.isfinite(f)) and np.all(f >= 0), (model.kind, mapping, f)
        from kesbrdf.errors import ExportError
        from kesbrdf.export._framework import VALUE_MAX, check_values

        try:
            check_values(model, "rgl-bsdf")
        except ExportError as exc:
            assert "\n" not in str(exc)
        else:
            assert np.all(f <= VALUE_MAX)
