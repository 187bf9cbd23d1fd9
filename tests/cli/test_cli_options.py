"""Every CLI option either works or gives one line on stderr and exit 2, before any long work."""

from __future__ import annotations

import time

import pytest

from kesbrdf.cli.main import main

EXIT_USER_ERROR = 2
#: A refused option must answer at once: no render, fit or plot may start first (s; the
#: slowest legitimate work before the check is importing numpy-level modules).
FAST_S = 10.0


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    from kesbrdf.measure.gonio import measure
    from kesbrdf.io.measurement_csv import write_measurement
    from kesbrdf.models.kes import fit
    from kesbrdf.references.ward import AnisotropicWard

    d = tmp_path_factory.mktemp("options")
    m = measure(AnisotropicWard(0.1, 0.25, rho_d=0.1, rho_s=0.1))
    write_measurement(d / "m.csv", m)
    fit(m).save(d / "m.kes.json")
    header = b"theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg\n"
    (d / "latin1.csv").write_bytes(header + b"30,0,30,180 \xe9\n")
    (d / "bom_crlf.csv").write_bytes(b"\xef\xbb\xbf" + header.replace(b"\n", b"\r\n") + b"30,0,30,180\r\n")
    (d / "azimuth.csv").write_bytes(header + b"30,1e6,30,180\n")
    return d


CASES = [
    (["render", "{d}/m.kes.json", "-o", "{t}/x.tiff"], "-o {t}/x.tiff: expected a file ending in .png, .jpg, .jpeg, .exr"),
    (["render", "{d}/m.kes.json", "-o", "{t}/x.mp4"], "video output needs --animation"),
    (["colourways", "{d}/m.kes.json", "-o", "{t}/x.jpg"], "expected a file ending in .png"),
    (["colourways", "{d}/m.kes.json", "-o", "{t}/x.png", "--columns", "0"], "--columns: expected tiles per row >= 1"),
    (["simulate", "-o", "{t}/s.txt"], "-o {t}/s.txt: expected a file ending in .csv"),
    (["simulate", "-o", "{t}/s.csv", "--params", "{{"], "--params: expected a JSON object"),
    (["simulate", "-o", "{t}/s.csv", "--params", "[1]"], "--params: expected a JSON object of parameter names"),
    (["simulate", "-o", "{t}/s.csv", "--params", '{{"alpha": 1}}'], "unknown parameter 'alpha' of reference satin-ward"),
    (["simulate", "-o", "{t}/s.csv", "--params", '{{"alpha_x": "0.1"}}'], "alpha_x (reference satin-ward): expected a number in [0.0001, 1]"),
    (["simulate", "-o", "{t}/s.csv", "--params", '{{"alpha_x": 5}}'], "expected a number in [0.0001, 1], got 5"),
    # found by the fuzz sweep: a lobe this narrow evaluated to NaN
    (["simulate", "-o", "{t}/s.csv", "--params", '{{"alpha_x": 1e-301}}'], "expected a number in [0.0001, 1], got 1e-301"),
    (["simulate", "-o", "{t}/s.csv", "--params", '{{"alpha_x": NaN}}'], "--params: expected finite numbers, got NaN"),
    (["simulate", "-o", "{t}/s.csv", "--params", '{{"rho_s": [0.1, 0.2]}}'], "--params for reference satin-ward"),
    (["simulate", "-o", "{t}/s.csv", "--reference", "sadeghi-satin", "--params", '{{"n_samples": 2.5}}'],
     "n_samples (reference sadeghi-satin): expected an integer in [1, 1024]"),
    (["simulate", "-o", "{t}/s.csv", "--step-deg", "1e-9"], "step_deg: expected a step that divides 90 deg, at least 0.5"),
    (["simulate", "-o", "{t}/s.csv", "--step-deg", "nan"], "step_deg: expected a step"),
    (["simulate", "-o", "{t}/s.csv", "--noise", "nan"], "noise: expected a finite number >= 0"),
    (["simulate", "-o", "{t}/s.csv", "--noise-floor", "-1"], "noise_floor: expected a finite number >= 0"),
    (["simulate", "-o", "{t}/s.csv", "--seed", "-1", "--noise", "0.1"], "--seed: expected an integer >= 0"),
    (["simulate", "-o", "{t}/s.csv", "--orientations-deg", "0,0"], "orientations_deg: expected distinct orientations"),
    (["simulate", "-o", "{t}/s.csv", "--orientations-deg", "0,45,1e308"], "orientations_deg: expected 1 to 360 orientations"),
    (["simulate", "-o", "{t}/s.csv", "--vignetting", "0.2"], "--vignetting: applies to camera frames only"),
    (["eval", "{d}/m.kes.json", "--pairs", "{d}/latin1.csv", "-o", "{t}/o.csv"], "{d}/latin1.csv:2: expected UTF-8 text, got the byte 0xe9"),
    (["eval", "{d}/m.kes.json", "--pairs", "{d}/azimuth.csv", "-o", "{t}/o.csv"], "{d}/azimuth.csv:2: column phi_i_deg: expected degrees in [-360, 360]"),
    (["eval", "{d}/m.kes.json", "--pairs", "{d}/bom_crlf.csv", "-o", "{t}/o.txt"], "expected a file ending in .csv"),
    (["validate", "{d}/m.kes.json", "{d}/m.csv", "--json", "{t}/v.txt"], "--json {t}/v.txt: expected a file ending in .json"),
    (["ingest", "{d}/missing.csv", "-o", "{t}/x.txt"], "expected a file ending in .csv"),
    (["view", "{d}/m.kes.json", "--no-browser", "--max-upload-mb", "nan"], "--max-upload-mb: expected a positive size"),
    (["plot", "{d}/m.kes.json", "--figure", "5", "-o", "{t}/a.png", "--dpi", "0"], "--dpi: expected a resolution in [10, 1200]"),
    (["plot", "{d}/m.kes.json", "--figure", "4", "-o", "{t}/a.png", "--gamma-deg", "nan"], "--gamma-deg: expected values in (-90, 90)"),
    (["report", "{d}/m.kes.json", "-o", "{t}/r.html", "--figures-dir", "{d}/m.csv"], "--figures-dir"),
]


@pytest.mark.parametrize("argv, message", CASES, ids=[f"{c[0][0]}-{k}" for k, c in enumerate(CASES)])
def test_bad_option_is_one_line_exit_2_before_any_work(files, tmp_path, capsys, argv, message):
    fill = {"d": files, "t": tmp_path}
    t0 = time.perf_counter()
    rc = main([a.format(**fill) for a in argv])
    elapsed = time.perf_counter() - t0
    err = capsys.readouterr().err
    assert rc == EXIT_USER_ERROR, err
    assert err.startswith("kesbrdf: error: ") and err.count("\n") == 1 and "Traceback" not in err
    assert message.format(**fill) in err
    assert elapsed < FAST_S
    assert list(tmp_path.iterdir()) == []  # nothing written


def test_pairs_file_with_bom_and_crlf_is_read(files, tmp_path):
    out = tmp_path / "o.csv"
    assert main(["eval", str(files / "m.kes.json"), "--pairs", str(files / "bom_crlf.csv"), "-o", str(out)]) == 0
    lines = out.read_text().splitlines()
    assert lines[0].startswith("theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg") and len(lines) == 2
