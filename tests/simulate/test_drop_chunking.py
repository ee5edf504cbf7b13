"""The drop rig's chunked stepping in contact finds the events of a record at every step.

``run_drop`` runs chunks of steps while the body touches the plate and runs a chunk again in
halves when an event may lie in it (simulate.rigs.drop). With every contact chunk set to one
step it records every step, as the rig did before; both must give the same observables and
event times (the engine's trajectory does not depend on the chunking, up to rounding, except
where a rolling torque stops a body: that constraint acts over each kick, and a chunk's end splits
one, so the drops through a sequence of end impacts, where the spin stops, have no rolling
friction here).
"""

from __future__ import annotations

import math

import pytest

import demcal.simulate.rigs.drop as drop
from demcal.simulate.params import DEMParameters

PARAMS = DEMParameters()
NO_ROLLING = DEMParameters(mu_r_pw=0.0, mu_r_pp=0.0)
EVENTS = ("t_contact", "t_separation", "t_apex", "z_contact", "z_apex")
OBSERVABLES = ("apparent_restitution", "velocity_ratio", "rotational_energy_share", "drop_height_m",
               "rebound_height_m")


def _per_step(monkeypatch, **kwargs):
    with monkeypatch.context() as m:
        for name in ("CONTACT_CHUNK_FRACTION", "CONTACT_CHUNK_ACTIVE", "CONTACT_CHUNK_QUIET"):
            m.setattr(drop, name, 0.0)
        return drop.run_drop(**kwargs)


@pytest.mark.parametrize("params, seed, orientation_deg", [
    (PARAMS, 0, 0.0),       # flat: five contacts at once, a small rebound
    (PARAMS, 0, 75.0),      # one end, rebound with a spin
    (NO_ROLLING, 1, None),  # 20 deg: one end strikes, the body pivots (still falling as it leaves)
    (NO_ROLLING, 6, None),  # 51 deg: both ends strike in turn
])
def test_chunked_contact_matches_a_record_at_every_step(monkeypatch, params, seed, orientation_deg):
    kwargs = dict(params=params, seed=seed, height=0.1, orientation_deg=orientation_deg)
    ref = _per_step(monkeypatch, **kwargs)
    res = drop.run_drop(**kwargs)
    assert res.record["t"].size < ref.record["t"].size
    dt = res.meta["dt"]
    for name in OBSERVABLES:
        a, b = ref.observable[name], res.observable[name]
        assert (math.isnan(a) and math.isnan(b)) or b == pytest.approx(a, rel=1e-9, abs=1e-12), name
    for name in EVENTS:
        a, b = ref.record[name], res.record[name]
        tol = 0.5 * dt if name.startswith("t_") else 1e-12
        assert (math.isnan(a) and math.isnan(b)) or abs(a - b) < tol, name
