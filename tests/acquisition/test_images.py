"""Frame I/O: lossless round trips, the 16-bit colour PNG trap, bad files."""

import struct
import zlib

import numpy as np
import pytest

from kesbrdf.measure.acquisition.images import linearize, read_image, sha256_file, write_image
from kesbrdf.measure.acquisition.sensor import srgb_encode
from kesbrdf.errors import FormatError


@pytest.mark.parametrize(
    "name, dtype, shape",
    [
        ("g8.png", np.uint8, (6, 7)),
        ("rgb8.png", np.uint8, (6, 7, 3)),
        ("g16.png", np.uint16, (6, 7)),
        ("rgb16.tif", np.uint16, (6, 7, 3)),
        ("g16.tif", np.uint16, (6, 7)),
        ("rgb.exr", np.float32, (6, 7, 3)),
        ("y.exr", np.float32, (6, 7)),
    ],
)
def test_round_trip_is_lossless(tmp_path, rng, name, dtype, shape):
    if np.issubdtype(dtype, np.integer):
        pixels = rng.integers(0, np.iinfo(dtype).max, size=shape, endpoint=True).astype(dtype)
    else:
        pixels = rng.random(shape).astype(dtype)
    write_image(tmp_path / name, pixels)
    frame = read_image(tmp_path / name)
    expected = pixels if pixels.ndim == 3 else pixels[..., None]
    np.testing.assert_array_equal(frame.pixels, expected.astype(float))
    assert frame.dtype == np.dtype(dtype).name
    assert frame.max_code == (None if dtype == np.float32 else float(np.iinfo(dtype).max))


def _png_rgb16(path, pixels):
    """A minimal 16-bit RGB PNG written by hand (Pillow cannot write one)."""
    h, w, _ = pixels.shape
    raw = b"".join(b"\x00" + pixels[y].astype(">u2").tobytes() for y in range(h))

    def chunk(tag, data):
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data))

    ihdr = struct.pack(">IIBBBBB", w, h, 16, 2, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


def test_16bit_colour_png_is_refused_not_truncated(tmp_path):
    path = tmp_path / "rgb16.png"
    _png_rgb16(path, np.full((4, 4, 3), 40000, np.uint16))
    with pytest.raises(FormatError, match=r"rgb16\.png: 16-bit colour PNG .* TIFF"):
        read_image(path)


def test_writer_refuses_16bit_colour_png(tmp_path):
    with pytest.raises(FormatError, match="use .tif"):
        write_image(tmp_path / "x.png", np.zeros((4, 4, 3), np.uint16))


def test_corrupt_and_unknown_files(tmp_path):
    bad = tmp_path / "bad.tif"
    bad.write_bytes(b"not a tiff at all")
    with pytest.raises(FormatError, match=r"bad\.tif: cannot read image"):
        read_image(bad)
    with pytest.raises(FormatError, match=r"expected an image with suffix"):
        read_image(tmp_path / "frame.jpg")
    with pytest.raises(FileNotFoundError):
        read_image(tmp_path / "missing.png")


def test_alpha_is_dropped(tmp_path):
    write_image(tmp_path / "rgba.png", np.full((3, 3, 4), 9, np.uint8))
    assert read_image(tmp_path / "rgba.png").shape == (3, 3, 3)


def test_srgb_linearisation_recovers_linear_codes(tmp_path):
    linear = np.linspace(0, 1, 256)
    codes = np.rint(srgb_encode(linear) * 65535).astype(np.uint16).reshape(16, 16)
    write_image(tmp_path / "s.png", codes)
    frame = read_image(tmp_path / "s.png")
    # one 16-bit code of the encoded signal is at most 1/(12.92·65535) in linear units
    np.testing.assert_allclose(linearize(frame, "srgb").ravel() / 65535, linear, atol=2e-5)
    np.testing.assert_array_equal(linearize(frame, "linear"), frame.pixels)


def test_sha256_of_file(tmp_path):
    p = tmp_path / "x.bin"
    p.write_bytes(b"abc")
    assert sha256_file(p) == "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
