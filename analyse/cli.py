"""``demcal analyse`` sub-commands: analyse an existing table of runs.

    demcal analyse pb  TABLE --factors F1,...,Fk --response COL --json OUT
    demcal analyse bbd TABLE --factors F1,F2,F3 --response COL [--block COL] --json OUT

TABLE is a CSV or an xlsx workbook (``--sheet``). ``--levels coded`` (default) reads the factor
columns as coded levels; ``--levels actual`` codes them from ``--low``/``--high`` or, if those are
not given, from each column's minimum and maximum in the table.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from demcal.errors import InputError, WorkbookError
from demcal.jsonio import write_json
from demcal.provenance import Provenance, sha256_file


def _split(text: str, what: str) -> list[str]:
    items = [s.strip() for s in text.split(",")]
    if not text.strip() or any(not s for s in items):
        raise InputError(f"{what} must be a comma-separated list, got {text!r}")
    return items


def _floats(text: str, what: str, n: int) -> np.ndarray:
    items = _split(text, what)
    try:
        values = np.array([float(s) for s in items])
    except ValueError:
        raise InputError(f"{what} must be numbers, got {text!r}") from None
    if values.size != n:
        raise InputError(f"{what} needs {n} values (one per factor), got {values.size}")
    return values


def read_table(path, numeric, labels=(), sheet=None) -> dict:
    """Read the named columns of a CSV or xlsx table.

    Parameters
    ----------
    path : path-like
        ``.csv`` or ``.xlsx``/``.xlsm``.
    numeric : sequence of str
        Columns that must hold a number in every row.
    labels : sequence of str
        Columns read as text labels (e.g. a block column); empty cells are refused.
    sheet : str, optional
        Sheet of a workbook (default the first).

    Returns
    -------
    dict
        Column -> numpy float array (numeric) or tuple of str (labels).

    Raises
    ------
    WorkbookError
        Missing column, empty or non-numeric cell, naming file, sheet, row (data rows counted
        from 1 under the header) and column.
    """
    import pandas as pd

    path = Path(path)
    if not path.exists():
        raise InputError(f"table not found: {path}")
    suffix = path.suffix.lower()
    if suffix == ".csv":
        try:
            frame = pd.read_csv(path, dtype=str, keep_default_na=False, skipinitialspace=True)
        except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
            raise WorkbookError(f"cannot read the table: {exc}", file=str(path)) from None
        sheet_name = None
    elif suffix in (".xlsx", ".xlsm"):
        try:
            frame = pd.read_excel(path, sheet_name=sheet if sheet is not None else 0, dtype=object)
        except ValueError as exc:  # unknown sheet
            raise WorkbookError(str(exc), file=str(path), sheet=sheet) from None
        sheet_name = sheet
    else:
        raise InputError(f"table must be .csv or .xlsx, got {path.name}")
    frame.columns = [str(c).strip() for c in frame.columns]
    for col in list(numeric) + list(labels):
        if col not in frame.columns:
            raise WorkbookError(f"missing column (columns present: {', '.join(frame.columns)})",
                                file=str(path), sheet=sheet_name, column=col)
    if len(frame) == 0:
        raise WorkbookError("the table has no data rows", file=str(path), sheet=sheet_name)

    def empty(v):
        return v is None or (isinstance(v, float) and math.isnan(v)) or str(v).strip() == ""

    out = {}
    for col in numeric:
        values = []
        for i, v in enumerate(frame[col].tolist()):
            try:
                if empty(v) or isinstance(v, bool):
                    raise ValueError
                x = float(str(v).strip()) if isinstance(v, str) else float(v)
                if not math.isfinite(x):
                    raise ValueError
            except (TypeError, ValueError):
                raise WorkbookError("expected a finite number", file=str(path), sheet=sheet_name,
                                    row=i + 1, column=col, value=v) from None
            values.append(x)
        out[col] = np.array(values)
    for col in labels:
        values = []
        for i, v in enumerate(frame[col].tolist()):
            if empty(v):
                raise WorkbookError("empty label", file=str(path), sheet=sheet_name, row=i + 1,
                                    column=col, value=v)
            values.append(str(v).strip() if not isinstance(v, float) or not v.is_integer()
                          else str(int(v)))
        out[col] = tuple(values)
    return out


def _coded_design(args, table, factors):
    x = np.column_stack([table[f] for f in factors])
    k = len(factors)
    if args.levels == "coded":
        if args.low or args.high:
            raise InputError("--low/--high apply to --levels actual only")
        return x, np.full(k, -1.0), np.full(k, 1.0), x
    if bool(args.low) != bool(args.high):
        raise InputError("give both --low and --high, or neither")
    low = _floats(args.low, "--low", k) if args.low else x.min(axis=0)
    high = _floats(args.high, "--high", k) if args.high else x.max(axis=0)
    for j, f in enumerate(factors):
        if not high[j] > low[j]:
            raise InputError(f"factor {f}: high level {float(high[j])!r} must exceed low level "
                             f"{float(low[j])!r} (a column that does not vary cannot be coded)")
    from demcal.analyse.designs import to_coded
    return to_coded(x, low, high), low, high, x


def _provenance(args, factors):
    return Provenance(inputs={str(args.table): sha256_file(args.table)},
                      options={"command": args.analyse_command, "factors": factors,
                               "response": args.response, "levels": args.levels,
                               "sheet": args.sheet,
                               "block": getattr(args, "block", None)}).to_dict()


def _run_pb(args) -> int:
    from demcal.analyse.screening import plackett_burman_screening

    factors = _split(args.factors, "--factors")
    dummies = _split(args.dummies, "--dummies") if args.dummies else []
    table = read_table(args.table, factors + dummies + [args.response], sheet=args.sheet)
    coded, low, high, _ = _coded_design(args, table, factors)
    dz = np.column_stack([table[d] for d in dummies]) if dummies else None
    result = plackett_burman_screening(coded, table[args.response], factors, dummies=dz,
                                       alpha=args.alpha, response_name=args.response,
                                       low=low, high=high)
    out = result.to_dict()
    out["provenance"] = _provenance(args, factors)
    write_json(args.json, out)
    sig = ", ".join(f"{t} ({result.factors[result.letters.index(t)]})" for t in result.significant)
    print(f"wrote {args.json}: significant at {args.alpha}: {sig or 'none'}")
    return 0


def _run_bbd(args) -> int:
    from demcal.analyse.optimise import canonical_analysis, optimise_to_target
    from demcal.analyse.regression import fit_response_surface

    factors = _split(args.factors, "--factors")
    labels = [args.block] if args.block else []
    table = read_table(args.table, factors + [args.response], labels, sheet=args.sheet)
    coded, low, high, _ = _coded_design(args, table, factors)
    blocks = table[args.block] if args.block else None
    fit = fit_response_surface(coded, table[args.response], args.model, factors=factors,
                               response_name=args.response, blocks=blocks, low=low, high=high)
    out = fit.to_dict()
    _, _, B = fit.second_order()
    out["canonical"] = canonical_analysis(fit).to_dict() if np.any(B) else None
    if args.target is not None:
        ref = _floats(args.reference, "--reference", len(factors)) if args.reference else None
        if ref is not None and args.levels == "coded":
            opt = optimise_to_target(fit, args.target, reference_coded=ref, seed=args.seed)
        else:
            opt = optimise_to_target(fit, args.target, reference_actual=ref, seed=args.seed)
        out["target_optimisation"] = opt.to_dict()
    out["provenance"] = _provenance(args, factors)
    write_json(args.json, out)
    print(f"wrote {args.json}: R2 {fit.fit.r2:.4f}, adj R2 {fit.fit.adj_r2:.4f}, "
          f"significant: {', '.join(fit.significant) or 'none'}")
    return 0


def _common(p):
    p.add_argument("table", type=Path, help="CSV or xlsx table of runs, one row per run")
    p.add_argument("--factors", required=True, help="factor columns, comma-separated (A, B, ...)")
    p.add_argument("--response", required=True, help="response column")
    p.add_argument("--json", required=True, type=Path, help="output JSON file")
    p.add_argument("--levels", choices=("coded", "actual"), default="coded",
                   help="factor columns hold coded (-1..1) or actual levels (default coded)")
    p.add_argument("--low", help="actual levels coded -1, comma-separated (with --levels "
                   "actual; write --low=-1,... when the first value is negative)")
    p.add_argument("--high", help="actual levels coded +1, comma-separated (with --levels actual)")
    p.add_argument("--sheet", help="sheet of an xlsx workbook (default the first)")


def register(subparsers) -> None:
    """Add ``demcal analyse pb|bbd``."""
    parser = subparsers.add_parser("analyse",
                                   help="analyse designed runs (screening, response surface)",
                                   description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="analyse_command", metavar="ANALYSIS")
    sub.required = True

    pb = sub.add_parser("pb", help="Plackett-Burman screening: effects, ANOVA, Pareto, Lenth")
    _common(pb)
    pb.add_argument("--dummies",
                    help="dummy (unassigned) columns, comma-separated, for Lenth's margins")
    pb.add_argument("--alpha", type=float, default=0.05, help="significance level (default 0.05)")
    pb.set_defaults(handler=_run_pb)

    bbd = sub.add_parser("bbd",
                         help="response-surface fit (Box-Behnken or any second-order design)")
    _common(bbd)
    bbd.add_argument("--block", help="block column (pure error is then taken within blocks)")
    bbd.add_argument("--model", choices=("linear", "2fi", "quadratic"), default="quadratic",
                     help="model order (default quadratic)")
    bbd.add_argument("--target", type=float,
                     help="also find settings where the fitted response equals this target")
    bbd.add_argument("--reference", help="reference point for --target (preferred solution is "
                     "the closest), comma-separated, in the units of --levels")
    bbd.add_argument("--seed", type=int, default=0, help="seed of the multi-start search")
    bbd.set_defaults(handler=_run_bbd)
