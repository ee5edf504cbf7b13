"""Particle shapes, one module each, registered by the name the workbook's meta ``shape`` gives.

=========  ====================================================  ==============================
shape      particle                                              specimen columns
=========  ====================================================  ==============================
segment    equal spheres in a row (roots, stems, pellets)        length_mm, diameter_mm
sphere     one sphere (soybean, pea)                             diameter_mm, or three axes
kernel     ellipsoid of inscribed spheres (maize, rice, wheat)   length_mm, width_mm, thickness_mm
clump      the workbook's ``clump`` sheet of spheres, scaled     length_mm (and width, thickness)
=========  ====================================================  ==============================

A new shape is a module with a :class:`~demcal.simulate.shapes.base.Shape` subclass and one
line in ``SHAPES``.
"""

from __future__ import annotations

import importlib

from demcal.errors import InputError
from demcal.simulate.shapes.base import Shape

#: Shape name -> "module:class".
SHAPES = {"segment": "demcal.simulate.shapes.segment:Segment",
          "sphere": "demcal.simulate.shapes.sphere:Sphere",
          "kernel": "demcal.simulate.shapes.kernel:Kernel",
          "clump": "demcal.simulate.shapes.clump:ClumpTable"}

#: The shape of a workbook that names none.
DEFAULT_SHAPE = "segment"


def shape_class(name: str) -> type[Shape]:
    """The class of shape ``name``; an unknown name lists the valid ones."""
    key = str(name).strip().lower()
    if key not in SHAPES:
        raise InputError(f"unknown shape {name!r}; valid shapes: {', '.join(SHAPES)}")
    module, cls = SHAPES[key].split(":")
    return getattr(importlib.import_module(module), cls)


def size_columns() -> tuple:
    """Every calliper column any shape is measured by, in the order the shapes name them."""
    out = []
    for name in SHAPES:
        for option in shape_class(name).specimen_columns:
            out += [c for c in option if c not in out]
    return tuple(out)


def shape_from_dict(d: dict) -> Shape:
    """A shape from :meth:`Shape.to_dict`'s layout (``{"shape": name, field: value, ...}``)."""
    if not isinstance(d, dict) or "shape" not in d:
        raise InputError(f"a particle shape needs a dict with its name under 'shape', got {d!r}")
    cls = shape_class(d["shape"])
    unknown = sorted(set(d) - {"shape"} - set(cls.field_names()))
    if unknown:
        raise InputError(f"shape {cls.name}: unknown field(s) {', '.join(unknown)}; valid: "
                         f"{', '.join(cls.field_names())}")
    return cls(**{k: v for k, v in d.items() if k != "shape"})


__all__ = ["DEFAULT_SHAPE", "SHAPES", "Shape", "shape_class", "shape_from_dict", "size_columns"]
