"""The model file reader (kesbrdf.io.model_file): round trip, hostile input, fuzzing.

Property: for any bytes, :func:`load_model` either returns a model or raises
:class:`~kesbrdf.errors.ModelError` (a KesbrdfError, one line); a model that loads
evaluates to finite, non-negative values at any pair above the horizon.

The hypothesis tests mutate valid files of both kinds (truncation, byte flips, JSON
type swaps, huge numbers, deep nesting, unicode, array shapes).  ``make test`` runs a
few thousand examples; ``HYPOTHESIS_PROFILE=fuzz`` (``make fuzz``) runs 100,000 per test.
"""

from __future__ import annotations

import base64
import copy
import json
import os
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from kesbrdf.errors import KesbrdfError, ModelError
from kesbrdf.io.model_file import MAX_ARRAY_ELEMENTS, MAX_DEPTH, load_model, model_from_dict, model_to_dict

settings.register_profile("fuzz", max_examples=100_000, deadline=None,
                          suppress_health_check=list(HealthCheck))
FUZZ = os.environ.get("HYPOTHESIS_PROFILE") == "fuzz"
if FUZZ:
    settings.load_profile("fuzz")
#: Examples per property in the normal suite (together well under 20 s).
EXAMPLES = {"bytes": 900, "json": 1000, "shape": 300}


def examples(kind: str) -> int:
    """Examples per property: a few thousand, 100,000 under the fuzz profile, or
    ``KESBRDF_FUZZ_EXAMPLES`` when set (for a sweep of a given size)."""
    if os.environ.get("KESBRDF_FUZZ_EXAMPLES"):
        return int(os.environ["KESBRDF_FUZZ_EXAMPLES"])
    return 100_000 if FUZZ else EXAMPLES[kind]


def _small_models():
    from kesbrdf.measure.gonio import measure
    from kesbrdf.models.halfdiff import fit_halfdiff
    from kesbrdf.models.kes import fit
    from kesbrdf.references.ward import AnisotropicWard

    ref = AnisotropicWard(0.15, 0.3, rho_d=0.1, rho_s=0.1)
    kes = fit(measure(ref), n_phi=8, gamma_step=np.radians(12.0))
    halfdiff = fit_halfdiff(measure(ref, protocol="dense", step_deg=18), n_phi=8)
    return {"kes": kes, "kes-halfdiff": halfdiff}


MODELS = _small_models()
DOCS = {k: model_to_dict(m) for k, m in MODELS.items()}
TEXTS = {k: json.dumps(d) for k, d in DOCS.items()}
TMP = Path(tempfile.mkdtemp(prefix="kesbrdf-fuzz-"))
RNG = np.random.default_rng(8)
PAIRS_WI = RNG.normal(size=(64, 3)) * [1, 1, 0] + [0, 0, 0.05]
PAIRS_WR = RNG.normal(size=(64, 3))
PAIRS_WI[:, 2] = np.abs(PAIRS_WI[:, 2]) + 1e-3
PAIRS_WR[:, 2] = np.abs(PAIRS_WR[:, 2]) + 1e-3


def check_outcome(load):
    """``load()`` loads (and evaluates sanely) or raises ModelError; anything else fails."""
    try:
        model = load()
    except ModelError as exc:
        assert "\n" not in str(exc)
        return None
    for mapping in model.mappings:
        f = model.evaluate(PAIRS_WI, PAIRS_WR, mapping)
        assert f.shape == (64, model.n_channels)
        assert np.all(np.isfinite(f)) and np.all(f >= 0), (model.kind, mapping)
    return model


def load_bytes(data: bytes):
    path = TMP / "m.kes.json"
    path.write_bytes(data)
    return check_outcome(lambda: load_model(path))


# -- round trip and targeted cases -------------------------------------------------------
@pytest.mark.parametrize("kind", sorted(MODELS))
def test_round_trip_is_exact(tmp_path, kind):
    model = MODELS[kind]
    path = model.save(tmp_path / "m.kes.json")
    again = load_model(path)
    assert type(again) is type(model) and again.kind == kind
    np.testing.assert_array_equal(again.table, model.table)
    assert again.parameters == json.loads(json.dumps(model.parameters))


def mutated(base="kes", /, **changes):
    doc = copy.deepcopy(DOCS[base])
    for path, value in changes.items():
        node = doc
        keys = path.split("__")
        for k in keys[:-1]:
            node = node[k]
        node[keys[-1]] = value
    return doc


def table_entry(shape, data=None):
    return {"dtype": "<f8", "shape": shape, "data": data if data is not None else ""}


HOSTILE = {
    "banana kind": (mutated(kind="banana"), "expected model kind one of 'kes', 'kes-halfdiff'.*got 'banana'"),
    "negative shape": (mutated(arrays__table=table_entry([-1, -3])), "non-negative integers"),
    "float shape": (mutated(arrays__table=table_entry([2.5, 3])), "non-negative integers"),
    "bool shape": (mutated(arrays__table=table_entry([True, 3])), "non-negative integers"),
    "huge shape": (mutated(arrays__table=table_entry([2**32, 2**32])), f"at most {MAX_ARRAY_ELEMENTS} elements"),
    # found by the fuzz profile: an empty array whose other extents overflow numpy
    "empty huge shape": (mutated(arrays__body=table_entry([0, 2**31, 2**31])), f"at most {MAX_ARRAY_ELEMENTS} elements"),
    "shape not a list": (mutated(arrays__table=table_entry("Infinity")), "non-negative integers"),
    "short data": (mutated(arrays__body=table_entry([1], "AAAA")), "expected 8 bytes"),
    "bad dtype": (mutated(arrays__body={"dtype": "|O", "shape": [1], "data": "AAAAAAAAAAA="}), "dtype one of"),
    "array not an object": (mutated(arrays__body=[1.0]), "expected an object"),
    "channels not a list": (mutated(channels="R"), "channels: expected a non-empty list"),
    "channels empty": (mutated(channels=[]), "channels: expected a non-empty list"),
    "parameters a list": (mutated(parameters=[1, 2]), "parameters: expected a JSON object"),
    "version a string": (mutated(format_version="1"), "format version 1, got '1'"),
    "missing arrays": (mutated(arrays={}), "missing array"),
    "one gamma": (None, "at least 2 values"),
    "nan table": (None, "table: expected finite non-negative"),
    "negative table": (None, "table: expected finite non-negative"),
    "phi grid not uniform": (None, "phi_grid: expected the uniform grid"),
}


def _array_doc(name, values, kind="kes"):
    return mutated(kind, **{f"arrays__{name}": {
        "dtype": "<f8", "shape": list(np.shape(values)),
        "data": base64.b64encode(np.asarray(values, "<f8").tobytes()).decode()}})


def _special(case):
    m = MODELS["kes"]
    if case == "one gamma":
        return _array_doc("gamma_grid", m.gamma_grid[:1])
    if case == "nan table":
        t = m.table.copy()
        t[0, 0, 0] = np.nan
        return _array_doc("table", t)
    if case == "negative table":
        t = m.table.copy()
        t[1, 1, 0] = -1.0
        return _array_doc("table", t)
    if case == "phi grid not uniform":
        g = m.phi_grid.copy()
        g[3] += 0.01
        return _array_doc("phi_grid", g)
    raise KeyError(case)


@pytest.mark.parametrize("case", sorted(HOSTILE))
def test_hostile_documents_give_one_line_model_errors(case):
    doc, match = HOSTILE[case]
    doc = _special(case) if doc is None else doc
    with pytest.raises(ModelError, match=match) as info:
        model_from_dict(doc, source="m.kes.json")
    assert str(info.value).startswith("m.kes.json: ") and "\n" not in str(info.value)


@pytest.mark.parametrize("text,match", [
    ("[" * 100_000 + "]" * 100_000, "nested at most"),
    ('{"format": "kesbrdf-model", "x": ' + "[" * (MAX_DEPTH + 5) + "]" * (MAX_DEPTH + 5) + "}", "nested at most"),
    ('{"format": "kesbrdf-model", "format_version": NaN}', "NaN is not valid JSON"),
    ('{"format": "kesbrdf-model", "format_version": 1e999}', "overflows"),
    ('{"format": "kesbrdf-model", "format_version": ' + "9" * 5000 + "}", "expected a kesbrdf model file"),
    ("\ufeff" + '{"format": "other"}', "expected format 'kesbrdf-model'"),
])
def test_hostile_text(tmp_path, text, match):
    path = tmp_path / "m.kes.json"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ModelError, match=match):
        load_model(path)


def test_unknown_kind_never_loads_as_kes(tmp_path):
    path = tmp_path / "m.kes.json"
    path.write_text(json.dumps(mutated(kind="banana")))
    with pytest.raises(KesbrdfError, match="'banana'"):
        load_model(path)


# -- property-based: mutated files ---------------------------------------------------------
@settings(max_examples=examples("bytes"), deadline=None, suppress_health_check=list(HealthCheck))
@given(kind=st.sampled_from(sorted(TEXTS)), data=st.data())
def test_mutated_bytes_load_or_raise_model_error(kind, data):
    raw = bytearray(TEXTS[kind].encode())
    op = data.draw(st.sampled_from(["truncate", "flip", "insert", "delete"]))
    pos = data.draw(st.integers(0, len(raw) - 1))
    if op == "truncate":
        raw = raw[:pos]
    elif op == "flip":
        for _ in range(data.draw(st.integers(1, 8))):
            raw[data.draw(st.integers(0, len(raw) - 1))] = data.draw(st.integers(0, 255))
    elif op == "insert":
        raw[pos:pos] = data.draw(st.binary(min_size=1, max_size=16)) if data.draw(st.booleans()) else \
            data.draw(st.text(min_size=1, max_size=8)).encode("utf-8")
    else:
        del raw[pos:pos + data.draw(st.integers(1, 64))]
    load_bytes(bytes(raw))


JSON_LEAVES = st.one_of(
    st.none(), st.booleans(),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.sampled_from([0, 1, 2, 3, 8, -1, 2**31, 2**32, 2**63, 10**30]),
    st.floats(allow_nan=False, allow_infinity=False),
    st.sampled_from([1e308, -1e308, 5e-324, 0.5, 1e-300]),
    st.text(max_size=12), st.sampled_from(["<f8", "<f4", "kes", "kes-halfdiff", "banana", "", "\u00e9\u2603\U0001f600"]),
)
JSON_VALUES = st.recursive(JSON_LEAVES, lambda inner: st.one_of(
    st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=6), inner, max_size=4)), max_leaves=12)


def _paths(node, prefix=()):
    yield prefix
    if isinstance(node, dict):
        for k, v in node.items():
            if k != "data":  # the base64 text: covered by the byte mutations
                yield from _paths(v, prefix + (k,))
    elif isinstance(node, list) and len(node) <= 8:
        for i, v in enumerate(node):
            yield from _paths(v, prefix + (i,))


PATHS = {k: [p for p in _paths(d) if p] for k, d in DOCS.items()}


@settings(max_examples=examples("json"), deadline=None, suppress_health_check=list(HealthCheck))
@given(kind=st.sampled_from(sorted(DOCS)), data=st.data())
def test_mutated_json_loads_or_raises_model_error(kind, data):
    doc = copy.deepcopy(DOCS[kind])
    for _ in range(data.draw(st.integers(1, 3))):
        path = data.draw(st.sampled_from(PATHS[kind]))
        node = doc
        try:
            for k in path[:-1]:
                node = node[k]
            if data.draw(st.integers(0, 9)) == 0 and isinstance(node, dict):
                node.pop(path[-1], None)  # a missing key
            else:
                value = data.draw(JSON_VALUES)
                if data.draw(st.integers(0, 19)) == 0:
                    value = [value]
                    for _ in range(data.draw(st.integers(MAX_DEPTH - 4, MAX_DEPTH + 40))):
                        value = [value]  # deep nesting
                node[path[-1]] = value
        except (KeyError, IndexError, TypeError):
            continue  # an earlier mutation removed the path
    text = json.dumps(doc)
    load_bytes(text.encode("utf-8"))


@settings(max_examples=examples("shape"), deadline=None, suppress_health_check=list(HealthCheck))
@given(kind=st.sampled_from(sorted(DOCS)), data=st.data())
def test_mutated_array_shapes_load_or_raise_model_error(kind, data):
    doc = copy.deepcopy(DOCS[kind])
    name = data.draw(st.sampled_from(sorted(doc["arrays"])))
    entry = doc["arrays"][name]
    dims = st.one_of(st.integers(-3, 400), st.sampled_from([2**31, 2**32, 2**62, 10**20]),
                     st.floats(allow_nan=False), st.booleans(), st.text(max_size=3))
    entry["shape"] = data.draw(st.lists(dims, max_size=6))
    if data.draw(st.booleans()):
        # data consistent with the shape when it is small: reaches the kind's checks
        try:
            n = int(np.prod([int(s) for s in entry["shape"]], dtype=object))
        except (TypeError, ValueError, OverflowError):
            n = -1
        if 0 <= n <= 100_000:
            values = data.draw(st.sampled_from([0.0, 1.0, -1.0, np.nan, np.inf, 1e308]))
            entry["data"] = base64.b64encode(np.full(n, values, "<f8").tobytes()).decode()
    load_bytes(json.dumps(doc).encode("utf-8"))


def test_a_key_with_a_newline_is_quoted_in_the_one_line_error():
    """Found by the fuzz sweep: a bad number under a key holding a newline gave a
    two-line ModelError (the key was printed raw)."""
    from kesbrdf.io.model_file import model_from_dict

    doc = copy.deepcopy(DOCS["kes"])
    doc["format_version.\n"] = 1.0000000000000002e100
    with pytest.raises(ModelError) as info:
        model_from_dict(doc)
    message = str(info.value)
    assert "\n" not in message and '"format_version.\\n"' in message, message
