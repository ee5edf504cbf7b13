"""The joint calibration's twins (analyse.twin_likelihood): a twin that does not respond to its
own parameter is reported as uninformative and leaves that parameter at its measured prior."""

from __future__ import annotations

import numpy as np
import pytest

from tests.analyse.standin import heap_standin_runner

#: What a single sphere reads on the sliding incline whatever its friction: it rolls first, at
#: tan(angle) = mu_r (a constant here).
ROLLING_SPHERE_READING = 0.164


def _deaf_runner(task: dict) -> dict:
    """The stand-in's twins, except the particle-steel slide twin, which reads a constant."""
    if task.get("rig") == "incline" and task["surface"] == "steel" and task["mode"] == "slide":
        return {"rig": "incline", "observable": {"static_friction_apparent": ROLLING_SPHERE_READING}}
    return heap_standin_runner(task)


def _execute(stage, tasks):
    return [{"key": f"{stage}-{i}", "seed": 0, "result": _deaf_runner(t)} for i, t in enumerate(tasks)]


def test_a_twin_that_does_not_respond_to_its_parameter_is_uninformative_and_not_used(measurement):
    from demcal.analyse.campaign import base_parameters, factor_levels
    from demcal.analyse.plausible import measured_prior
    from demcal.analyse.twin_likelihood import twin_constraints

    factors = factor_levels(measurement, "minmax")
    constraints = twin_constraints(measurement, base_parameters(measurement), factors, _execute,
                                   lambda records: [{"key": r["key"]} for r in records])
    deaf, heard = constraints["mu_s_pw"], constraints["mu_s_pp"]
    assert not deaf.informative and deaf.response == pytest.approx(0.0, abs=1e-12)
    assert "does not respond to its parameter" in deaf.note
    # the stand-in's other slide twin reads mu_s itself: it changes by the grid's width
    assert heard.informative and heard.response == pytest.approx(heard.grid[-1] - heard.grid[0], rel=1e-9)
    prior = measured_prior(measurement, factors, constraints)
    i = prior.names.index("mu_s_pw")
    est = measurement.quantities["static_friction.steel"]
    assert prior.sources[i] == "static_friction.steel"            # the measured prior, not the twin's
    assert prior.mean[i] == pytest.approx(est.value) and prior.sd[i] == pytest.approx(est.sd)


@pytest.mark.parametrize("n", [2, 3, 5, 20])
def test_the_twin_posterior_covers_the_parameter_at_any_number_of_trials(n):
    """A twin whose reading is 0.9 theta, n trials of sd 0.03 at theta = 0.5: the posterior's
    mean +- 1.96 sd covers theta in at least 93 % of 2000 labs (lower 95 % Clopper-Pearson
    bound). The standard error estimated from n trials needs the Student-t likelihood: a
    normal one covered 71 % at n = 2, 81 % at 3 and 89 % at 5."""
    from scipy import stats

    from demcal.analyse.twin_likelihood import _grid_posterior
    from demcal.simulate.rigs import rig

    rng = np.random.default_rng(n)
    grid = rig("drop").grid(0.5, 0.03, (0.01, 1.0))
    reps, covered = 2000, 0
    for _ in range(reps):
        resid = 0.45 + 0.03 * rng.standard_normal(n) - 0.9 * grid[:, None]
        mean, sd, _ = _grid_posterior(grid, resid.mean(axis=1), resid.std(axis=1, ddof=1) / np.sqrt(n), n)
        covered += abs(mean - 0.5) <= 1.96 * sd
    assert stats.beta.ppf(0.05, covered, reps - covered + 1) >= 0.93, covered / reps
