"""kesbrdf.io.text: the reading rules every text reader shares (docs/formats.md, "Reading rules").

Each rule is checked through every reader that uses it, on a small valid file that is
then broken in one way: the reader must give a FormatError naming file and line, never
another exception (the defects of issue 8: ``_csv.Error: field larger than field limit``,
``UnicodeDecodeError`` for a Latin-1 file, ``OverflowError`` for a manifest azimuth 1e306).
"""

from __future__ import annotations

import numpy as np
import pytest

from kesbrdf.measure.acquisition.manifest import read_manifest
from kesbrdf.errors import FormatError
from kesbrdf.io.curet import read_curet
from kesbrdf.io.measurement_csv import read_measurement
from kesbrdf.io.pairs_csv import read_pairs
from kesbrdf.io.text import MAX_LINE_CHARS, csv_fields, decode_text, parse_number

MEASUREMENT = "psi_deg,theta_i_deg,theta_r_deg,value\n0,60,30,0.1\n90,45,45,0.2\n"
MANIFEST = (
    "# kesbrdf-manifest: 1\n"
    "file,kind,psi_deg,theta_i_deg,theta_r_deg,phi_i_deg,phi_r_deg,exposure_s,roi\n"
    "d.tif,dark,,,,,,0.5,\n"
    "s.tif,sample,0,60,30,,,0.5,\"1,1,4,4\"\n"
)
PAIRS = "theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg\n30,0,30,180\n60,45,10,270\n"

#: reader name -> (read(path), valid text, line of the last data row)
READERS = {
    "measurement": (read_measurement, MEASUREMENT, 3),
    "manifest": (read_manifest, MANIFEST, 4),
    "pairs": (read_pairs, PAIRS, 3),
}


def _write(tmp_path, name, data: bytes):
    path = tmp_path / name
    path.write_bytes(data)
    return path


@pytest.mark.parametrize("reader", sorted(READERS))
def test_bom_crlf_and_lone_cr_are_read_like_the_plain_file(tmp_path, reader):
    read, text, _ = READERS[reader]
    plain = read(_write(tmp_path, "plain.csv", text.encode()))
    for variant in (b"\xef\xbb\xbf" + text.encode(), text.replace("\n", "\r\n").encode(), text.replace("\n", "\r").encode()):
        got = read(_write(tmp_path, "variant.csv", variant))
        if reader == "measurement":
            np.testing.assert_array_equal(got.values, plain.values)
        elif reader == "manifest":
            assert [r.line for r in got.rows] == [r.line for r in plain.rows]
        else:
            np.testing.assert_array_equal(got, plain)


@pytest.mark.parametrize("reader", sorted(READERS))
def test_latin1_bytes_name_the_line(tmp_path, reader):
    read, text, last = READERS[reader]
    data = text.encode()[:-1] + "é".encode("latin-1") + b"\n"
    path = _write(tmp_path, "latin1.csv", data)
    with pytest.raises(FormatError, match=rf"^{path}:{last}: expected UTF-8 text, got the byte 0xe9"):
        read(path)


@pytest.mark.parametrize("reader", sorted(READERS))
@pytest.mark.parametrize("length", [140_000, MAX_LINE_CHARS + 1])
def test_a_field_longer_than_the_csv_modules_limit_is_a_format_error(tmp_path, reader, length):
    read, text, last = READERS[reader]
    lines = text.splitlines()
    # the last field of the last row (value, roi, phi_r_deg) becomes one huge quoted number
    keep = {"measurement": "90,45,45", "manifest": "s.tif,sample,0,60,30,,,0.5", "pairs": "60,45,10"}[reader]
    assert lines[-1].startswith(keep)
    lines[-1] = keep + ',"' + "9" * length + '"'
    path = _write(tmp_path, "long.csv", ("\n".join(lines) + "\n").encode())
    with pytest.raises(FormatError, match=rf"^{path}:{last}: "):
        read(path)


@pytest.mark.parametrize("value", ["1e306", "1e999", "nan", "-inf", "9" * 400])
def test_a_manifest_azimuth_out_of_range_is_a_format_error(tmp_path, value):
    text = MANIFEST.replace("s.tif,sample,0,60,30,,,", f"s.tif,sample,,60,30,{value},10,")
    path = _write(tmp_path, "m.csv", text.encode())
    with pytest.raises(FormatError, match=rf"^{path}:4: column phi_i_deg: "):
        read_manifest(path)


def test_a_manifest_azimuth_beyond_a_turn_and_a_dark_rows_theta_are_range_checked(tmp_path):
    path = _write(tmp_path, "m.csv", MANIFEST.replace(",,,0.5,\"1", ",370,10,0.5,\"1").replace("s.tif,sample,0,", "s.tif,sample,,").encode())
    with pytest.raises(FormatError, match=r":4: column phi_i_deg: expected degrees in \[-360, 360\], got 370"):
        read_manifest(path)
    path = _write(tmp_path, "m.csv", MANIFEST.replace("d.tif,dark,,,", "d.tif,dark,,95,").encode())
    with pytest.raises(FormatError, match=r":3: column theta_i_deg: expected degrees in \[0, 90\], got 95"):
        read_manifest(path)


def test_radiance_ratio_at_grazing_incidence_is_refused_with_its_line(tmp_path):
    text = "# quantity: radiance_ratio\n" + MEASUREMENT.replace("90,45,45", "90,90,45")
    path = _write(tmp_path, "m.csv", text.encode())
    with pytest.raises(FormatError, match=rf"^{path}:4: column theta_i_deg: expected degrees in \[0, 90\) for quantity radiance_ratio"):
        read_measurement(path)


def test_radiance_ratio_values_are_finite_after_conversion(tmp_path):
    # the largest value at the most grazing accepted angle stays finite as f_r
    text = "# quantity: radiance_ratio\n" + MEASUREMENT.replace("90,45,45,0.2", "90,89.99999999,45,1e100")
    m = read_measurement(_write(tmp_path, "m.csv", text.encode()))
    assert np.all(np.isfinite(m.values)) and m.values[1, 0] > 1e100


@pytest.mark.parametrize("first", ["1e999", "nan", "inf", "1.5"])
def test_curet_sample_numbers_that_are_not_integers_are_format_errors(tmp_path, first):
    table = _write(tmp_path, "table.txt", b"1 0.1 0.0 0.5 3.14\n")
    abrdf = _write(tmp_path, "abrdf.dat", f"{first} 0.1\n".encode())
    with pytest.raises(FormatError, match=rf"^{abrdf}:1: "):
        read_curet(table, abrdf, 1)


def test_curet_azimuths_beyond_one_turn_are_refused(tmp_path):
    table = _write(tmp_path, "table.txt", b"1 0.1 0.0 0.5 100\n")
    abrdf = _write(tmp_path, "abrdf.dat", b"1 0.1\n")
    with pytest.raises(FormatError, match=r"table\.txt:1: phi_i: expected radians in \[-2 pi, 2 pi\]"):
        read_curet(table, abrdf, 1)


def test_primitives():
    assert decode_text(b"\xef\xbb\xbfa", "f") == "a"
    with pytest.raises(FormatError, match=r"^f:2: expected text, got a NUL"):
        decode_text(b"a\nb\x00", "f")
    assert csv_fields('1,"4,4,28,28"', "f", 1) == ["1", "4,4,28,28"]
    assert parse_number(" -0 ", "c", "f", 1) == 0.0
    assert parse_number("", "c", "f", 1, empty=-1.0) == -1.0
    for bad in ("", "1e101", "0x10", "nan"):
        with pytest.raises(FormatError, match=r"^f:1: column c: expected"):
            parse_number(bad, "c", "f", 1)
