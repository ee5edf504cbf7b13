"""Static friction on a slowly tilting plate (the inclinometer of the paper's friction tests):
a body that cannot roll starts to slide at tan(theta) = mu_s (Coulomb's law of friction).

A flat clump of three spheres lies on the plate; the tilt is applied by turning gravity
(equivalent for a quasi-static test) at 2 deg/s from 2 deg below the expected angle. Sliding is
declared when the clump moves down the slope faster than 2 mm/s; at that tilt rate the body
reaches that speed within about 0.2 deg of the onset.
"""

from __future__ import annotations

import math

import numpy as np

import pytest

from demcal.simulate import DEMParameters
from demcal.simulate.clump import make_template
from tests.simulate.helpers import R, floor, simulation


def _gravity(deg):
    th = math.radians(deg)
    return (9.81 * math.sin(th), 0.0, -9.81 * math.cos(th))


@pytest.mark.parametrize("mu_s", [0.2, 0.5])
def test_slide_onset_coulomb_flat_clump_on_tilting_plate(mu_s):
    sim = simulation(DEMParameters(mu_s_pw=mu_s, mu_r_pw=0.15), dt=5e-5, lo=(-1.0, -0.2, -0.05),
                     hi=(1.0, 0.2, 0.1))
    a = 0.008  # sphere centres on a circle of 8 mm: overlapping spheres, a flat triangle
    tpl = sim.add_template(make_template([[a, 0.0, 0.0], [-a / 2, a * math.sqrt(3) / 2, 0.0],
                                          [-a / 2, -a * math.sqrt(3) / 2, 0.0]], R, 912.0))
    floor(sim)
    expected = math.degrees(math.atan(mu_s))
    tilt = expected - 2.0
    sim.gravity = _gravity(tilt)
    sim.add_clump(tpl, (0.0, 0.0, R))
    sim.run(duration=0.2)                       # settle
    assert abs(sim.velocities()[0, 0]) < 1e-6   # holds well below the angle
    rate, chunk = 2.0, 20
    while sim.velocities()[0, 0] < 0.002:
        sim.run(n_steps=chunk)
        tilt += rate * chunk * sim.dt
        sim.gravity = _gravity(tilt)
        assert tilt < expected + 2.0, "never slid"
    assert tilt == pytest.approx(expected, abs=0.5)
    assert abs(sim.angular_velocities()[0]).max() < 1e-6  # it slides, it does not roll


# ---------------------------------------------------------------------------------------------
# round particles: the sliding twin rolls first, the sled of glued particles slides at mu_s

def test_a_single_sphere_on_the_sliding_incline_rolls_first_whatever_its_friction():
    from demcal.simulate.rigs.incline import run_incline
    from demcal.simulate.shapes.sphere import Sphere

    params = DEMParameters(shape=Sphere(0.0066), particle_density_kg_m3=1200.0, dt=None, mu_r_pw=0.05)
    angles = [run_incline(params.with_(mu_s_pw=mu), mode="slide").observable["roll_angle_deg"]
              for mu in (0.3, 0.6)]
    assert angles[0] == pytest.approx(angles[1], abs=0.05)                 # no response to mu_s
    assert math.tan(math.radians(angles[0])) == pytest.approx(0.05, rel=0.1)   # it rolls at mu_r


def test_a_sled_of_glued_spheres_slides_at_tan_angle_equal_to_mu_s():
    """tan(onset) against mu_s over 0.2-0.6: slope 1 within 5 % (Coulomb), and each reading
    within 2 % of mu_s."""
    import numpy as np

    from demcal.simulate.rigs.incline import run_incline
    from demcal.simulate.shapes.sphere import Sphere

    params = DEMParameters(shape=Sphere(0.0066), particle_density_kg_m3=1200.0, dt=None)
    mus = np.array([0.2, 0.4, 0.6])
    readings = np.array([run_incline(params.with_(mu_s_pw=float(mu)), mode="sled").observable[
        "static_friction_apparent"] for mu in mus])
    assert readings == pytest.approx(mus, rel=0.02)
    assert np.polyfit(mus, readings, 1)[0] == pytest.approx(1.0, rel=0.05)


def test_a_sled_is_nine_particles_with_their_summed_mass_and_parallel_axis_inertia():
    from demcal.simulate.rigs.incline import SLED_GAP, sled_template
    from demcal.simulate.shapes.sphere import Sphere

    one = Sphere(0.006).template(1000.0)
    sled = sled_template(one)
    m, r = one.mass, 0.003
    step = 0.006 * (1 + SLED_GAP)
    assert sled.n_spheres == 9 and sled.mass == pytest.approx(9 * m)
    # about z: 9 (2/5 m r^2) + m step^2 (4 corners x 2 + 4 edges x 1) = 9 (0.4 m r^2) + 12 m step^2
    assert max(sled.principal_moments) == pytest.approx(9 * 0.4 * m * r * r + 12 * m * step ** 2, rel=1e-9)


# ---------------------------------------------------------------------------------------------
# the calibration's runs start tilted below Coulomb's onset

@pytest.mark.parametrize("shape, mode, surface, mu_s", [
    ("segment", "slide", "steel", 0.6), ("segment", "slide", "particle", 0.4), ("sphere", "sled", "steel", 0.45)])
def test_a_twin_run_started_tilted_reads_the_onset_of_one_started_flat(shape, mode, surface, mu_s):
    """The calibration's task starts at 0.8 atan(mu_s): the onset it reads is that of the lab's
    tilt from 0 within one 0.01 deg chunk, in fewer steps."""
    from demcal.simulate.rigs.incline import CHUNK_DEG, run_incline, run_task, task
    from demcal.simulate.shapes.sphere import Sphere

    params = (DEMParameters() if shape == "segment" else
              DEMParameters(shape=Sphere(0.0066), particle_density_kg_m3=1200.0, dt=None))
    params = params.with_(**{"mu_s_pw" if surface == "steel" else "mu_s_pp": mu_s})
    inputs = task(params, mode, surface)
    assert inputs["start_deg"] == pytest.approx(0.8 * math.degrees(math.atan(mu_s)), abs=0.005)
    flat = run_incline(params, mode=mode, surface=surface)
    tilted = run_task(inputs)
    assert tilted["observable"]["slide_angle_deg"] == pytest.approx(flat.observable["slide_angle_deg"],
                                                                    abs=CHUNK_DEG)
    assert tilted["steps"] < flat.meta["steps"] / 3


def test_a_friction_whose_tilted_start_lies_beyond_the_runs_last_tilt_starts_flat():
    """mu_s may reach 5 in a calibration's prior: 0.8 atan(4) = 60.8 deg lies beyond the 60 deg a
    run tilts to, so the run starts flat (and reads no onset, as before), instead of being
    refused; just below, it starts tilted."""
    from demcal.simulate.rigs.incline import MAX_TILT_DEG, RESTART_WITHIN_DEG, task

    assert task(DEMParameters(mu_s_pw=4.0), "slide", "steel")["start_deg"] == 0.0
    below = math.tan(math.radians((MAX_TILT_DEG - 2 * RESTART_WITHIN_DEG) / 0.8))
    assert 0.0 < task(DEMParameters(mu_s_pw=below), "slide", "steel")["start_deg"] < MAX_TILT_DEG


def test_a_twin_run_that_moves_at_once_is_run_again_from_flat():
    """A single sphere on the sliding twin rolls at once at the tilted start: the task runs it
    again from 0, so it reports the rolling onset the lab would see, not the start angle."""
    from demcal.simulate.rigs.incline import run_incline, run_task, task
    from demcal.simulate.shapes.sphere import Sphere

    params = DEMParameters(shape=Sphere(0.0066), particle_density_kg_m3=1200.0, dt=None, mu_r_pw=0.05,
                           mu_s_pw=0.45)
    inputs = task(params, "slide", "steel")
    assert inputs["start_deg"] > 15.0
    flat = run_incline(params, mode="slide", surface="steel")
    again = run_task(inputs)
    # the sphere only rolls: no sliding onset (NaN) in either
    assert math.isnan(flat.observable["slide_angle_deg"])
    same = {k: v for k, v in flat.observable.items() if not (isinstance(v, float) and math.isnan(v))}
    assert {k: again["observable"][k] for k in same} == same
    assert all(math.isnan(again["observable"][k]) for k in flat.observable.keys() - same.keys())
    assert again["steps"] > flat.meta["steps"]          # both runs are counted
    assert any(n.startswith("moved at once when started tilted") for n in again["notes"])


def test_the_rolled_arc_keeps_counting_past_half_a_turn():
    """A sphere that only rolls moves its centre by exactly its rolled arc. Taken from the
    rotation since the start, the arc wrapped at half a turn (pi h, 10.4 mm for a 6.6 mm sphere)
    and the slip jumped by twice that, read as a slide at 3.66 deg. Added up piece by piece, it
    follows the 50 mm the sphere rolls: the slip stays below the threshold, and no slide is read."""
    from demcal.simulate.rigs.incline import STOP_DISTANCE, run_incline
    from demcal.simulate.shapes.sphere import Sphere

    params = DEMParameters(shape=Sphere(0.0066), particle_density_kg_m3=1200.0, dt=None, mu_r_pw=0.05,
                           mu_s_pw=0.45)
    res = run_incline(params, mode="slide", surface="steel")
    rec = res.record
    assert rec["displacement"][-1] > STOP_DISTANCE > 4 * math.pi * rec["rolling_height"]   # two turns
    assert rec["rolled_arc"][-1] == pytest.approx(rec["displacement"][-1], abs=1e-4)
    assert np.all(np.abs(rec["slip"]) < res.provenance.options["threshold"])
    assert math.isnan(res.observable["slide_angle_deg"])
    assert math.degrees(math.atan(0.05)) < res.observable["roll_angle_deg"] < 3.5


def test_the_spring_dashpot_rolling_models_windup_is_not_read_as_rolling():
    """Under the spring-dashpot rolling model a soft sphere (G 1.04 MPa, mu_r 0.05) winds its
    rolling spring elastically by up to d_n / (2.25 mu_r) = 37 um of arc before it rolls; read as
    rolling it gave an onset of 0.79 deg. Counted beyond that windup, the onset is the constant
    torque model's (within 0.05 deg) and tan(onset) is mu_r within 10 % (the detection lag)."""
    from demcal.simulate.rigs.incline import run_incline
    from demcal.simulate.shapes.sphere import Sphere

    params = DEMParameters(shape=Sphere(0.0066), particle_density_kg_m3=1200.0, shear_modulus_pa=1.04e6,
                           dt=None, mu_r_pw=0.05, mu_s_pw=0.6)
    cdt = run_incline(params, mode="roll")
    epsd = run_incline(params.with_(rolling_model="epsd"), mode="roll")
    assert cdt.record["elastic_rolling_arc"] == 0.0
    assert 20e-6 < epsd.record["elastic_rolling_arc"] < 60e-6
    assert epsd.observable["roll_angle_deg"] == pytest.approx(cdt.observable["roll_angle_deg"], abs=0.05)
    assert epsd.observable["rolling_friction_apparent"] == pytest.approx(0.05, rel=0.1)


@pytest.mark.parametrize("mu_s", [0.12, 0.25])
def test_a_kernel_that_rocks_onto_its_next_sphere_is_not_read_as_sliding(mu_s):
    """The kernel shape on its flat side rests on its middle sphere, whose centre is its centre
    of mass: it balances like a ball, rolls at tan(theta) = mu_r until an end sphere meets the
    plate (17.6 deg of turn for this maize kernel), and that landing slips it by tens of
    micrometres whatever its friction. The reading is the slide that follows, at tan(theta) =
    mu_s (Coulomb, within the detection lag), and the knock is in the run's notes."""
    from demcal.simulate.rigs.incline import run_incline
    from demcal.simulate.shapes.kernel import Kernel

    mu_r = 0.0782
    params = DEMParameters(shape=Kernel(10.54e-3, 7.26e-3, 4.57e-3, n_spheres=3), dt=None,
                           particle_density_kg_m3=1425.0, shear_modulus_pa=1.04e6, poisson_ratio=0.3,
                           e_pp=0.318, mu_s_pp=mu_s, mu_r_pp=mu_r)
    res = run_incline(params, mode="slide", surface="particle")
    assert res.observable["roll_angle_deg"] == pytest.approx(math.degrees(math.atan(mu_r)), abs=0.3)
    assert res.observable["static_friction_apparent"] == pytest.approx(mu_s, abs=0.005)
    assert any(note.endswith("and stopped: not read as a slide") for note in res.meta["notes"])
