"""Power at a lab's sample size: each catalogue kind, planted at the virtual lab's default size
in workbooks of the size labs use (20 drops per pair, 20 trials per incline group, 6 heap
photos), is found by the critique's diagnosis in at least 80 % of them, by the lower 95 %
Clopper-Pearson bound over 100 workbooks per kind; and it is never ruled out. The
clean-workbook false-alarm bounds are in test_critique_planted.

The workbooks are measured without their twins (no DEM run but the drop twin's orientation
table, once), as ``demcal critique --no-twins`` does; at about 0.3 s a workbook without photos
(and seconds with them) the 700 workbooks are an opt-in validation run (``-m validation``)."""

import pytest
from scipy import stats

from demcal.analyse.critique import diagnosis
from demcal.analyse.critique.mechanisms import judge
from demcal.measure.pipeline import measure_workbook
from demcal.measure.workbook import read_workbook
from demcal.simulate.virtual_lab import PlantedEffect, Truth, write_virtual_workbook

#: A lab's design: 7 drops of each pair from each of 3 heights (21 per pair), 20 slide and 20
#: roll trials on each surface, 10 compressions, no camera track.
LAB = dict(photos="none", n_tracks=0, n_compression=10, n_drop=7, n_incline=20,
           drop_heights_mm=(200.0, 400.0, 600.0))
#: Where a signature needs its own design: photos for the camera, one height and hand-released
#: drops (20 per pair) for the orientation.
DESIGNS = {"camera_tilt": dict(photos="analytic", n_photos=6),
           "orientation_rotation": dict(drop_heights_mm=(400.0,), n_drop=20)}
KINDS = ("velocity_dependent_restitution", "size_dependence", "block_effect", "trial_order_drift",
         "moisture_dependence", "camera_tilt", "orientation_rotation")
N = 100


def verdicts(kind: str, seed: int, root) -> dict:
    vw = write_virtual_workbook(Truth(), root / f"w{seed}", effects=(PlantedEffect(kind),), rng=seed,
                                **{**LAB, **DESIGNS.get(kind, {})})
    wb = read_workbook(vw.path)
    tests, untestable = diagnosis.run_tests(diagnosis.measured_series(measure_workbook(wb), wb))
    out: dict = {}
    for f in judge(tests, untestable):
        out.setdefault(f.mechanism, set()).add(f.verdict)
    return out


@pytest.mark.validation
@pytest.mark.parametrize("kind", KINDS)
def test_each_kind_is_found_with_80_percent_power_at_a_labs_sample_size(kind, tmp_path):
    found = ruled_out = 0
    for seed in range(N):
        v = verdicts(kind, 9000 + seed, tmp_path)
        found += "found" in v.get(kind, ())
        ruled_out += "ruled_out" in v.get(kind, ())
    lower = float(stats.beta.ppf(0.05, found, N - found + 1)) if found else 0.0
    assert lower >= 0.8, (kind, found)
    assert ruled_out == 0, (kind, ruled_out)
