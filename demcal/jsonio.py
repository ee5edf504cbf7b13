"""JSON output shared by every command: numpy-aware, written atomically (a crash never leaves
half a file behind)."""

from __future__ import annotations

import json
import math
import os
import tempfile
from dataclasses import asdict, is_dataclass
from pathlib import Path

import numpy as np


def to_jsonable(obj):
    """Convert numpy scalars/arrays, dataclasses, paths and non-finite floats to JSON types.

    NaN and infinities become None (JSON has no representation for them).
    """
    if is_dataclass(obj) and not isinstance(obj, type):
        return to_jsonable(asdict(obj))
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return to_jsonable(obj.item())
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, Path):
        return str(obj)
    return obj


def restore_nan(d: dict, *names) -> dict:
    """``d`` with the fields ``names`` that JSON holds as None (``to_jsonable`` writes NaN so)
    back to NaN, for reading a float field that is never legitimately absent."""
    return {**d, **{n: math.nan for n in names if d.get(n, 0) is None}}


def check_schema(doc: dict, supported: int, where: str) -> None:
    """Refuse a document written by a newer layout than this code reads (files without a
    ``schema_version`` have the first layout)."""
    from demcal.errors import InputError

    version = doc.get("schema_version", 1)
    if not isinstance(version, int) or version > supported:
        raise InputError(f"{where}: schema version {version!r} is newer than this demcal reads "
                         f"({supported}); update demcal")


def write_json(path, obj, indent: int = 2) -> Path:
    """Write ``obj`` as JSON to ``path`` atomically (temporary file in the same folder, then rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    text = json.dumps(to_jsonable(obj), indent=indent, allow_nan=False)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text + "\n")
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; give the file normal permissions
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def read_json(path):
    with open(path) as f:
        return json.load(f)
