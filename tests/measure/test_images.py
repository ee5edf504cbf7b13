"""Image files as untrusted input (measure.images): size from the header, pixel limit, one
checked decode.

The hostile files are built here, small: PNGs whose IHDR claims 30000 x 30000 and 12000 x
12000 px (zero rows, compressed as they are written, about 1 MB), a JPEG whose frame header
claims 60000 x 60000 px, truncated files, a text file named .jpg. Nothing here decodes one of
them in this process: a refusal that reaches the decoder runs in a child process under an
address-space cap, which also reports its peak memory.
"""

from __future__ import annotations

import struct
import subprocess
import sys
import time
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest

from demcal.errors import WorkbookError
from demcal.measure.images import MAX_PHOTO_PIXELS, check_image, image_size, read_image
from demcal.measure.pipeline import measure_workbook
from demcal.measure.workbook import ReadOptions, read_workbook

ROOT = Path(__file__).resolve().parents[2]
HEAP = ROOT / "data" / "astragalus" / "photos" / "heap_1.jpg"       # 1200 x 900 px
HEAP_PIXELS = 1200 * 900

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
CHILD_CAP = 3 * 2**30          # address space of a child that might decode a bomb [bytes]
CHILD_PEAK_MAX = 600 * 2**20   # peak resident memory a refusal may take [bytes]


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def write_zero_png(path, width, height, rows_per_block=64):
    """A valid grey 8-bit PNG of zeros, compressed block by block as it is written (nothing
    of its decoded size is ever in memory)."""
    comp = zlib.compressobj(9)
    block = bytes(width + 1) * rows_per_block       # filter byte 0, then the row
    with open(path, "wb") as f:
        f.write(PNG_SIGNATURE + _chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)))
        for start in range(0, height, rows_per_block):
            n = min(rows_per_block, height - start)
            data = comp.compress(block if n == rows_per_block else bytes(width + 1) * n)
            if data:
                f.write(_chunk(b"IDAT", data))
        f.write(_chunk(b"IDAT", comp.flush()) + _chunk(b"IEND", b""))
    return path


def jpeg_claiming(path, width, height):
    """A small real JPEG whose frame header (SOF0) is rewritten to claim ``width x height``."""
    ok, buf = cv2.imencode(".jpg", np.full((64, 64, 3), 128, np.uint8))
    data = bytearray(buf.tobytes())
    sof = data.index(b"\xff\xc0")
    assert data[sof + 4] == 8                       # precision: this is the frame header
    data[sof + 5:sof + 9] = struct.pack(">HH", height, width)
    path.write_bytes(bytes(data))
    return path


@pytest.fixture(scope="module")
def bombs(tmp_path_factory):
    root = tmp_path_factory.mktemp("bombs")
    return {"png_30000": (write_zero_png(root / "bomb_30000.png", 30000, 30000), 30000, 30000),
            "png_12000": (write_zero_png(root / "bomb_12000.png", 12000, 12000), 12000, 12000),
            "jpeg_60000": (jpeg_claiming(root / "bomb.jpg", 60000, 60000), 60000, 60000)}


def encoded(ext, img=None):
    """``img`` (default the example heap photo) encoded as ``ext``, as bytes."""
    ok, buf = cv2.imencode(ext, cv2.imread(str(HEAP)) if img is None else img)
    return buf.tobytes()


# ------------------------------------------------------------------------------------------
# Size from the header

def test_size_from_the_header_of_png_jpeg_and_other_formats(tmp_path):
    assert image_size(HEAP) == (1200, 900)
    for ext in (".png", ".bmp", ".tif"):
        path = tmp_path / f"heap{ext}"
        path.write_bytes(encoded(ext))
        assert image_size(path) == (1200, 900), ext
        assert check_image(path) == (1200, 900)


def test_bombs_are_refused_from_their_header_at_once(bombs):
    assert bombs["png_30000"][0].stat().st_size < 1.5e6           # about 1 MB on disk
    for path, width, height in bombs.values():
        start = time.perf_counter()
        assert image_size(path) == (width, height)
        with pytest.raises(ValueError) as info:
            check_image(path)
        assert time.perf_counter() - start < 2.0
        message = str(info.value)
        assert f"{width} x {height} px ({width * height:,} pixels)" in message
        assert f"limit of {MAX_PHOTO_PIXELS:,} pixels" in message
        assert "--max-photo-pixels" in message


def test_a_text_file_named_jpg_and_damaged_headers(tmp_path):
    text = tmp_path / "notes.jpg"
    text.write_text("heap photo to follow\n")
    for call in (image_size, check_image, read_image):
        with pytest.raises(ValueError, match="not a readable image file"):
            call(text)
    png = bytearray(encoded(".png"))
    png[29] ^= 0xFF                                             # IHDR checksum
    (tmp_path / "crc.png").write_bytes(bytes(png))
    with pytest.raises(ValueError, match="IHDR checksum"):
        image_size(tmp_path / "crc.png")
    (tmp_path / "short.png").write_bytes(encoded(".png")[:20])
    with pytest.raises(ValueError, match="damaged PNG header"):
        image_size(tmp_path / "short.png")
    with pytest.raises(ValueError, match=r"0 x 64 px"):
        image_size(jpeg_claiming(tmp_path / "zero.jpg", 0, 64))
    (tmp_path / "cut.jpg").write_bytes(encoded(".jpg")[:100])   # inside the header
    with pytest.raises(ValueError, match="damaged JPEG header"):
        image_size(tmp_path / "cut.jpg")
    with pytest.raises(OSError):
        image_size(tmp_path / "missing.png")


# ------------------------------------------------------------------------------------------
# The limit and its override

def test_a_photo_just_over_a_lowered_limit_and_the_override(tmp_path):
    with pytest.raises(ValueError, match=r"1200 x 900 px \(1,080,000 pixels\).*limit of 1,079,999"):
        check_image(HEAP, max_pixels=HEAP_PIXELS - 1)
    with pytest.raises(ValueError, match="1,079,999"):
        read_image(HEAP, max_pixels=HEAP_PIXELS - 1)
    assert check_image(HEAP, max_pixels=HEAP_PIXELS) == (1200, 900)
    assert read_image(HEAP, max_pixels=HEAP_PIXELS).shape == (900, 1200, 3)
    for bad in (0, -5, 1.5e6, None, True):
        with pytest.raises(ValueError, match="max_pixels"):
            check_image(HEAP, max_pixels=bad)


# ------------------------------------------------------------------------------------------
# One checked decode

def test_read_image_decodes_as_opencv_does(tmp_path):
    assert np.array_equal(read_image(HEAP), cv2.imread(str(HEAP), cv2.IMREAD_COLOR))
    bgr = cv2.imread(str(HEAP))
    gray = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
    (tmp_path / "gray.png").write_bytes(encoded(".png", gray))
    assert np.array_equal(read_image(tmp_path / "gray.png"), cv2.cvtColor(gray, cv2.COLOR_GRAY2BGR))
    (tmp_path / "rgba.png").write_bytes(encoded(".png", cv2.cvtColor(bgr, cv2.COLOR_BGR2BGRA)))
    assert np.array_equal(read_image(tmp_path / "rgba.png"), bgr)
    (tmp_path / "heap.bmp").write_bytes(encoded(".bmp"))
    assert np.array_equal(read_image(tmp_path / "heap.bmp"), bgr)


@pytest.mark.parametrize("ext, cut", [(".png", 0.6), (".png", -12), (".jpg", 0.6), (".jpg", -2)])
def test_truncated_files_are_a_clean_error(tmp_path, capfd, ext, cut):
    """Cut in the image data, or just before the end (PNG: the IEND chunk; JPEG: the end of
    image marker): refused before OpenCV sees it, with nothing written to stderr."""
    data = encoded(ext)
    path = tmp_path / f"cut{ext}"
    path.write_bytes(data[:int(cut * len(data))] if cut > 0 else data[:cut])
    assert image_size(path) == (1200, 900)                      # the header is intact
    with pytest.raises(ValueError, match=f"truncated {ext[1:].upper().replace('JPG', 'JPEG')}"):
        read_image(path)
    assert capfd.readouterr().err == ""


def test_a_jpeg_with_data_after_its_end_is_read(tmp_path):
    path = tmp_path / "trailer.jpg"
    path.write_bytes(encoded(".jpg") + b"appended by a phone\xff\xd8")
    assert read_image(path).shape == (900, 1200, 3)


# ------------------------------------------------------------------------------------------
# Refusal in a child process: quick, small, one line

CHILD = """
import sys
from demcal.cli import main
try:
    code = main(sys.argv[1:])
finally:
    with open("/proc/self/status") as f:
        peak = next(line.split()[1] for line in f if line.startswith("VmHWM:"))
    print(f"peak_rss_kib {peak}")
sys.exit(code)
"""


def _cap_address_space():
    import resource
    resource.setrlimit(resource.RLIMIT_AS, (CHILD_CAP, CHILD_CAP))


def run_capped(*argv):
    """``demcal *argv`` in a child under the address-space cap: (process, wall time [s], peak
    resident memory [bytes]). The peak is the child's own (VmHWM of its address space):
    ru_maxrss would also count the pages of this process, which the child is forked from."""
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", CHILD, *map(str, argv)], capture_output=True,
                          text=True, timeout=120, preexec_fn=_cap_address_space)
    elapsed = time.perf_counter() - start
    return proc, elapsed, int(proc.stdout.split("peak_rss_kib")[1]) * 1024


needs_proc = pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="needs Linux /proc")


@needs_proc
@pytest.mark.parametrize("bomb", ["png_30000", "png_12000", "jpeg_60000"])
def test_demcal_repose_refuses_a_bomb_quickly_in_little_memory(bombs, tmp_path, bomb):
    path, width, height = bombs[bomb]
    proc, elapsed, peak = run_capped("repose", path, "--json", tmp_path / "out.json")
    err = proc.stderr.strip().splitlines()
    assert proc.returncode == 2, proc.stderr
    assert len(err) == 1 and err[0].startswith("demcal repose: error:"), proc.stderr
    assert f"{width} x {height} px" in err[0] and f"{MAX_PHOTO_PIXELS:,}" in err[0]
    assert "--max-photo-pixels" in err[0]
    assert peak < CHILD_PEAK_MAX, f"peak resident memory {peak / 2**20:.0f} MiB"
    assert elapsed < 30.0            # the interpreter and demcal's imports; no decoding
    assert not (tmp_path / "out.json").exists()


@needs_proc
def test_a_limit_raised_beyond_what_opencv_decodes_is_a_clean_error(bombs, tmp_path):
    """60000 x 60000 px allowed: OpenCV's own limit (or, failing it, the cap) refuses it."""
    proc, elapsed, peak = run_capped("repose", bombs["jpeg_60000"][0], "--json",
                                     tmp_path / "out.json", "--max-photo-pixels", 4 * 10**9)
    err = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(err) == 1, proc.stderr
    assert "OpenCV cannot decode it" in err[0]
    assert peak < CHILD_PEAK_MAX


# ------------------------------------------------------------------------------------------
# The workbook's photos

def _heap_photos(sheets):
    for row in sheets["repose"]:
        row["side"] = "right"


@pytest.fixture
def heap_campaign(campaign):
    """The conftest workbook with two photos of the example's heap (PNG) instead of sketches."""
    path = campaign(_heap_photos)
    photos = (path if path.is_dir() else path.parent) / "photos"
    bgr = cv2.imread(str(HEAP))
    for name in ("p1.png", "p2.png"):
        cv2.imwrite(str(photos / name), bgr)
    return path


def test_workbook_photo_over_the_limit_is_refused_naming_its_row(heap_campaign):
    with pytest.raises(WorkbookError) as info:
        read_workbook(heap_campaign, ReadOptions(max_photo_pixels=HEAP_PIXELS - 1))
    assert (info.value.sheet, info.value.row, info.value.column) == ("repose", 1, "file")
    assert "1200 x 900 px" in str(info.value) and "1,079,999" in str(info.value)
    m = measure_workbook(heap_campaign, reading=ReadOptions(max_photo_pixels=HEAP_PIXELS))
    assert m.quantities["repose_angle_deg"].n == 2
    assert m.provenance.options["reading"]["max_photo_pixels"] == HEAP_PIXELS


def test_workbook_photos_are_decoded_once(heap_campaign, monkeypatch):
    from PIL import ImageFile

    calls = []

    def counting(name, original):
        def call(*args, **kwargs):
            calls.append(name)
            return original(*args, **kwargs)
        return call

    monkeypatch.setattr(cv2, "imread", counting("cv2.imread", cv2.imread))
    monkeypatch.setattr(cv2, "imdecode", counting("cv2.imdecode", cv2.imdecode))
    monkeypatch.setattr(ImageFile.ImageFile, "load", counting("PIL load", ImageFile.ImageFile.load))
    measure_workbook(read_workbook(heap_campaign))
    assert calls == ["cv2.imdecode", "cv2.imdecode"]


def _drum_photos(sheets):
    for row in sheets["repose"]:
        row["side"] = "drum"


def test_a_drum_photo_with_no_free_surface_is_refused_naming_its_row(campaign):
    """Drum photos (side ``drum``) are read by the drum estimator; one whose drum holds no
    bed is refused naming the sheet, its row and column, and the command exits 2 without a
    traceback."""
    from demcal.simulate.rigs.drum import drum_photo

    path = campaign(_drum_photos)
    photos = (path if path.is_dir() else path.parent) / "photos"
    # a bed of 4 mm spheres below a line at 30 deg through the drum's centre, then an empty drum
    rng = np.random.default_rng(1)
    pts = rng.uniform(-0.075, 0.075, size=(6000, 2))
    bed = pts[(np.hypot(*pts.T) < 0.07) & (pts[:, 1] < np.tan(np.radians(30.0)) * pts[:, 0])]
    centres = np.column_stack([bed[:, 0], np.zeros(len(bed)), bed[:, 1]])
    cv2.imwrite(str(photos / "p1.png"), drum_photo(centres, np.full(len(bed), 0.004), 0.15))
    cv2.imwrite(str(photos / "p2.png"), drum_photo(np.zeros((0, 3)), np.zeros(0), 0.15))
    with pytest.raises(WorkbookError) as info:
        measure_workbook(read_workbook(path))
    assert (info.value.sheet, info.value.row, info.value.column) == ("repose", 2, "file")
    assert "no powder bed found in the drum" in str(info.value)
    proc = subprocess.run([sys.executable, "-m", "demcal.cli", "measure", str(path)], capture_output=True, text=True)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert "repose" in proc.stderr and "no powder bed found" in proc.stderr
