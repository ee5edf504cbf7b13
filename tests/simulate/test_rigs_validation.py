"""Long checks of the rig twins (opt in: ``pytest -m validation tests/simulate``).

- The quick repose profile reproduces the paper profile's angle within the seed scatter and
  responds to particle-steel friction in the same direction (benchmark conventions: LIGGGHTS'
  rolling lever and the cylinder mass model, the paper's calibrated parameters).
- The incline's slide onset is the same at a four times slower tilt.
"""

import math

import numpy as np
import pytest

from demcal.simulate.params import DEMParameters
from demcal.simulate.rigs import run_rig

pytestmark = pytest.mark.validation

BENCH = DEMParameters(e_pp=0.32, e_pw=0.36, mu_s_pw=0.22, mass_model="cylinder", rolling_lever="liggghts_reff")
SEEDS = (1, 2, 3)


def _angles(profile, params):
    return np.array([run_rig("repose", params, seed=s, profile=profile).observable["angle_deg"] for s in SEEDS])


def test_quick_profile_matches_paper_profile_within_seed_scatter():
    quick, paper = _angles("quick", BENCH), _angles("paper", BENCH)
    se = math.sqrt(quick.var(ddof=1) / len(SEEDS) + paper.var(ddof=1) / len(SEEDS))
    assert abs(quick.mean() - paper.mean()) < 3.0 * max(se, 1.0)


def test_quick_profile_responds_to_wall_friction_like_the_paper_profile():
    low, high = BENCH.with_(mu_s_pw=0.05), BENCH.with_(mu_s_pw=0.5)
    for profile in ("quick", "paper"):
        assert _angles(profile, high).mean() - _angles(profile, low).mean() > 10.0


def test_incline_slide_onset_at_a_slow_tilt():
    slow = run_rig("incline", BENCH, mode="slide", tilt_rate_deg_s=0.25).observable["slide_angle_deg"]
    assert slow == pytest.approx(math.degrees(math.atan(BENCH.mu_s_pw)), abs=0.1)
    default = run_rig("incline", BENCH, mode="slide").observable["slide_angle_deg"]
    assert abs(default - slow) < 0.1
