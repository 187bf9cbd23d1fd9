"""Hostile model files are refused in one line by eval, export and validate (project issue
16, item 7): values past the readers' bound (1e308), NaN, an overflowing JSON number,
arrays past the size limit, files past the size limit; and every export format refuses a
model whose values it cannot hold (1e50 fits a model file but not float32).
"""

from __future__ import annotations

import base64
import json

import numpy as np
import pytest

from kesbrdf.cli.main import main
from kesbrdf.io.model_file import MAX_ARRAY_ELEMENTS, MAX_FILE_BYTES
from kesbrdf.io.text import MAX_ABS_NUMBER


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    """A measurement, a valid kes model file (small grid) and a pairs file."""
    from kesbrdf.measure.gonio import measure
    from kesbrdf.io.measurement_csv import write_measurement
    from kesbrdf.models.kes import fit
    from kesbrdf.references.ward import AnisotropicWard

    d = tmp_path_factory.mktemp("hostile")
    m = measure(AnisotropicWard(0.15, 0.3, rho_d=[0.1, 0.2, 0.3], rho_s=0.1))
    write_measurement(d / "meas.csv", m)
    fit(m, n_phi=16, gamma_step=np.radians(6.0)).save(d / "model.kes.json")
    (d / "pairs.csv").write_text("theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg\n60,180,30,0\n89.9,0,89.9,180\n")
    return d


def _with_value(doc: dict, array: str, value: float, index: int = 0) -> dict:
    entry = doc["arrays"][array]
    a = np.frombuffer(base64.b64decode(entry["data"]), "<f8").copy()
    a[index] = value
    entry["data"] = base64.b64encode(a.tobytes()).decode("ascii")
    return doc


def hostile(base, case: str):
    """Write the hostile variant ``case`` of the base model; return (path, words the error must hold)."""
    doc = json.loads((base / "model.kes.json").read_text())
    path = base / f"{case}.kes.json"
    if case == "table 1e308":
        _with_value(doc, "table", 1e308, 7)
        words = ("'table'", "at most 1e100", "1e+308")
    elif case == "body 1e101":
        _with_value(doc, "body", 1e101)
        words = ("'body'", "at most 1e100")
    elif case == "table nan":
        _with_value(doc, "table", float("nan"), 7)
        words = ("table", "nan")
    elif case == "q_nodes -inf":
        _with_value(doc, "q_nodes", -float("inf"))
        words = ("'q_nodes'", "-inf")
    elif case == "field 1e999":
        doc["parameters"]["noise_floor"] = 1.0
        text = json.dumps(doc).replace('"noise_floor": 1.0', '"noise_floor": 1e999')
        path.write_text(text)
        return path, ("parameters.noise_floor", "overflows a double")
    elif case == "field 1e200":
        doc["diagnostics"]["x"] = [0, 1e200]
        words = ("diagnostics.x[1]", "at most 1e100", "1e+200")
    elif case == "huge array":
        doc["arrays"]["table"]["shape"] = [REPORTED_ELEMENTS]
        words = ("'table'", f"at most {MAX_ARRAY_ELEMENTS} elements")
    elif case == "huge file":
        with open(path, "wb") as fh:  # sparse: no disk space used
            fh.truncate(REPORTED_BYTES)
        return path, ("at most", str(MAX_FILE_BYTES), "bytes")
    else:
        raise KeyError(case)
    path.write_text(json.dumps(doc))
    return path, words


#: The hostile report's model file: 230 MB, i.e. about 21 million doubles in base64; it
#: was accepted and took 1.1 GB to evaluate.  Both sizes are past the stated limits.
REPORTED_BYTES = 230_000_000
REPORTED_ELEMENTS = 21_000_000


def test_the_limits_refuse_the_reported_file():
    """The stated limits (docs/formats.md) are below the reported file, and above the
    largest table kesbrdf fits: a 1° kes-halfdiff, 360 × 91 × 91 × 3 values."""
    assert REPORTED_BYTES > MAX_FILE_BYTES and REPORTED_ELEMENTS > MAX_ARRAY_ELEMENTS
    largest = 360 * 91 * 91 * 3
    assert largest <= MAX_ARRAY_ELEMENTS and 4 * (8 * largest) // 3 < MAX_FILE_BYTES

CASES = ("table 1e308", "body 1e101", "table nan", "q_nodes -inf", "field 1e999", "field 1e200", "huge array",
         "huge file")


def argv(command: str, model, base, out):
    if command == "eval":
        return ["eval", str(model), "--pairs", str(base / "pairs.csv"), "-o", str(out / "f.csv")]
    if command == "export":
        return ["export", str(model), "--format", "brdf-explorer", "-o", str(out / "m.brdf")]
    if command == "render":  # the model is refused before "rendering ..." is printed (one line in all)
        return ["render", str(model), "-o", str(out / "r.png"), "--spp", "1", "--resolution", "16x12"]
    return ["validate", str(model), str(base / "meas.csv"), "--json", str(out / "v.json")]


@pytest.mark.parametrize("case", CASES)
@pytest.mark.parametrize("command", ("eval", "export", "validate", "render"))
def test_hostile_model_is_refused_in_one_line(base, tmp_path, capsys, command, case):
    model, words = hostile(base, case)
    capsys.readouterr()
    assert main(argv(command, model, base, tmp_path)) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err, err
    assert err.startswith(f"kesbrdf: error: {model}: ")
    for w in words:
        assert w in err, (w, err)
    assert list(tmp_path.iterdir()) == []


def test_the_bound_is_the_csv_readers(base, tmp_path):
    """1e100 itself loads and evaluates to finite values at grazing angles (the bound is
    shared with the CSV readers, kesbrdf.io.text.MAX_ABS_NUMBER)."""
    assert MAX_ABS_NUMBER == 1e100
    doc = _with_value(json.loads((base / "model.kes.json").read_text()), "table", MAX_ABS_NUMBER)
    (tmp_path / "m.kes.json").write_text(json.dumps(doc))
    assert main(argv("eval", tmp_path / "m.kes.json", base, tmp_path)) == 0
    values = np.loadtxt(tmp_path / "f.csv", delimiter=",", skiprows=1)
    assert np.all(np.isfinite(values))


FORMATS = ("rgl-bsdf", "rgl-bsdf-spectral", "mitsuba-scene", "gltf", "glb", "mtlx", "usd", "brdf-explorer")
#: f_r of a table value v reaches v / COS_EPS = v * 1e6 at grazing angles: 1e33 overflows
#: float32 (3.4e38) there, 1e31 does not.
PAST_FLOAT32, WITHIN_FLOAT32 = 1e33, 1e31


@pytest.mark.parametrize("fmt", FORMATS)
def test_every_export_refuses_values_past_its_range_in_one_line(base, tmp_path, fmt):
    from kesbrdf.errors import ExportError
    from kesbrdf.export import FORMATS as KNOWN
    from kesbrdf.export import export, format_module
    from kesbrdf.io.model_file import model_from_dict

    assert fmt in KNOWN
    module = format_module(fmt)
    model = model_from_dict(_with_value(json.loads((base / "model.kes.json").read_text()), "table", PAST_FLOAT32))
    out = tmp_path / f"m{module.EXTENSIONS[0]}"
    with pytest.raises(ExportError) as info:
        export(model, fmt, out)
    message = str(info.value)
    assert "\n" not in message and message.startswith(f"{fmt}: cannot export") and "'table'" in message
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("value", (1e308, float("inf"), float("nan")))
def test_export_refuses_an_in_memory_model_no_file_could_hold(base, tmp_path, value):
    """The Python API: a model built in memory with 1e308 / inf / NaN is refused like a file."""
    from kesbrdf.errors import ExportError
    from kesbrdf.export import export
    from kesbrdf.io.model_file import load_model as load

    model = load(base / "model.kes.json")
    model.table[1, 1, 0] = value
    with pytest.raises(ExportError, match="gltf: cannot export the model: .*table"):
        export(model, "gltf", tmp_path / "m.gltf")
    assert list(tmp_path.iterdir()) == []


def test_export_accepts_values_within_float32(base, tmp_path):
    from kesbrdf.export._framework import check_values
    from kesbrdf.io.model_file import model_from_dict

    model = model_from_dict(_with_value(json.loads((base / "model.kes.json").read_text()), "table", WITHIN_FLOAT32))
    check_values(model, "rgl-bsdf")  # no error


def test_tensor_files_refuse_non_finite_fields(tmp_path):
    from kesbrdf.errors import ExportError
    from kesbrdf.io.tensor_file import write_tensor_file

    with pytest.raises(ExportError, match="field 'rgb'.*1 NaN or inf"):
        write_tensor_file(tmp_path / "t.bsdf", {"rgb": np.array([1.0, np.inf], np.float32)})
    assert list(tmp_path.iterdir()) == []
