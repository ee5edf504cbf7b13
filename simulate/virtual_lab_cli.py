"""``demcal virtual-lab``: a complete lab workbook written from a stated truth.

    demcal virtual-lab TRUTH.yaml --out DIR [--plant KIND=SIZE ...] [--seed N] [--force] [--workers N]

TRUTH.yaml states the material, the scatter and reading noise of the lab, and the design of the
campaign (``simulate.truth_file``; data/virtual_lab/truth.yaml is a commented example). The
workbook goes to DIR (one CSV per sheet, with its photos, tracks and curves) or, for a path
ending in ``.xlsx``, to that workbook file; ``DIR/truth.json`` records the truth, the planted
effects and their true sizes. The command prints the true value of every quantity
``demcal measure`` will report, so that the measurement can be compared with the truth.
"""

from __future__ import annotations

import math
import os
import sys
from pathlib import Path

import numpy as np

from demcal.errors import InputError
from demcal.simulate.materials import youngs_modulus

#: Attachment folders the virtual lab writes beside the sheets, and the files it names there.
ATTACHMENTS = {"photos": "heap_*.jpg", "tracks": "T*.csv", "curves": "C*.csv"}


def parse_plant(items) -> tuple:
    """``["KIND=SIZE", "KIND=SIZE:SHEET", "KIND=SIZE:SHEET:QUANTITY", "KIND", ...]`` ->
    PlantedEffect tuple (no size: the kind's default; no sheet or quantity: the kind's)."""
    from demcal.simulate.virtual_lab import EFFECT_KINDS, PlantedEffect

    effects = []
    for item in items:
        kind, sep, rest = str(item).partition("=")
        kind = kind.strip()
        if kind not in EFFECT_KINDS:
            raise InputError(f"--plant {item!r}: unknown effect {kind!r}; valid: {', '.join(EFFECT_KINDS)}")
        size, _, where = rest.partition(":")
        sheet, _, quantity = where.partition(":")
        value = None
        if sep and size.strip():
            try:
                value = float(size)
            except ValueError:
                raise InputError(f"--plant {item!r}: SIZE must be a number, got {size.strip()!r}") from None
        try:
            effects.append(PlantedEffect(kind, size=value, sheet=sheet.strip() or None,
                                         quantity=quantity.strip() or None))
        except InputError as exc:
            raise InputError(f"--plant {item!r}: {exc}") from None
    return tuple(effects)


def _apparent_ratio(truth, effects, pair: str, heights_mm) -> float:
    """Mean apparent / contact restitution of a pair's drops: 1, or, with segments released by
    hand (``orientation_rotation``), the drop twin's ratio averaged over the release angles and
    heights (the twin points the workbook used, from the cache)."""
    from demcal.simulate.virtual_lab import drop_twin_ratio

    hand = [e for e in effects if e.kind == "orientation_rotation" and e.acts_on(f"restitution.{pair}")]
    if not hand:
        return 1.0
    lowest = min(e.size for e in hand)
    angles = np.linspace(lowest, 90.0, 181)
    params = truth.params.with_(contact_effective_mass=True)   # as the virtual lab's drops
    return float(np.mean([drop_twin_ratio(params, pair, h * 1e-3, angles).mean() for h in heights_mm]))


def true_quantities(truth, design: dict, effects=()) -> dict:
    """The true value of each quantity ``demcal measure`` reports for a virtual workbook.

    Parameters
    ----------
    truth : Truth
    design : dict
        Options of ``write_virtual_workbook`` (``simulate.truth_file.design_defaults`` keys).
    effects : sequence of PlantedEffect
        Planted effects: segments released by hand change the apparent restitution (the twin's
        ratio is applied); the others are centred on the truth, except a block effect, which
        raises the affected quantity by up to its size.

    Returns
    -------
    dict
        Quantity name -> (value, unit), in measure's names and units. The restitution is the
        apparent one, sqrt(h2/h1), what the drops measure.
    """
    from demcal.simulate.shapes.segment import Segment
    from demcal.simulate.virtual_lab import size_columns

    p = truth.params
    shape = p.shape
    envelope = truth.envelope_ratio * p.particle_density_kg_m3
    if isinstance(shape, Segment):
        length, dia = shape.length_m, shape.diameter_m
        # E[d^2 L] = (d^2 + sd_d^2) L for independent sizes (their clipping at +-40 % is negligible)
        volume = math.pi / 4.0 * (dia ** 2 + truth.diameter_sd_m ** 2) * length
    else:
        volume = _mean_volume(shape, truth.size_sd_rel)
    out = {column: (getattr(shape, name) * 1e3, "mm") for name, column in zip(shape.sizes, size_columns(shape))}
    out.update({"mass_g": (envelope * volume * 1e3, "g"),
                "particle_density_kg_m3": (p.particle_density_kg_m3, "kg/m^3"),
                "envelope_density_kg_m3": (envelope, "kg/m^3")})
    for pair in design["pairs"]:
        ratio = _apparent_ratio(truth, effects, pair, design["drop_heights_mm"])
        out[f"restitution.{pair}"] = (truth.restitution(pair) * ratio, "1")
    for surface in design["surfaces"]:
        out[f"static_friction.{surface}"] = (truth.friction(surface, "slide"), "1")
    for surface in design["surfaces"]:
        out[f"rolling_friction.{surface}"] = (truth.friction(surface, "roll"), "1")
    if design["n_compression"]:
        out["poisson_ratio"] = (p.poisson_ratio, "1")
    if design["n_compression"] and shape.strip_contact:
        out["elastic_modulus_pa"] = (youngs_modulus(p.shear_modulus_pa, p.poisson_ratio), "Pa")
        out["shear_modulus_pa"] = (p.shear_modulus_pa, "Pa")
    if design["photos"] == "analytic" and design["n_photos"]:
        out["repose_angle_deg"] = (truth.repose_angle_deg, "deg")
    return out


def _mean_volume(shape, sd_rel: float, nodes: int = 7) -> float:
    """E[V] of a shape whose sizes are independent normals of relative sd ``sd_rel`` about its
    own, each at most the one before as the virtual lab draws them (Gauss-Hermite quadrature
    over each size, exact for volumes of degree up to 13; the clipping at +-40 %, 6.7 sd at the
    default spread, is neglected)."""
    import itertools
    from dataclasses import replace

    x, w = np.polynomial.hermite_e.hermegauss(nodes)
    w = w / w.sum()
    total = 0.0
    for idx in itertools.product(range(nodes), repeat=len(shape.sizes)):
        sizes = {}
        for n, i in zip(shape.sizes, idx):           # each axis at most the one before, as drawn
            sizes[n] = min([getattr(shape, n) * (1.0 + sd_rel * x[i])] + list(sizes.values()))
        total += float(np.prod([w[i] for i in idx])) * replace(shape, **sizes).volume()
    return total


def _clear(out: Path, force: bool) -> None:
    """Refuse to write into a non-empty folder, unless ``force`` and it holds an earlier virtual
    workbook, whose sheets and files are then removed (a stale sheet would be measured)."""
    from demcal.measure.workbook import SHEETS

    if out.suffix.lower() == ".xlsx":
        if out.exists() and not force:
            raise InputError(f"--out {out}: the file exists; give --force to replace it")
        return
    if not out.exists():
        return
    if not out.is_dir():
        raise InputError(f"--out {out}: exists and is not a folder")
    if not any(out.iterdir()):
        return
    if not force:
        raise InputError(f"--out {out}: the folder is not empty; choose a new folder, or give --force to "
                         "replace the virtual workbook written there")
    if not (out / "truth.json").is_file():
        raise InputError(f"--out {out}: --force replaces only a virtual workbook (a folder holding "
                         "truth.json); this folder holds other files")
    for name in list(SHEETS) + ["truth"]:
        for path in (out / f"{name}.csv", out / f"{name}.json"):
            path.unlink(missing_ok=True)
    for folder, pattern in ATTACHMENTS.items():
        for path in (out / folder).glob(pattern):
            path.unlink()


def register(subparsers) -> None:
    """Add the ``virtual-lab`` sub-command."""
    from demcal.simulate.virtual_lab import EFFECT_KINDS

    p = subparsers.add_parser(
        "virtual-lab", help="write a complete lab workbook from a stated truth (to try or teach the pipeline)",
        description="Run a virtual lab campaign from the truth and design stated in TRUTH.yaml and write "
                    "every sheet of its workbook, with heap photos, camera tracks and compression curves. "
                    "Effects can be planted for the critique to find. DIR/truth.json records the truth, "
                    "the effects and their true sizes.")
    p.add_argument("truth", metavar="TRUTH.yaml", help="the truth file (see data/virtual_lab/truth.yaml)")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="folder for the workbook (one CSV per sheet), or a path ending in .xlsx")
    p.add_argument("--plant", action="append", default=[], metavar="KIND=SIZE[:SHEET[:QUANTITY]]",
                   help=f"plant an effect (repeatable; SIZE in the kind's unit, omitted: its default; "
                        f"SHEET and QUANTITY where, e.g. trial_order_drift=-0.001:drop:restitution); "
                        f"KIND one of {', '.join(EFFECT_KINDS)}")
    p.add_argument("--seed", type=int, default=0, help="seed of the virtual campaign (default %(default)s)")
    p.add_argument("--force", action="store_true", help="replace a virtual workbook already in DIR")
    p.add_argument("--workers", type=int, default=os.cpu_count() or 1,
                   help="processes pouring the heaps of DEM photos at once; the workbook is the same "
                        "whatever their number (default: the cores, %(default)s)")
    p.set_defaults(handler=run)


def _fmt(x: float) -> str:
    return f"{x:.4g}"


def run(args) -> int:
    from demcal.simulate.truth_file import read_truth_file
    from demcal.simulate.rigs import rig_of_geometry
    from demcal.simulate.virtual_lab import EFFECT_DEFAULTS, check_design, write_virtual_workbook

    if args.workers < 1:
        raise InputError(f"--workers must be >= 1, got {args.workers}")
    spec = read_truth_file(args.truth)
    effects = parse_plant(args.plant)
    design = spec.design
    check_design(effects, **design)          # before a workbook in --out is replaced
    out = Path(args.out)
    _clear(out, args.force)
    if design["photos"] == "dem" and design["n_photos"]:
        from demcal.simulate.virtual_lab import repose_geometries

        rigs = ([r.workbook_name for r in map(rig_of_geometry, repose_geometries(design["repose_rig"]))]
                if design.get("repose_rig") else ["repose"])
        print(f"pouring {design['n_photos']} heaps in each of the rigs {', '.join(rigs)} for the photos: this "
              "takes minutes" if len(rigs) > 1 else
              f"pouring {design['n_photos']} heaps in the {rigs[0]} rig for the photos: this takes minutes",
              file=sys.stderr)
    vw = write_virtual_workbook(spec.truth, out, effects=effects, rng=args.seed, workers=args.workers, **design)
    root = out.parent if out.suffix.lower() == ".xlsx" else out
    print(f"virtual workbook written: {vw.path} (seed {args.seed}; truth and planted effects in "
          f"{root / 'truth.json'})")
    for e in effects:
        unit = EFFECT_DEFAULTS[e.kind]["unit"]
        print(f"planted: {e.kind}, size {e.size:g} {unit}, sheet {e.sheet}")
    for x in vw.expected:
        print(f"  true effect on {x['quantity']} vs {x['covariate']}: {_fmt(x['true_effect'])} {x['unit']}")
    print("\ntrue values of the quantities demcal measure reports:")
    print(f"{'quantity':<34} {'truth':>11}  unit")
    for name, (value, unit) in true_quantities(spec.truth, design, effects).items():
        print(f"{name:<34} {_fmt(value):>11}  {unit}")
    if design["photos"] == "dem" and design["n_photos"]:
        print("repose_angle_deg: the repose twin's at the truth (the photos show its heaps; no other truth)")
    if any(e.kind == "block_effect" for e in effects):
        print("(a block effect raises the quantities it acts on by up to its size; the values above are "
              "without it)")
    print(f"\nnext: demcal measure {args.out} --json measurement.json")
    return 0
