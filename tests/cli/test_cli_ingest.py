"""``kesbrdf ingest`` through the real CLI: every problem case gives its one-line
message naming the manifest line and file, exit code 2, and no output file."""

import numpy as np
import pytest
from acq_helpers import SMALL_RIG, Lambertian, edit_manifest

from kesbrdf.measure.acquisition.camera import simulate_images
from kesbrdf.measure.acquisition.images import read_image, write_image
from kesbrdf.cli.main import main
from kesbrdf.io.measurement_csv import read_measurement


def _first(rows, kind):
    return next(r for r in rows if r["kind"] == kind)


def _line_of(manifest, file):
    """1-based line number of ``file``'s row in the manifest."""
    return next(i for i, ln in enumerate(manifest.read_text().splitlines(), 1) if ln.startswith(file + ","))


def run_failing(manifest, capsys, *extra):
    out = manifest.parent / "meas.csv"
    code = main(["ingest", str(manifest), "-o", str(out), *extra])
    err = capsys.readouterr().err
    assert code == 2
    assert not out.exists()
    assert not list(manifest.parent.glob(".meas.csv.*"))  # no partial file either
    lines = [ln for ln in err.splitlines() if ln.startswith("kesbrdf: error:")]
    assert len(lines) == 1, err
    return lines[0]


def test_success_writes_measurement_and_summary(small_rig, capsys):
    out = small_rig.parent / "meas.csv"
    assert main(["ingest", str(small_rig), "-o", str(out)]) == 0
    stdout = capsys.readouterr().out
    assert "used" in stdout and "wrote" in stdout
    m = read_measurement(out)
    assert len(m) == 8 and m.uncertainty is not None
    assert m.provenance["flag"] == ["ok"] * 8
    np.testing.assert_allclose(m.values, Lambertian([0.2, 0.5, 0.8])(m.wi, m.wr), rtol=0.01)


def test_saturated_frame_is_rejected_or_kept_as_lower_bound(tmp_path, capsys, lambertian_rgb):
    manifest = simulate_images(lambertian_rgb, tmp_path, exposure=0.6, **SMALL_RIG)
    message = run_failing(manifest, capsys)
    assert f"{manifest}:" in message and "sample_p0_i60_r30.tif: " in message
    assert "ROI pixels clipped (at or above code 65535)" in message and "lower-bound" in message
    out = tmp_path / "meas.csv"
    assert main(["ingest", str(manifest), "-o", str(out), "--saturation", "lower-bound", "-v"]) == 0
    assert "flagged" in capsys.readouterr().out
    assert "lower_bound" in read_measurement(out).provenance["flag"]


def test_roi_outside_the_image(small_rig, capsys):
    def widen(rows):
        _first(rows, "sample")["roi"] = "4,4,20,8"
        return rows

    edit_manifest(small_rig, widen)
    message = run_failing(small_rig, capsys)
    line = _line_of(small_rig, "sample_p0_i60_r30.tif")
    assert f"{small_rig}:{line}: sample_p0_i60_r30.tif: ROI 4,4,20,8 falls outside the 12x12 image" in message


def test_missing_dark_frame_for_an_exposure(small_rig, capsys):
    sample = next(r for r in small_rig.read_text().splitlines() if ",sample," in r)
    exposure = sample.split(",")[5]
    edit_manifest(small_rig, lambda rows: [r for r in rows if not (r["kind"] == "dark" and r["exposure_s"] == exposure)])
    message = run_failing(small_rig, capsys)
    assert f"missing dark frame: no dark frame at exposure_s={exposure}" in message
    assert message.count(str(small_rig)) == 1 and ".tif: " in message


def test_no_dark_frames_at_all(small_rig, capsys):
    edit_manifest(small_rig, lambda rows: [r for r in rows if r["kind"] != "dark"])
    message = run_failing(small_rig, capsys)
    assert f"{small_rig}: missing dark frames" in message


def test_no_white_frames(small_rig, capsys):
    edit_manifest(small_rig, lambda rows: [r for r in rows if r["kind"] != "white"])
    message = run_failing(small_rig, capsys)
    assert f"{small_rig}: missing white frames" in message


def test_image_of_another_size(small_rig, capsys):
    name = "sample_p45_i30_r60.tif"
    write_image(small_rig.parent / name, np.full((16, 12, 3), 2000, np.uint16))
    message = run_failing(small_rig, capsys)
    line = _line_of(small_rig, name)
    assert f"{small_rig}:{line}: {name}: image is 12x16x3 uint16, expected 12x12x3 uint16 as dark_" in message


def test_image_of_another_bit_depth(small_rig, capsys):
    name = "sample_p90_i60_r30.tif"
    pixels = read_image(small_rig.parent / name).pixels
    write_image(small_rig.parent / name, (pixels / 257).astype(np.uint8))
    message = run_failing(small_rig, capsys)
    assert f"{name}: image is 12x12x3 uint8, expected 12x12x3 uint16" in message


def test_manifest_row_whose_file_does_not_exist(small_rig, capsys):
    (small_rig.parent / "white_i30_r60.tif").unlink()
    message = run_failing(small_rig, capsys)
    line = _line_of(small_rig, "white_i30_r60.tif")
    assert f"{small_rig}:{line}: white_i30_r60.tif: file not found" in message


def test_value_negative_after_dark_subtraction(small_rig, capsys):
    name = "sample_p135_i30_r60.tif"
    write_image(small_rig.parent / name, np.full((12, 12, 3), 900, np.uint16))  # black level is 1024
    message = run_failing(small_rig, capsys)
    line = _line_of(small_rig, name)
    assert f"{small_rig}:{line}: {name}: value negative after dark subtraction: -1" in message
    assert "does the dark frame match?" in message


def test_rejected_frames_are_listed_on_stderr(small_rig, capsys):
    for name in ("sample_p0_i60_r30.tif", "sample_p45_i60_r30.tif"):
        (small_rig.parent / name).unlink()
    out = small_rig.parent / "meas.csv"
    assert main(["ingest", str(small_rig), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "2 rejected" in err and "sample_p45_i60_r30.tif" in err
    assert "(1 more problem in other frames)" in err


def test_malformed_manifest(small_rig, capsys):
    small_rig.write_text(small_rig.read_text().replace(",dark,", ",darkness,", 1))
    message = run_failing(small_rig, capsys)
    assert "column kind: expected one of sample, white, dark, got 'darkness'" in message


def test_missing_manifest(tmp_path, capsys):
    message = run_failing(tmp_path / "nope.csv", capsys)
    assert "nope.csv" in message


@pytest.mark.parametrize("flag", ["--quiet"])
def test_quiet_prints_nothing(small_rig, capsys, flag):
    assert main(["ingest", str(small_rig), "-o", str(small_rig.parent / "m.csv"), flag]) == 0
    assert capsys.readouterr().out == ""
