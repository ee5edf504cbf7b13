"""Image files from outside: their size from the header, a pixel limit, one checked decode.

A photo file is untrusted input: a 1 MB PNG may claim 30000 x 30000 px and take gigabytes to
decode. :func:`image_size` reads the width and height from the file's header without
decoding the pixels (PNG and JPEG headers are parsed here, other formats through Pillow's lazy
open); :func:`check_image` refuses an image with more pixels than a limit;
:func:`read_image` checks the header, refuses a truncated PNG or JPEG, and only then decodes
the file, once, with OpenCV.

Errors are ``ValueError`` with a reason that does not name the file: the caller knows where
the file came from (a workbook row, a command-line argument) and says so.
"""

from __future__ import annotations

import io
import struct
import warnings
import zlib
from pathlib import Path

import numpy as np

#: Most pixels a photo may have. A heap angle needs far fewer, but a full-resolution frame of
#: a 48- or 50-megapixel phone sensor (8192 x 6144 = 50.3 MP) or of a 45-megapixel camera is a
#: genuine photo and passes. At this size the repose estimator takes about 1.6 GB and 2 to 3
#: minutes on two cores (some 30 bytes and 3 microseconds per pixel); a larger photo must be
#: allowed explicitly (``--max-photo-pixels``).
MAX_PHOTO_PIXELS = 52_000_000

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_JPEG_SOI = b"\xff\xd8"
_JPEG_EOI = b"\xff\xd9"
#: JPEG frame headers (SOF0-SOF15 but DHT, JPG and DAC, which share the range).
_JPEG_SOF = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}
_JPEG_SOS = 0xDA
#: JPEG markers without a length: TEM and the restart markers.
_JPEG_STANDALONE = frozenset({0x01, *range(0xD0, 0xD8)})


def image_size(path) -> tuple[int, int]:
    """Width and height of an image file, from its header only [px].

    The pixel data are never decoded: PNG and JPEG headers are parsed here (the IHDR chunk,
    the first frame header), other formats are opened lazily by Pillow.

    Parameters
    ----------
    path : str or pathlib.Path
        The image file.

    Returns
    -------
    (int, int)
        Width and height [px].

    Raises
    ------
    ValueError
        Not an image, or its header is damaged, or (a format other than PNG and JPEG) it
        claims more pixels than Pillow opens (twice ``PIL.Image.MAX_IMAGE_PIXELS``).
    OSError
        The file cannot be opened.
    """
    with open(path, "rb") as fp:
        return _size(fp)


def check_image(path, max_pixels=MAX_PHOTO_PIXELS) -> tuple[int, int]:
    """Width and height of an image file, refused if it has more than ``max_pixels`` pixels.

    Reads the header only (:func:`image_size`), so a decompression bomb costs nothing.

    Parameters
    ----------
    path : str or pathlib.Path
        The image file.
    max_pixels : int
        Most pixels accepted (width times height) [px]; default ``MAX_PHOTO_PIXELS``.

    Returns
    -------
    (int, int)
        Width and height [px].

    Raises
    ------
    ValueError
        Not an image, a damaged header, or more pixels than ``max_pixels`` (the message gives
        the size, the limit and the option that raises it).
    OSError
        The file cannot be opened.
    """
    _check_limit(max_pixels)
    width, height = image_size(path)
    _check_pixels(width, height, max_pixels)
    return width, height


def read_image(path, max_pixels=MAX_PHOTO_PIXELS) -> np.ndarray:
    """Decode an image file once, after checking its header: a BGR ``uint8`` array.

    The file is read once; its header is checked against ``max_pixels``, a PNG or JPEG is
    checked to be complete (a PNG up to its IEND chunk, a JPEG up to its end-of-image marker
    after the image data), and only then are the pixels decoded, by OpenCV
    (``cv2.IMREAD_COLOR``: grey and colour images as three-channel BGR, alpha dropped, 16 bits
    reduced to 8, the EXIF orientation applied).

    Parameters
    ----------
    path : str or pathlib.Path
        The image file.
    max_pixels : int
        Most pixels accepted (width times height) [px]; default ``MAX_PHOTO_PIXELS``.

    Returns
    -------
    numpy.ndarray
        ``(height, width, 3)`` BGR image, ``uint8``.

    Raises
    ------
    ValueError
        Not an image, a damaged header, more pixels than ``max_pixels``, a truncated file, or
        data OpenCV cannot decode.
    OSError
        The file cannot be read.
    """
    import cv2  # imported here: checking a header does not need OpenCV

    _check_limit(max_pixels)
    data = Path(path).read_bytes()
    # The header checked is the one of the bytes decoded.
    width, height = _size(io.BytesIO(data))
    _check_pixels(width, height, max_pixels)
    _check_complete(data)
    try:
        img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    except cv2.error as exc:
        raise ValueError(f"OpenCV cannot decode it ({exc.err})") from None
    if img is None:
        raise ValueError("not a readable image file (OpenCV cannot decode its data)")
    return img


# ----------------------------------------------------------------------------------------
# Headers

def _size(fp) -> tuple[int, int]:
    head = fp.read(8)
    fp.seek(0)
    if head == _PNG_SIGNATURE:
        return _png_size(fp)
    if head.startswith(_JPEG_SOI):
        return _jpeg_layout(fp)[:2]
    return _pillow_size(fp)


def _png_size(fp) -> tuple[int, int]:
    """Width and height from the IHDR chunk, which must come first and match its CRC."""
    head = fp.read(33)          # signature, IHDR length and type, 13 data bytes, CRC
    if len(head) < 33:
        raise ValueError("not a readable image file (damaged PNG header: the file ends inside it)")
    length, kind = struct.unpack(">I4s", head[8:16])
    if (length, kind) != (13, b"IHDR"):
        raise ValueError("not a readable image file (damaged PNG header: no IHDR chunk first)")
    if zlib.crc32(head[12:29]) != struct.unpack(">I", head[29:33])[0]:
        raise ValueError("not a readable image file (damaged PNG header: IHDR checksum mismatch)")
    width, height = struct.unpack(">II", head[16:24])
    if not (0 < width < 2**31 and 0 < height < 2**31):
        raise ValueError(f"not a readable image file (damaged PNG header: {width} x {height} px)")
    return width, height


def _jpeg_layout(fp) -> tuple[int, int, int]:
    """Width and height from the first frame header, and the offset of the first scan.

    Walks the marker segments from the start of image to the first start of scan, skipping
    over their contents.
    """
    def damaged(why):
        return ValueError(f"not a readable image file (damaged JPEG header: {why})")

    fp.seek(2)
    size = None
    while True:
        marker = fp.read(1)
        if marker and marker != b"\xff":
            raise damaged("no marker where one is due")
        while marker == b"\xff":                 # the marker's 0xFF and any fill bytes
            marker = fp.read(1)
        if not marker:
            raise damaged("the file ends before the image data")
        m = marker[0]
        if m in _JPEG_STANDALONE:
            continue
        if m == _JPEG_EOI[1]:
            raise damaged("end of image before the image data")
        raw = fp.read(2)
        if len(raw) < 2:
            raise damaged("the file ends before the image data")
        length = int.from_bytes(raw, "big")
        if length < 2:
            raise damaged(f"a segment of length {length}")
        if m == _JPEG_SOS:
            if size is None:
                raise damaged("no frame header before the image data")
            return size[0], size[1], fp.tell() - 4
        if m in _JPEG_SOF and size is None:
            frame = fp.read(length - 2)
            if len(frame) < 6:
                raise damaged("the frame header is cut short")
            height, width = struct.unpack(">HH", frame[1:5])
            if width == 0 or height == 0:
                # A height of 0 is left to a later DNL marker, which OpenCV does not read.
                raise damaged(f"the frame header gives {width} x {height} px")
            size = (width, height)
        else:
            fp.seek(length - 2, io.SEEK_CUR)


def _pillow_size(fp) -> tuple[int, int]:
    from PIL import Image, UnidentifiedImageError

    try:
        # Pillow warns above MAX_IMAGE_PIXELS; the caller's own limit decides here.
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            with Image.open(fp) as im:
                return im.size
    except Image.DecompressionBombError:
        raise ValueError(f"its header claims more than {2 * Image.MAX_IMAGE_PIXELS:,} pixels, "
                         f"more than Pillow opens") from None
    except UnidentifiedImageError:
        raise ValueError("not a readable image file (not an image format recognised)") from None
    except (OSError, SyntaxError, EOFError, struct.error, ValueError) as exc:
        raise ValueError(f"not a readable image file (damaged header: {exc})") from None


# ----------------------------------------------------------------------------------------
# Checks

def _check_limit(max_pixels):
    if isinstance(max_pixels, bool) or not isinstance(max_pixels, (int, np.integer)) or max_pixels < 1:
        raise ValueError(f"max_pixels must be a positive whole number of pixels, got {max_pixels!r}")


def _check_pixels(width, height, max_pixels):
    if width * height > max_pixels:
        raise ValueError(f"{width} x {height} px ({width * height:,} pixels) is more than the limit "
                         f"of {max_pixels:,} pixels for a photo; if the photo is genuine, raise the "
                         f"limit with --max-photo-pixels")


def _check_complete(data: bytes):
    """Refuse a PNG without its IEND chunk or a JPEG without an end of image after its data:
    a truncated file, which OpenCV would decode in part or refuse with messages on stderr."""
    if data.startswith(_PNG_SIGNATURE):
        pos = len(_PNG_SIGNATURE)
        while pos + 8 <= len(data):
            length, kind = struct.unpack_from(">I4s", data, pos)
            pos += 12 + length                  # length, type, data, CRC
            if kind == b"IEND":
                if pos <= len(data):
                    return
                break
        raise ValueError("not a readable image file (truncated PNG: no IEND chunk at the end)")
    if data.startswith(_JPEG_SOI):
        scan = _jpeg_layout(io.BytesIO(data))[2]
        # In the image data a 0xFF byte is followed by a stuffed 0 or a marker, so an end of
        # image after the first scan is a marker (the image's own, or one of data appended).
        if data.rfind(_JPEG_EOI) < scan:
            raise ValueError("not a readable image file (truncated JPEG: no end of image marker)")
