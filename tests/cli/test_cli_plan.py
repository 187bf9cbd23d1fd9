"""``kesbrdf plan`` through the real CLI: bad input gives one line and exit 2."""

from __future__ import annotations

import subprocess
import sys

import pytest


def _run(*args, cwd):
    return subprocess.run([sys.executable, "-m", "kesbrdf.cli.main", *args], capture_output=True, text=True, cwd=cwd)


def test_plan_rejects_bad_output_suffix_before_work(tmp_path):
    r = _run("plan", "--reference", "ward", "-o", str(tmp_path / "plan.txt"), cwd=tmp_path)
    assert r.returncode == 2
    assert "expected a file ending in .json" in r.stderr
    assert "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "plan.txt").exists()


def test_plan_needs_a_truth(tmp_path):
    r = _run("plan", "-o", str(tmp_path / "plan.json"), cwd=tmp_path)
    assert r.returncode == 2
    assert "expected --reference" in r.stderr


def test_plan_unknown_reference_lists_names(tmp_path):
    r = _run("plan", "--reference", "banana", "-o", str(tmp_path / "plan.json"), cwd=tmp_path)
    assert r.returncode == 2
    assert "banana" in r.stderr and "ward" in r.stderr


# -- carrying out a plan: plan.json's geometries, simulate --plan / --extras --------------

import json  # noqa: E402

import numpy as np  # noqa: E402

#: Plan angles are degrees rounded to 1e-9° in plan.json and in the CSV (1.7e-11 rad);
#: "the same angles" is held to the brief's 1e-9 (rad).
ANGLE_TOL_RAD = 1e-9


def _env_run(*args, cwd):
    r = _run(*args, cwd=cwd)
    assert "Traceback" not in r.stderr, r.stderr
    return r


def test_plan_geometries_round_trip_into_simulate_plan(tmp_path):
    """`kesbrdf plan` then `kesbrdf simulate --plan`: the CSV holds exactly the rows the
    planner scored for the protocol (same count, same angles), for the recommended
    protocol and for a named one with out-of-plane pairs."""
    from kesbrdf.io.measurement_csv import read_measurement
    from kesbrdf.measure import planning
    from kesbrdf.references.registry import make_reference

    plan = tmp_path / "plan.json"
    r = _env_run("plan", "--reference", "ward", "--budget", "240", "-o", str(plan), cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    doc = json.loads(plan.read_text())
    for protocol, flags in ((None, ()), ("paper+out-of-plane", ("--plan-protocol", "paper+out-of-plane"))):
        entry = doc["recommended"] if protocol is None else doc["protocols"][protocol]
        scored = planning.simulate(make_reference("ward"), entry["groups"])  # the rows expected_error fitted
        out = tmp_path / f"{protocol or 'recommended'}.csv"
        r = _env_run("simulate", "--reference", "ward", "--plan", str(plan), *flags, "-o", str(out), cwd=tmp_path)
        assert r.returncode == 0, r.stderr
        m = read_measurement(out)
        assert len(m) == len(scored) == entry["n_samples"] == len(entry["samples"])
        for name in ("theta_i", "phi_i", "theta_r", "phi_r"):
            assert np.max(np.abs(getattr(m, name) - getattr(scored, name))) < ANGLE_TOL_RAD, name
        assert np.array_equal(np.isnan(m.psi), np.isnan(scored.psi))
        assert np.allclose(m.values, scored.values, rtol=1e-12, atol=0)  # noise-free: the truth at those rows
    assert np.count_nonzero(np.isnan(m.psi)) == 8  # oop:30 and oop:60 at four orientations


def test_simulate_plan_refuses_protocol_options(tmp_path):
    plan = tmp_path / "plan.json"
    plan.write_text(json.dumps({"protocols": {}, "recommended": {"groups": ["paper"], "samples": []}}))
    r = _env_run("simulate", "--plan", str(plan), "--protocol", "dense", "-o", str(tmp_path / "m.csv"), cwd=tmp_path)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    assert r.stderr.strip() == ("kesbrdf: error: --plan: the plan's samples carry their own geometries; expected no "
                                "--protocol, --step-deg or --orientations-deg with it, got --protocol dense")


@pytest.mark.parametrize("extras, got", [("line:30,oops:3", "'oops:3'"), ("line:95", "'line:95'"), ("oop:", "'oop:'")])
def test_simulate_extras_bad_name_is_one_line_and_exit_2(tmp_path, extras, got):
    out = tmp_path / "m.csv"
    r = _env_run("simulate", "--reference", "ward", "--extras", extras, "-o", str(out), cwd=tmp_path)
    assert r.returncode == 2
    assert r.stderr.strip() == ("kesbrdf: error: --extras: sample group: expected paper, dense, specular:T, line:T or "
                                f"oop:T with 0 <= T < 90 deg, got {got}")
    assert not out.exists()


@pytest.mark.slow  # a whole default fit with its prior comparison: ~9 s here
def test_simulate_extras_then_fit(tmp_path):
    """The trial's two commands: paper + one out-of-plane group, then the default fit."""
    from kesbrdf.io.measurement_csv import read_measurement
    from kesbrdf.measure import planning

    csv = tmp_path / "m.csv"
    r = _env_run("simulate", "--reference", "sadeghi-black-satin", "--extras", "oop:30", "-o", str(csv), cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    m = read_measurement(csv)
    want = planning.protocol_samples(("paper", "oop:30"))
    assert len(m) == len(want) == 120 and np.count_nonzero(np.isnan(m.psi)) == 4
    for name in ("theta_i", "phi_i", "theta_r", "phi_r"):
        assert np.max(np.abs(getattr(m, name) - getattr(want, name))) < ANGLE_TOL_RAD, name
    model = tmp_path / "m.kes.json"
    r = _env_run("fit", str(csv), "-o", str(model), cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    report = json.loads(model.read_text())["diagnostics"]["fit_report"]
    assert report["rows_total"] == 120


def test_simulate_irawan_preset(tmp_path):
    """`--reference irawan-<preset>`: the Irawan-Marschner weave itself at the paper's rows."""
    from kesbrdf.io.measurement_csv import read_measurement
    from kesbrdf.references.irawan2012 import PRESET_NAMES, Irawan2012
    from kesbrdf.references.registry import IRAWAN_PRESETS, IRAWAN_REFERENCES, REFERENCES

    assert IRAWAN_PRESETS == PRESET_NAMES and set(IRAWAN_REFERENCES) <= set(REFERENCES)
    out = tmp_path / "denim.csv"
    r = _env_run("simulate", "--reference", "irawan-cotton-denim", "-o", str(out), cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    m = read_measurement(out)
    assert len(m) == 116 and m.channels == ("R", "G", "B")
    assert np.allclose(m.values, Irawan2012("cotton_denim")(m.wi, m.wr), rtol=1e-12, atol=0)
    help_text = _run("simulate", "--help", cwd=tmp_path).stdout
    listed = "".join(help_text.split())  # argparse wraps the list at hyphens
    assert all(f"{name}," in listed for name in IRAWAN_REFERENCES)
    r = _env_run("simulate", "--reference", "irawan-cotton-denim", "--params", '{"beta": 2}', "-o", str(out),
                 cwd=tmp_path)
    assert r.returncode == 2 and "unknown parameter 'beta' of reference irawan-cotton-denim; it takes none" in r.stderr
