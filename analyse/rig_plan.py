"""``demcal plan TRUTH --rigs``: what each repose rig of a planned lab pins down alone, and what
the rigs pin down together.

A lab that photographs its heap in one rig learns little of most contact parameters (on the
paper's material only the steel static friction narrows). Before building a second rig it can
ask what the rig would buy. The truth file (``simulate.truth_file``) states the material, its
parameters and the lab's design, with the rigs to compare in ``design.repose_rig`` (e.g.
``repose_rig: lifted_plate, drum`` and each rig's dimensions). The plan

1. writes the virtual workbook of that design (``simulate.virtual_lab``): drops, inclines,
   compressions and the heap photos of every rig, at the truth (``photos: dem`` pours each rig's
   heaps with the twin; ``analytic`` draws every rig's heap at the truth's one
   ``repose_angle_deg``, a quick but rough stand-in, and the plan says so);
2. measures it, and runs the plausible calibration (``analyse.plausible``) up to its sequential
   runs: each rig's noise, design and surrogate, and the joint twins of the drops and inclines;
3. reports per parameter the posterior/prior sd with each rig's heap alone and with all
   together (the posterior of the same prior given the rigs' lab angles), and what each rig's
   runs cost.

The workbook and the runs stay in the output folder: a second plan of the same truth file and
seed measures the same workbook and reruns nothing.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

from demcal.errors import InputError
from demcal.jsonio import read_json, write_json
from demcal.provenance import Provenance, sha256_file

#: What the plan writes beside the workbook: the source it was made from, for reuse.
PLAN_FILE = "plan.json"


@dataclass(frozen=True)
class RigPlan:
    """What each repose rig pins down alone and all together.

    Attributes
    ----------
    source : str
        The truth file.
    workbook : str
        The virtual workbook the plan measured.
    rigs : dict
        Per rig (workbook name): its lab angle (``target_deg``, ``target_sd_deg``, ``heaps``),
        run sd, replicates, runs and the surrogate's leave-one-out RMSE.
    prior : dict
        Per parameter: the prior (``analyse.surrogate.Prior.to_dict``).
    by_rig : dict
        Per rig, per parameter: ``sd_ratio`` (posterior/prior sd) and ``ci95`` given that rig alone.
    together : dict
        Per parameter: the same given every rig's angle.
    notes : list of str
    provenance : Provenance
    """

    source: str
    workbook: str
    rigs: dict
    prior: dict
    by_rig: dict
    together: dict
    notes: list
    provenance: Provenance

    def gain(self, name: str) -> float:
        """How much the rigs together narrow ``name`` beyond the better single rig (posterior/prior
        sd of the best rig alone minus that of all together)."""
        return min(v[name]["sd_ratio"] for v in self.by_rig.values()) - self.together[name]["sd_ratio"]

    def to_dict(self) -> dict:
        d = asdict(self)
        d["provenance"] = self.provenance.to_dict()
        return d

    def table(self) -> str:
        """Per parameter: prior sd, posterior/prior sd with each rig alone and together."""
        rigs = list(self.by_rig)
        head = f"{'parameter':<15}{'prior sd':>10}" + "".join(f"{r + ' alone':>22}" for r in rigs)
        head += f"{'together':>12}{'narrowed by combining':>24}" if len(rigs) > 1 else ""
        lines = [head]
        for name, p in self.prior.items():
            row = f"{name:<15}{p['sd']:>10.3g}" + "".join(f"{self.by_rig[r][name]['sd_ratio']:>22.2f}" for r in rigs)
            if len(rigs) > 1:
                row += f"{self.together[name]['sd_ratio']:>12.2f}{self.gain(name):>+24.2f}"
            lines.append(row)
        lines.append("posterior/prior sd: near 1 the rig's heap says nothing of the parameter; each rig:")
        for r, v in self.rigs.items():
            lines.append(f"  {r}: lab angle {v['target_deg']:.3g} deg over {v['heaps']} heaps, one run's sd "
                         f"{v['run_sd_deg']:.2g} deg, {v['runs']} runs ({v['replicates']} per point), "
                         f"surrogate leave-one-out RMSE {v['loo_rmse_deg']:.2g} deg")
        return "\n".join(lines)


def plan_rigs(source, out_dir, *, seed: int = 0, config=None, runner=None) -> RigPlan:
    """The plan of the module docstring, for the truth file ``source``, in ``out_dir``.

    ``config`` (``analyse.campaign.CampaignConfig``) sets the profile, budget and workers (its
    seed is replaced by ``seed``); ``runner`` is the DEM runner (tests pass a stand-in).
    """
    from dataclasses import replace

    from demcal.analyse.campaign import CampaignConfig, identify_rigs
    from demcal.measure.pipeline import measure_workbook
    from demcal.simulate.truth_file import read_truth_file
    from demcal.simulate.virtual_lab import repose_geometries, write_virtual_workbook

    source = Path(source)
    if source.suffix.lower() not in (".yaml", ".yml"):
        raise InputError(f"{source}: the rig plan starts from a truth file (.yaml, as for demcal virtual-lab) whose "
                         "design names the repose rigs to compare (design.repose_rig: lifted_plate, drum)")
    spec = read_truth_file(source)
    design = dict(spec.design)
    if not design.get("repose_rig"):
        raise InputError(f"{source}: design.repose_rig names no repose rig to plan (e.g. repose_rig: "
                         "lifted_plate, drum with each rig's dimensions)")
    if design["photos"] == "none" or not design["n_photos"]:
        raise InputError(f"{source}: the rig plan needs heap photos (design photos dem and n_photos >= 2)")
    notes = []
    if design["photos"] == "analytic" and len(repose_geometries(design["repose_rig"])) > 1:
        notes.append(f"analytic photos: every rig's heaps are drawn at the truth's one angle "
                     f"({spec.truth.repose_angle_deg:g} deg), not at the twin's angle in that rig; photos: dem "
                     "pours each rig's heaps at the truth")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    workbook = out / "workbook.xlsx"
    made_from = {"source_sha256": sha256_file(source), "seed": int(seed)}
    previous = read_json(out / PLAN_FILE).get("made_from") if (out / PLAN_FILE).is_file() else None
    if workbook.is_file() and previous == made_from:
        notes.append(f"the virtual workbook {workbook} of an earlier plan of the same truth file and seed is measured again")
    else:
        write_virtual_workbook(spec.truth, workbook, rng=seed, **design)
        write_json(out / PLAN_FILE, {"made_from": made_from})
    measurement = measure_workbook(workbook)
    config = replace(config or CampaignConfig(), seed=int(seed), workflow="plausible")
    found = identify_rigs(measurement, config, out, runner=runner)
    plan = RigPlan(source=str(source), workbook=str(workbook), rigs=found["rigs"], prior=found["prior"],
                   by_rig=found["by_rig"], together=found["together"], notes=notes,
                   provenance=Provenance(inputs={str(source): made_from["source_sha256"],
                                                 **measurement.provenance.inputs},
                                         seed=int(seed), options={"profile": config.profile,
                                                                  "budget_runs": config.budget_runs,
                                                                  "likelihood": config.likelihood}))
    write_json(out / PLAN_FILE, {"made_from": made_from, "plan": plan.to_dict(), "stages": found["stages"]})
    return plan
