"""``demcal repose``: angle of repose of one heap photo, written as JSON with an annotated image.

Example::

    demcal repose heap_03.jpg --json out/heap_03.json --side right

writes ``out/heap_03.json`` (angle, flank angles, floor tilt, the fits and provenance) and the
annotated photo ``out/heap_03_annotated.png`` unless ``--annotate`` names another file.
"""

from __future__ import annotations

from pathlib import Path

from demcal.errors import InputError
from demcal.jsonio import write_json
from demcal.provenance import Provenance, sha256_file
from demcal.measure.images import MAX_PHOTO_PIXELS
from demcal.measure.repose import SIDES, angle_from_photo


def register(subparsers) -> None:
    """Add the ``repose`` sub-command to the ``demcal`` parser."""
    p = subparsers.add_parser(
        "repose", help="angle of repose from a side photo of a heap",
        description="Measure the angle of repose of a heap from a side photo: threshold, top "
                    "boundary, floor line (its tilt is removed), robust line through 15-85 %% "
                    "of the height of each flank. Writes JSON and an annotated image.")
    p.add_argument("photo", help="heap photo (jpg, png, bmp, tif or another common format)")
    p.add_argument("--json", required=True, dest="json_out", metavar="OUT",
                   help="JSON file to write")
    p.add_argument("--side", choices=SIDES, default="auto",
                   help="flank(s) to measure: left rises to the crest, right falls from it; "
                        "both for a cone; auto (default) measures every flank whose toe is in "
                        "the frame")
    p.add_argument("--annotate", metavar="PATH", default=None,
                   help="annotated image to write (default: OUT's name with _annotated.png)")
    p.add_argument("--scale-mm-per-px", type=float, default=None, metavar="MM",
                   help="image scale, to report the heap height in metres")
    p.add_argument("--band", type=float, nargs=2, default=(0.15, 0.85), metavar=("LOW", "HIGH"),
                   help="fraction of the crest height between which each flank is fitted "
                        "(default 0.15 0.85)")
    p.add_argument("--max-photo-pixels", type=int, default=MAX_PHOTO_PIXELS, metavar="N",
                   help=f"refuse a photo with more pixels, before decoding it (default "
                        f"{MAX_PHOTO_PIXELS}); raise it for a genuine larger photo")
    p.set_defaults(handler=run)


def run(args) -> int:
    """Measure ``args.photo`` and write ``args.json_out`` and the annotated image."""
    photo = Path(args.photo)
    if not photo.is_file():
        raise InputError(f"photo {str(photo)!r}: file not found")
    if args.max_photo_pixels < 1:
        raise InputError(f"--max-photo-pixels must be a positive number of pixels, "
                         f"got {args.max_photo_pixels}")
    out = Path(args.json_out)
    annotate = Path(args.annotate) if args.annotate else out.with_name(out.stem + "_annotated.png")
    result = angle_from_photo(photo, side=args.side, annotate_to=annotate,
                              scale_mm_per_px=args.scale_mm_per_px, band=tuple(args.band),
                              max_pixels=args.max_photo_pixels)
    options = {"side": args.side, "band": list(args.band), "scale_mm_per_px": args.scale_mm_per_px}
    record = {
        "angle_deg": result.angle_deg,
        "flanks": result.flanks,
        "base_tilt_deg": result.base_tilt_deg,
        "annotated": result.annotated,
        "crest_height_px": result.crest_height,
        "crest_height_m": result.crest_height_m,
        "fits": {side: fit.to_dict() for side, fit in result.fits.items()},
        "photo": str(photo),
        "provenance": Provenance(inputs={str(photo): sha256_file(photo)}, options=options).to_dict(),
    }
    write_json(out, record)
    flanks = ", ".join(f"{s} {v:.2f}" for s, v in result.flanks.items() if v is not None)
    print(f"{photo}: angle of repose {result.angle_deg:.2f} deg ({flanks}); "
          f"floor tilt {result.base_tilt_deg:+.2f} deg -> {out}")
    return 0
