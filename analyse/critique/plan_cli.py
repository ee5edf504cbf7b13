"""``demcal plan``: the smallest effect of each catalogue mechanism a lab design would detect;
with ``--rigs``, what each repose rig of the design pins down alone and together.

    demcal plan WORKBOOK_OR_TRUTH [--mechanisms NAME,...] [--reps N] [--seed N] [--power 0.8]
                [--steps 4] [--photos none|analytic] [--alpha 0.01] [--correction bh|holm]
                [--json OUT]
    demcal plan TRUTH --rigs --out DIR [--seed N] [--profile quick|paper] [--workers N]
                [--budget-runs N] [--json OUT]

WORKBOOK_OR_TRUTH is a truth file (``.yaml``, as for ``demcal virtual-lab``) or a lab workbook,
whose sheets give the design and whose measured values give the truth
(``analyse.critique.plan``). Prints one row per mechanism: where it is planted, the smallest
effect detected in at least 80 % of the virtual workbooks, the detection rate there and its
Clopper-Pearson 95 % interval; then, for a design with drops, the drop twin's sensitivity of
the apparent restitution to the contact restitution by release orientation (where to drop).
"""

from __future__ import annotations

from demcal.jsonio import write_json
from demcal.measure.cli import add_workbook_options, read_options
from demcal.text import one_line

#: Longest note printed [characters].
NOTE_LIMIT = 2000


def register(subparsers) -> None:
    """Add the ``plan`` sub-command (the defaults written out: importing the planner at start-up
    would load the whole critique for every command)."""
    p = subparsers.add_parser(
        "plan", help="smallest effect of each mechanism a lab design detects with 80 %% power",
        description="For each data-effect mechanism of the critique's catalogue, plant it in virtual "
                    "workbooks of the design at growing sizes, run the critique's diagnosis on each, and "
                    "report the smallest size detected in at least the target share of them.")
    p.add_argument("source", metavar="WORKBOOK_OR_TRUTH",
                   help="truth file (.yaml, see data/virtual_lab/truth.yaml) or lab workbook")
    p.add_argument("--mechanisms", default="", metavar="NAME,...",
                   help="mechanisms to plan (default: every one the virtual lab can plant)")
    p.add_argument("--reps", type=int, default=20, help="virtual workbooks per effect size (%(default)s)")
    p.add_argument("--seed", type=int, default=0, help="seed of the virtual workbooks (%(default)s)")
    p.add_argument("--power", type=float, default=0.8, help="detection rate to reach (%(default)s)")
    p.add_argument("--steps", type=int, default=4, help="bisections of the effect size (%(default)s)")
    p.add_argument("--photos", choices=("none", "analytic"), default="none",
                   help="heap photos in the virtual workbooks: none (default, fast) or analytic "
                        "(plans camera_tilt too; slower)")
    p.add_argument("--alpha", type=float, default=0.01,
                   help="the critique's significance after correction (%(default)s)")
    p.add_argument("--correction", choices=("bh", "holm"), default="bh",
                   help="the critique's multiple-testing correction (%(default)s)")
    p.add_argument("--json", metavar="OUT", help="write the plan to this JSON file")
    g = p.add_argument_group("repose rigs (--rigs): what each rig of the truth file's design pins down")
    g.add_argument("--rigs", action="store_true",
                   help="instead of the mechanisms: write the truth file's virtual workbook, run each of its "
                        "repose rigs (design.repose_rig) up to the calibration's sequential runs, and give per "
                        "parameter the posterior/prior SD with each rig alone and with all together (DEM runs: "
                        "tens of minutes)")
    g.add_argument("--out", metavar="DIR", help="folder of the virtual workbook and the runs (kept: a second "
                                                "plan reruns nothing)")
    g.add_argument("--profile", choices=("quick", "paper"), default="quick",
                   help="the rigs' run profile (%(default)s)")
    g.add_argument("--workers", type=int, default=None, help="parallel DEM runs (default: the cores)")
    g.add_argument("--budget-runs", type=int, default=None,
                   help="runs of design and sequential rounds per rig (default: the calibration's)")
    add_workbook_options(p)
    p.set_defaults(handler=run)


def _num(x) -> str:
    return "-" if x is None else f"{x:.3g}"


def table(plan) -> str:
    """The plan as a text table, one row per mechanism."""
    pct = f"{100 * plan.power:g} %"
    head = (f"{'mechanism':<31} {'sheet':<8} {'covariate':<15} {'smallest effect at ' + pct + ' power':>30}  "
            f"{'rate':>9}  {'95 % CI':<13} unit")
    lines = [head]
    for m in plan.mechanisms:
        if m.sheet is None:
            lines.append(f"{m.mechanism:<31} {'-':<8} {'-':<15} {'-':>30}  {'-':>9}  {'-':<13} "
                         f"{one_line(m.note, limit=NOTE_LIMIT)}")
            continue
        size = _num(m.size) if m.reached else f"not reached at {_num(m.size)}"
        if m.at_floor:
            size = f"<= {size}"
        ci = f"[{m.ci95[0]:.2f}, {m.ci95[1]:.2f}]"
        lines.append(f"{m.mechanism:<31} {m.sheet:<8} {m.covariate:<15} {size:>30}  "
                     f"{m.hits:>4}/{m.n:<4}  {ci:<13} {m.unit}")
    return "\n".join(lines)


def orientation_table(rows) -> str:
    """The drop twin's sensitivity by release orientation (``plan.orientation_design``), one
    line per pair: where to drop to measure the contact restitution."""
    lines = []
    for pair in dict.fromkeys(r.pair for r in rows):
        mine = [r for r in rows if r.pair == pair]
        best = max(mine, key=lambda r: r.sensitivity)
        cells = "  ".join(f"{r.orientation_deg:g}: {r.sensitivity:.2f}" for r in mine)
        lines.append(f"  {pair}: d apparent / d e by release orientation [deg]: {cells}; best at "
                     f"{best.orientation_deg:g} deg (apparent {best.apparent:.3f})")
    return "\n".join(lines)


def _design_text(d: dict) -> str:
    parts = []
    if d["pairs"]:
        parts.append(f"drops {', '.join(d['pairs'])} from {', '.join(f'{h:g}' for h in d['drop_heights_mm'])} mm, "
                     f"{d['n_drop']} per pair and height")
    if d["surfaces"]:
        parts.append(f"incline {', '.join(d['surfaces'])}, {d['n_incline']} slide and {d['n_incline']} roll "
                     "trials each")
    parts.append(f"{d['n_specimens']} specimens, {d['n_compression']} compressions, heap photos "
                 + (f"{d['photos']} ({d['n_photos']})" if d["photos"] != "none" else "none"))
    return "; ".join(parts)


def run_rigs(args) -> int:
    """``demcal plan TRUTH --rigs``: the rig plan (``analyse.rig_plan``)."""
    from dataclasses import replace

    from demcal.analyse.campaign import CampaignConfig
    from demcal.analyse.rig_plan import plan_rigs
    from demcal.errors import InputError

    if not args.out:
        raise InputError("--rigs needs --out DIR: the folder of the virtual workbook and its runs")
    if args.mechanisms:
        raise InputError("--mechanisms plans the critique's mechanisms; --rigs plans the repose rigs: give one")
    config = replace(CampaignConfig(), profile=args.profile)
    if args.workers is not None:
        config = replace(config, workers=args.workers)
    if args.budget_runs is not None:
        config = replace(config, budget_runs=args.budget_runs)
    print(f"rig plan of {args.source}: the virtual workbook and the runs in {args.out}, seed {args.seed}")
    plan = plan_rigs(args.source, args.out, seed=args.seed, config=config)
    for note in plan.notes:
        print(f"note: {one_line(note, limit=NOTE_LIMIT)}")
    print(plan.table())
    if args.json:
        print(f"written: {write_json(args.json, plan.to_dict())}")
    return 0


def run(args) -> int:
    if args.rigs:
        return run_rigs(args)
    if args.out or args.budget_runs is not None:
        from demcal.errors import InputError

        raise InputError("--out and --budget-runs belong to --rigs (the repose rigs' plan)")
    from demcal.analyse.critique.cli import _list
    from demcal.analyse.critique.plan import check_options, plan_design, read_design

    mechanisms = _list(args.mechanisms, "--mechanisms")
    check_options(mechanisms=mechanisms, reps=args.reps, steps=args.steps, power=args.power, alpha=args.alpha,
                  correction=args.correction)
    lab = read_design(args.source, photos=args.photos, reading=read_options(args))
    print(f"plan of {lab.kind} {lab.source}: {args.reps} virtual workbooks per size, seed {args.seed}, "
          f"critique alpha {args.alpha:g} ({args.correction})")
    print(f"design: {_design_text(lab.design)}")
    for note in lab.notes:
        print(f"note: {one_line(note, limit=NOTE_LIMIT)}")     # may name the workbook's pairs
    plan = plan_design(lab, mechanisms=mechanisms or None, reps=args.reps, seed=args.seed, power=args.power,
                       steps=args.steps, alpha=args.alpha, correction=args.correction, progress=True)
    print(table(plan))
    for m in plan.mechanisms:
        if m.sheet is not None and m.note:
            print(f"{m.mechanism}: {one_line(m.note, limit=NOTE_LIMIT)}")
    out = plan.to_dict()
    pairs = lab.design.get("pairs") or ()
    if pairs:
        from demcal.analyse.critique.plan import orientation_design

        heights = sorted(lab.design["drop_heights_mm"])
        height = heights[len(heights) // 2]
        rows = orientation_design(lab.truth.params, pairs, height * 1e-3)
        print(f"where to drop (drop twin from {height:g} mm at the planned truth): a sensitivity near 1 "
              "reads the contact restitution itself, near 0 says little of it")
        print(orientation_table(rows))
        out["drop_orientations"] = [r.to_dict() for r in rows]
    if args.json:
        print(f"written: {write_json(args.json, out)}")
    return 0
