"""Manifest parsing: good files parse, every format problem names file:line."""

import math

import pytest

from kesbrdf.measure.acquisition.manifest import format_manifest, parse_manifest, read_manifest
from kesbrdf.errors import FormatError

GOOD = """# kesbrdf-manifest: 1
# sample: test cloth
# white_reflectance: 0.98
# response: srgb
# operator: someone
file,kind,psi_deg,theta_i_deg,theta_r_deg,exposure_s,roi
d.png,dark,,,,0.01,
w.png,white,,60,30,0.01,"1,2,9,10"
s.png,sample,45,60,30,0.01,1 2 9 10
g.png,sample,,60,30,0.02,
"""


def test_good_manifest_parses(tmp_path):
    m = parse_manifest(GOOD.replace("g.png,sample,,60,30,0.02,", "g.png,sample,90,60,30,0.02,"), tmp_path / "m.csv")
    assert m.white_reflectance == 0.98
    assert m.response == "srgb"
    assert m.header["operator"] == "someone"
    assert [r.kind for r in m.rows] == ["dark", "white", "sample", "sample"]
    assert m.rows[1].roi == (1, 2, 9, 10) and m.rows[2].roi == (1, 2, 9, 10)
    assert m.rows[2].path == tmp_path / "s.png"
    assert m.rows[2].line == 9
    assert math.isnan(m.rows[0].theta_i_deg)


def test_general_geometry_rows(tmp_path):
    text = GOOD.replace("exposure_s,roi", "exposure_s,roi,phi_i_deg,phi_r_deg")
    text = "\n".join(ln + ("," if ln and not ln.startswith(("#", "file")) else "") for ln in text.splitlines())
    text = text.replace("g.png,sample,,60,30,0.02,,", "g.png,sample,,60,30,0.02,,10,200")
    text = text.replace("d.png,dark,,,,0.01,,", "d.png,dark,,,,0.01,,,")
    text = text.replace('w.png,white,,60,30,0.01,"1,2,9,10",', 'w.png,white,,60,30,0.01,"1,2,9,10",,')
    text = text.replace("s.png,sample,45,60,30,0.01,1 2 9 10,", "s.png,sample,45,60,30,0.01,1 2 9 10,,")
    m = parse_manifest(text, tmp_path / "m.csv")
    assert m.rows[3].is_general and not m.rows[2].is_general


@pytest.mark.parametrize(
    "old, new, line, message",
    [
        ("exposure_s,roi", "exposure_s,roi,colour", 6, "unknown column 'colour'"),
        ("file,kind,", "file,type,", 6, "unknown column 'type'"),
        ("d.png,dark", "d.png,flat", 7, "column kind: expected one of sample, white, dark"),
        ("s.png,sample,45,60,30,0.01", "s.png,sample,45,sixty,30,0.01", 9, "column theta_i_deg: expected a number"),
        ("d.png,dark,,,,0.01", "d.png,dark,,,,-1", 7, "exposure_s: expected a positive time"),
        ('"1,2,9,10"', '"1,2,9"', 8, "roi: expected four integers"),
        ('"1,2,9,10"', '"9,2,1,10"', 8, "expected x1 > x0"),
        ("s.png,sample,45,60", "s.png,sample,45,95", 9, "theta_i_deg: expected degrees in [0, 90)"),
        ("s.png,sample,45,", "s.png,sample,200,", 9, "psi_deg: expected degrees in [0, 180)"),
        ("w.png,white,,60", "w.png,white,,", 8, "theta_i_deg: expected an angle for a white frame"),
        ("# white_reflectance: 0.98", "# white_reflectance: 1.5", 3, "white_reflectance: expected a reflectance factor in (0, 1]"),
        ("# response: srgb", "# response: gamma2", 4, "response: expected one of linear, srgb"),
        ("g.png,sample,,60,30,0.02,", "g.png,sample,45,60,30,0.02,", 10, "duplicate sample geometry, already on line 9"),
        ("g.png,sample,,60,30,0.02,", "g.png,sample,,60,30,0.02", 10, "expected 7 fields, got 6"),
    ],
)
def test_format_problems_name_file_and_line(tmp_path, old, new, line, message):
    assert old in GOOD
    path = tmp_path / "scan.csv"
    path.write_text(GOOD.replace(old, new, 1))
    with pytest.raises(FormatError) as info:
        read_manifest(path)
    text = str(info.value)
    assert text.startswith(f"{path}:{line}: "), text
    assert message in text
    assert "\n" not in text


def test_sample_needs_psi_or_azimuths(tmp_path):
    path = tmp_path / "m.csv"
    path.write_text(GOOD)  # g.png has neither psi nor phi
    with pytest.raises(FormatError, match=r"m\.csv:10: sample frame: expected psi_deg"):
        read_manifest(path)


def test_white_reflectance_is_required_with_white_frames(tmp_path):
    path = tmp_path / "m.csv"
    path.write_text(GOOD.replace("# white_reflectance: 0.98\n", "").replace("g.png,sample,,", "g.png,sample,90,"))
    with pytest.raises(FormatError, match=r"m\.csv: missing header line '# white_reflectance: R'"):
        read_manifest(path)


def test_empty_manifest_is_refused(tmp_path):
    path = tmp_path / "m.csv"
    path.write_text("# white_reflectance: 0.9\nfile,kind,exposure_s\n")
    with pytest.raises(FormatError, match="expected at least one frame row"):
        read_manifest(path)


def test_format_then_parse_round_trip(tmp_path):
    rows = [
        dict(file="d.tif", kind="dark", exposure_s=0.5),
        dict(file="s.tif", kind="sample", psi_deg=135.0, theta_i_deg=87.0, theta_r_deg=3.0, exposure_s=0.5, roi=(2, 2, 8, 8)),
    ]
    text = format_manifest({"sample": "x", "white_reflectance": 0.99}, rows)
    m = parse_manifest(text, tmp_path / "m.csv")
    assert m.header["kesbrdf-manifest"] == 1
    assert (m.rows[1].psi_deg, m.rows[1].theta_i_deg, m.rows[1].roi) == (135.0, 87.0, (2, 2, 8, 8))
