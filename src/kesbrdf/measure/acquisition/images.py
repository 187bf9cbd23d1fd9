"""Reading and writing camera frames: 8/16-bit PNG and TIFF, OpenEXR.

Readers go through maintained libraries: Pillow (via imageio) for PNG, tifffile for
TIFF, the OpenEXR bindings for EXR.  A frame comes back as a :class:`Frame` holding
the stored code values as float64 of shape (H, W, C) plus what is needed to check
it against other frames (dtype, bit depth) and to detect clipping (the largest code).

One trap is caught here: Pillow reads a 16-bit *colour* PNG silently as 8 bits (it
has no 48/64-bit RGB mode), which would corrupt every value.  Such files are refused
with a message that says to store 16-bit colour frames as TIFF (16-bit greyscale PNG
is read exactly).

Linearisation (:func:`linearize`) turns stored code values into values proportional
to the sensor signal: ``"linear"`` leaves them alone, ``"srgb"`` inverts the sRGB
transfer function on ``code / max_code``.  OpenEXR frames are linear floats.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from kesbrdf._atomic import atomic_path
from kesbrdf.measure.acquisition.sensor import RESPONSES, srgb_decode
from kesbrdf.errors import FormatError, validate_choice, where
from kesbrdf.io.files import open_regular, sha256_file  # noqa: F401  (sha256_file re-exported)

__all__ = [
    "Frame",
    "read_image",
    "write_image",
    "linearize",
    "sha256_file",
    "IMAGE_SUFFIXES",
]

#: File name suffixes the reader understands.
IMAGE_SUFFIXES = (".png", ".tif", ".tiff", ".exr")

#: Largest frame accepted (pixels), checked from the file's header before decoding: a
#: 100-megapixel camera frame.  A corrupt header declaring a huge size would otherwise
#: make the decoder allocate gigabytes.
MAX_IMAGE_PIXELS = 100_000_000

_EXTRA = "install kesbrdf[images]"


@dataclass
class Frame:
    """One camera frame.

    Attributes
    ----------
    pixels : ndarray, shape (H, W, C)
        Stored code values in their stored type (uint8/uint16 for PNG/TIFF, float for
        EXR; not converted, so that large frames stay small in memory).  Alpha dropped.
    dtype : str
        Storage type: ``uint8``, ``uint16``, ``float16`` or ``float32``.
    max_code : float or None
        Largest storable code (255 or 65535) for integer frames; None for floats.
    path : Path
    """

    pixels: np.ndarray
    dtype: str
    max_code: float | None
    path: Path

    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(self.pixels.shape)  # type: ignore[return-value]

    @property
    def description(self) -> str:
        """``"32x32x3 uint16"``: size and bit depth, as messages show them."""
        h, w, c = self.pixels.shape
        return f"{w}x{h}x{c} {self.dtype}"


def _as_hwc(array: np.ndarray, path: Path) -> np.ndarray:
    if array.ndim == 2:
        array = array[..., None]
    if array.ndim != 3 or array.shape[-1] not in (1, 2, 3, 4):
        raise FormatError(f"{where(path)}expected a grey, RGB or RGBA image, got an array of shape {array.shape}")
    if array.shape[-1] in (2, 4):  # drop alpha
        array = array[..., :-1]
    return array


def _png_ihdr(path: Path) -> tuple[int, int]:
    """(bit depth, colour type) from a PNG's IHDR chunk; the declared size is checked."""
    with open_regular(path) as fh:
        head = fh.read(33)
    if len(head) < 26 or head[:8] != b"\x89PNG\r\n\x1a\n":
        raise FormatError(f"{where(path)}expected a PNG file, got bytes that do not start with the PNG signature")
    width, height = int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")
    _check_pixels(path, width * height, f"{width}x{height}")
    return head[24], head[25]


def _check_pixels(path: Path, pixels: int, size: str) -> None:
    if pixels > MAX_IMAGE_PIXELS:
        raise FormatError(f"{where(path)}expected a frame of at most {MAX_IMAGE_PIXELS} pixels, got {size}")


def _read_png(path: Path) -> np.ndarray:
    bit_depth, colour_type = _png_ihdr(path)
    if bit_depth == 16 and colour_type in (2, 6):
        raise FormatError(
            f"{where(path)}16-bit colour PNG cannot be read without loss (Pillow reduces it to 8 bits); "
            "expected 8-bit PNG, 16-bit greyscale PNG, or store 16-bit colour frames as TIFF"
        )
    try:
        import imageio.v3 as iio
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError(f"reading PNG needs imageio: {_EXTRA}") from exc
    return np.asarray(iio.imread(path))


def _read_tiff(path: Path) -> np.ndarray:
    try:
        import tifffile
    except ImportError as exc:  # pragma: no cover
        raise ImportError(f"reading TIFF needs tifffile: {_EXTRA}") from exc
    # only the first page: a frame is one page, and a corrupt file whose page chain loops
    # would otherwise be walked without end (tifffile's series scan every page)
    with tifffile.TiffFile(path) as tif:
        page = tif.pages[0]
        _check_pixels(path, int(page.imagewidth) * int(page.imagelength), f"{page.imagewidth}x{page.imagelength}")
        return np.asarray(page.asarray())


def _read_exr(path: Path) -> np.ndarray:
    try:
        import OpenEXR
    except ImportError as exc:  # pragma: no cover
        raise ImportError(f"reading OpenEXR needs the OpenEXR bindings: {_EXTRA}") from exc
    with OpenEXR.File(str(path), header_only=True) as exr:
        (x0, y0), (x1, y1) = exr.header()["dataWindow"]
    _check_pixels(path, (int(x1) - int(x0) + 1) * (int(y1) - int(y0) + 1), f"{int(x1) - int(x0) + 1}x{int(y1) - int(y0) + 1}")
    with OpenEXR.File(str(path)) as exr:
        channels = exr.channels()
        if "RGB" in channels:
            return np.asarray(channels["RGB"].pixels)
        if "RGBA" in channels:
            return np.asarray(channels["RGBA"].pixels)[..., :3]
        for names in (("R", "G", "B"), ("Y",)):
            if all(n in channels for n in names):
                return np.stack([np.asarray(channels[n].pixels) for n in names], axis=-1)
        raise FormatError(f"{where(path)}expected EXR channels RGB or Y, got {', '.join(sorted(channels))}")


_READERS = {".png": _read_png, ".tif": _read_tiff, ".tiff": _read_tiff, ".exr": _read_exr}


def read_image(path) -> Frame:
    """Read a frame (8/16-bit PNG or TIFF, OpenEXR).

    Raises
    ------
    FileNotFoundError
        The file does not exist.
    FormatError
        Unknown suffix, unreadable or corrupt file, unsupported pixel type.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in _READERS:
        raise FormatError(
            f"{where(path)}expected an image with suffix {', '.join(IMAGE_SUFFIXES)}, got {suffix or 'none'}"
        )
    open_regular(path).close()  # missing: FileNotFoundError; a FIFO, device or folder: FormatError
    try:
        array = _READERS[suffix](path)
    except (FormatError, ImportError):
        raise
    except Exception as exc:  # corrupt files raise library-specific errors
        raise FormatError(f"{where(path)}cannot read image: {' '.join(str(exc).split())}") from None
    array = _as_hwc(array, path)
    if array.dtype == np.uint8:
        dtype, max_code = "uint8", 255.0
    elif array.dtype == np.uint16:
        dtype, max_code = "uint16", 65535.0
    elif array.dtype in (np.float16, np.float32):
        dtype, max_code = str(array.dtype), None
    else:
        raise FormatError(f"{where(path)}expected 8- or 16-bit integer or float16/32 pixels, got {array.dtype}")
    return Frame(np.ascontiguousarray(array), dtype, max_code, path)


def linearize(frame: Frame, response: str = "linear", codes=None) -> np.ndarray:
    """Code values -> linear signal in DN (float64, same scale as the stored codes).

    ``"srgb"`` decodes ``code / max_code`` with the inverse sRGB transfer function and
    scales back by ``max_code`` (for float frames the codes are taken as [0, 1]).
    ``codes`` (optional) linearises a crop of the frame's pixels instead of all of them.
    """
    validate_choice("response", response, RESPONSES)
    codes = np.asarray(frame.pixels if codes is None else codes, np.float64)
    if response == "linear":
        return codes
    scale = frame.max_code or 1.0
    return srgb_decode(codes / scale) * scale


def write_image(path, pixels) -> Path:
    """Write (H, W, C) or (H, W) pixels atomically; the format follows the suffix.

    uint8/uint16 go to PNG or TIFF (16-bit colour only to TIFF: see the module
    docstring), float arrays to OpenEXR (as float32).
    """
    path = Path(path)
    pixels = np.asarray(pixels)
    suffix = path.suffix.lower()
    if suffix not in _READERS:
        raise FormatError(f"{where(path)}expected suffix {', '.join(IMAGE_SUFFIXES)}, got {suffix or 'none'}")
    if pixels.ndim == 3 and pixels.shape[-1] == 1:
        pixels = pixels[..., 0]
    colour = pixels.ndim == 3
    with atomic_path(path) as tmp:
        if suffix == ".png":
            if pixels.dtype not in (np.uint8, np.uint16) or (colour and pixels.dtype == np.uint16):
                raise FormatError(
                    f"{where(path)}expected uint8 or greyscale uint16 pixels for PNG, got "
                    f"{'colour ' if colour else ''}{pixels.dtype}; use .tif for 16-bit colour"
                )
            import imageio.v3 as iio

            iio.imwrite(tmp, pixels, extension=".png")
        elif suffix in (".tif", ".tiff"):
            import tifffile

            tifffile.imwrite(tmp, pixels, compression="zlib", photometric="rgb" if colour else "minisblack")
        else:
            import OpenEXR

            data = np.ascontiguousarray(pixels, np.float32)
            header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
            with OpenEXR.File(header, {"RGB" if colour else "Y": data}) as exr:
                exr.write(os.fspath(tmp))
    return path
