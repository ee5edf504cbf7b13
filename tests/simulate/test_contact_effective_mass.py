"""Contact effective mass: dashpots that damp the mass a contact moves (``contact_effective_mass``).

References used here: rigid-body impact theory with Newton's restitution at the contact point
(Stronge 2000, ch. 2-3; Brach 2007, ch. 3): one off-centre impact in closed form, and a
segment's sequence of end impacts (Stoianovici & Hurmuzlu 1996) from an event-driven drop
written here in three-dimensional vectors, independently of the engine and of
``simulate.rigid_impact``; and the flat landing of a segment, whose contacts press together
like one.

The engine is checked on a stiff plate (particle shear modulus 1e10 Pa) from 100 mm: a contact
lasts about 41 us, against 85 us between the two end impacts at 0.5 deg, and the body turns by
about 0.3 deg during the contact at 60 deg, so the impacts are nearly the instantaneous
impulses of the theory. (On the default particle, 1e7 Pa, a contact from 400 mm lasts about
0.5 ms: the end contacts overlap up to about 6 deg from flat and the body turns by 8 deg
during a contact at 60 deg; no instantaneous impacts there.)
"""

import math

import numpy as np
import pytest

from demcal.errors import InputError
from demcal.simulate.engine import Simulation
from demcal.simulate.extensions import engine_hooks, with_contact_effective_mass
from demcal.simulate.integrate import matrix_from_quat
from demcal.simulate.params import DEMParameters
from demcal.simulate.rigid_impact import rigid_drop
from demcal.simulate.rigs import run_rig
from demcal.simulate.rigs.drop import automatic_time_step, release_orientation
from demcal.simulate.rigs.surfaces import make_surface
from demcal.simulate.walls import Plane
from demcal.units import GRAVITY

E = 0.36
#: A frictionless, stiff plate and a short fall (see the module docstring).
STIFF = DEMParameters(e_pw=E, mu_s_pw=0.0, mu_r_pw=0.0, shear_modulus_pa=1e10)
HEIGHT = 0.1


# ---------------------------------------------------------------------------------------------
# the references: closed form and an event-driven rigid body


def _rotation(axis, angle):
    """Rotation matrix about ``axis`` by ``angle`` [rad] (Rodrigues)."""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * K @ K


def end_impact_ratio(body, tilt_deg):
    """-v_z after / v_z before of one impact of the lower end sphere: (1 + e) m_eff / m - 1,
    m_eff = 1 / (1/m + a^2 / I), a the end sphere's horizontal lever, I the transverse moment."""
    lever = 0.5 * (STIFF.shape.length_m - STIFF.shape.diameter_m) * math.cos(math.radians(tilt_deg))
    m_eff = 1.0 / (1.0 / body.mass + lever ** 2 / max(body.principal_moments))
    return (1.0 + E) * m_eff / body.mass - 1.0


def rigid_body_drop(body, tilt_deg, e, height, g=GRAVITY, step=1e-6):
    """Drop of the rigid clump onto the frictionless plane z = 0, one impact at a time.

    Each impact: j = -(1 + e) v_n / (1/m + (r x n) . I^-1 (r x n)) at the struck sphere's
    lowest point r. In flight the body falls and turns at its constant angular velocity (a
    principal axis, checked); the next impact is the first crossing of the plane on a ``step``
    [s] grid, bisected. Followed to the first apex of the centre of mass. Returns the first
    impact's velocity ratio, the rebound ratio -1 + (plate impulse) / (m v_in) and the struck
    spheres in order.
    """
    R = _rotation((0.0, 1.0, 0.0), -math.radians(tilt_deg))     # template -> world, as the rig
    A = body.principal_axes
    inertia = R @ A @ np.diag(body.principal_moments) @ A.T @ R.T
    arms = (np.asarray(body.centres) - body.centre_of_mass) @ R.T
    radii = np.asarray(body.radii)
    n = np.array([0.0, 0.0, 1.0])
    v_in = math.sqrt(2.0 * g * height)
    z = -float((arms[:, 2] - radii).min())
    v, w = -v_in * n, np.zeros(3)
    k = int(np.argmin(arms[:, 2] - radii))
    impulse, first, struck = 0.0, None, []
    reach = float((np.linalg.norm(arms, axis=1) + radii).max())
    while True:
        r = arms[k] - radii[k] * n
        rn = np.cross(r, n)
        inv_inertia = np.linalg.inv(inertia)
        j = -(1.0 + e) * (v + np.cross(w, r)) @ n / (1.0 / body.mass + rn @ inv_inertia @ rn)
        v = v + j * n / body.mass
        w = w + inv_inertia @ rn * j
        assert np.linalg.norm(np.cross(inertia @ w, w)) <= 1e-9 * np.linalg.norm(inertia @ w) * np.linalg.norm(w)
        impulse += j
        struck.append(k)
        first = v[2] / v_in if first is None else first
        # flight: to the apex when rising, else until the centre of mass has fallen by its reach
        end = v[2] / g if v[2] > 0.0 else (v[2] + math.sqrt(v[2] ** 2 + 2.0 * g * reach)) / g
        tau = np.arange(0.0, end + step, step)
        grid = _heights(tau, z, v[2], w, arms, radii, g)
        cross = (grid[:-1] > 0.0) & (grid[1:] <= 0.0)
        rows = np.flatnonzero(cross.any(axis=1))
        if rows.size == 0:
            break
        lo, hi = tau[rows[0]], tau[rows[0] + 1]
        crossing = np.flatnonzero(cross[rows[0]])
        while hi - lo > 1e-15:
            mid = 0.5 * (lo + hi)
            below = (_heights(mid, z, v[2], w, arms, radii, g)[0, crossing] <= 0.0).any()
            lo, hi = (lo, mid) if below else (mid, hi)
        k = int(crossing[np.argmin(_heights(hi, z, v[2], w, arms, radii, g)[0, crossing])])
        Q = _rotation(w, np.linalg.norm(w) * hi) if w.any() else np.eye(3)
        arms, inertia = arms @ Q.T, Q @ inertia @ Q.T
        z += v[2] * hi - 0.5 * g * hi * hi
        v = v - g * hi * n
    return first, -1.0 + impulse / (body.mass * v_in), struck


def _heights(t, z, vz, w, arms, radii, g):
    """Heights above the plane of each sphere's lowest point (columns) after times ``t`` [s]
    (rows) of flight: the centre of mass falling from ``z`` at ``vz``, the arms turning at
    ``w`` (Rodrigues)."""
    t = np.atleast_1d(np.asarray(t, float))
    rate = float(np.linalg.norm(w))
    if rate == 0.0:
        turned = np.broadcast_to(arms[:, 2], (t.size, arms.shape[0]))
    else:
        u = w / rate
        c, s = np.cos(rate * t)[:, None], np.sin(rate * t)[:, None]
        turned = arms[:, 2] * c + np.cross(u, arms)[:, 2] * s + u[2] * (arms @ u) * (1.0 - c)
    return (z + vz * t - 0.5 * g * t * t)[:, None] + turned - radii


def engine_rebound(params, tilt_deg, height):
    """The engine's drop (the drop rig's plate, release orientation and time step), from first
    touch to the first apex of the centre of mass: -1 + (plate impulse) / (m v_in), i.e.
    (v_z + g t) / v_in, gravity during the contacts left out as the reference leaves it out."""
    body = params.template()
    surface = make_surface(params, "steel")
    q, _ = release_orientation(tilt_deg, np.random.default_rng(0))
    arms = (body.centres - body.centre_of_mass) @ matrix_from_quat(q).T
    v_in = math.sqrt(2.0 * GRAVITY * height)
    sim = Simulation(surface.materials, domain_lo=(-0.2, -0.2, -0.05), domain_hi=(0.2, 0.2, 0.2),
                     dt=automatic_time_step(body, surface, height), gravity=(0.0, 0.0, -GRAVITY),
                     rolling_lever=params.rolling_lever)
    sim.add_wall(Plane((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), material=surface.plate_material))
    sim.add_clump(sim.add_template(body), position=(0.0, 0.0, -float((arms[:, 2] - body.radii).min())),
                  orientation=q, velocity=(0.0, 0.0, -v_in), material="particle")
    rose = False
    while True:
        sim.run(n_steps=500)
        vz = float(sim.velocities()[0, 2])
        touching = bool((sim.sphere_positions()[:, 2] < sim.sphere_radii()).any())
        rose = rose or vz > 0.0
        if rose and vz <= 0.0 and not touching:
            return (vz + GRAVITY * sim.time) / v_in


# ---------------------------------------------------------------------------------------------
# the references agree


def test_rigid_body_references_agree():
    """The event-driven drop here, ``simulate.rigid_impact`` (planar) and the closed form of one
    end impact give the same rebounds; a flat landing and an end-on one rebound at e."""
    body = STIFF.template()
    for tilt in (0.5, 1.0, 3.0, 10.0, 30.0, 45.0, 60.0, 75.0):
        first, rebound, struck = rigid_body_drop(body, tilt, E, HEIGHT)
        lib = rigid_drop(body, tilt, E, HEIGHT)
        assert lib.first_velocity_ratio == pytest.approx(first, abs=1e-9)
        assert lib.rebound_velocity_ratio == pytest.approx(rebound, abs=1e-6)
        assert [k for _, ks in lib.impacts for k in ks] == struck
        assert first == pytest.approx(end_impact_ratio(body, tilt), rel=1e-9)
    # a few degrees off flat the far end strikes after the near one and the body leaves the
    # plate close to, but not at, e; flat and end on it is e
    assert rigid_drop(body, 1.0, E, HEIGHT).impacts[1][1] == (4,)
    assert 0.34 < rigid_drop(body, 1.0, E, HEIGHT).rebound_velocity_ratio < E
    for tilt in (0.0, 90.0):
        drop = rigid_drop(body, tilt, E, HEIGHT)
        assert drop.rebound_velocity_ratio == pytest.approx(E, abs=1e-12)
        assert drop.apparent_restitution == pytest.approx(E, abs=1e-12)
    assert len(rigid_drop(body, 0.0, E, HEIGHT).impacts[0][1]) == body.n_spheres


# ---------------------------------------------------------------------------------------------
# the twin against them


def test_contact_effective_mass_restores_the_contact_restitution_of_a_flat_landing():
    """A segment landing flat touches the plate with all its spheres at once; each contact
    damping with the whole mass leaves it far below the contact restitution (the glued-sphere
    damping, Kodam et al. 2010). Damping the effective mass: five equal dashpots in parallel are
    one dashpot of five times the stiffness, whose restitution is the contact one. End on (one
    contact) nothing changes, bit for bit."""
    params = DEMParameters(e_pw=E)
    on = with_contact_effective_mass(params)

    def rebound(p, orientation):
        return run_rig("drop", p, 0, orientation_deg=orientation).observable["apparent_restitution"]

    flat_off, flat_on = rebound(params, 0.0), rebound(on, 0.0)
    assert flat_off < 0.5 * E                        # the artefact the extension answers
    assert flat_on == pytest.approx(E, rel=0.05)
    assert rebound(on, 90.0) == rebound(params, 90.0)
    # switched off by default, recorded when on, and left out of the run keys when off
    assert not DEMParameters().contact_effective_mass and "contact_effective_mass" not in params.to_dict()
    assert [h["extension"] for h in engine_hooks(on)] == ["contact_effective_mass"]
    assert DEMParameters(**on.to_dict()) == on
    with pytest.raises(InputError, match="contact_effective_mass"):
        DEMParameters(contact_effective_mass=0.5)


@pytest.mark.parametrize("tilt_deg", [10.0, 30.0, 60.0])
def test_an_off_centre_impact_leaves_the_rigid_body_velocity_ratio(tilt_deg):
    """A tilted segment striking the frictionless plate with its end sphere: one contact whose
    normal moves only the effective mass there. The drop rig's first-impact velocity ratio
    follows the closed form within 2 % with the extension; with the dashpot set by the whole
    mass the contact realises a far lower restitution."""
    body = STIFF.template()
    expected = end_impact_ratio(body, tilt_deg)

    def ratio(p):
        return run_rig("drop", p, 0, height=HEIGHT, orientation_deg=tilt_deg).observable["velocity_ratio"]

    assert ratio(with_contact_effective_mass(STIFF)) == pytest.approx(expected, rel=0.02)
    m_eff_over_m = (1.0 + expected) / (1.0 + E)
    assert (1.0 + ratio(STIFF)) / m_eff_over_m - 1.0 < 0.9 * E       # whole-mass dashpot: overdamped


@pytest.mark.parametrize("tilt_deg", [0.5, 1.0, 2.0, 3.0, 5.0, 10.0, 30.0, 60.0])
def test_the_rebound_follows_the_rigid_body_through_its_end_impacts(tilt_deg):
    """From 0.5 to 60 deg the segment's rebound, over its one or two end impacts, is the rigid
    body's within 2 % (the contacts here are short against the turn and the time between the
    end impacts, see the module docstring)."""
    _, expected, _ = rigid_body_drop(STIFF.template(), tilt_deg, E, HEIGHT)
    assert engine_rebound(with_contact_effective_mass(STIFF), tilt_deg, HEIGHT) == pytest.approx(expected, rel=0.02)


@pytest.mark.parametrize("tilt_deg", [1.0, 3.0, 10.0, 30.0, 45.0, 60.0, 75.0])
def test_the_drop_rig_reads_the_rebound_to_the_first_apex_in_flight(tilt_deg):
    """The drop rig's apparent restitution sqrt(h_rebound / h_drop) is the rigid body's
    (``simulate.rigid_impact``) to the first apex of the centre of mass after the whole impact
    sequence: a tilted segment's centre of mass still descends between its end impacts, and
    that is not the end of the rebound. Within 2 % (0.005 where the rebound is nearly nil)."""
    body = STIFF.template()
    expected = rigid_drop(body, tilt_deg, E, HEIGHT).apparent_restitution
    rig = run_rig("drop", with_contact_effective_mass(STIFF), 0, height=HEIGHT, orientation_deg=tilt_deg)
    assert rig.observable["apparent_restitution"] == pytest.approx(expected, rel=0.02, abs=0.005)


@pytest.mark.parametrize("tilt_deg", [0.0, 0.25, 0.5])
def test_near_flat_landings_rebound_at_the_contact_restitution(tilt_deg):
    """Within 0.5 deg of flat the rebound is the contact restitution within 5 % (flat, the five
    contacts press together; tilted, the rigid body's two end impacts give 0.350 for e = 0.36)."""
    assert engine_rebound(with_contact_effective_mass(STIFF), tilt_deg, HEIGHT) == pytest.approx(E, rel=0.05)


def test_files_naming_the_former_hook_read_as_contact_effective_mass():
    """Results, truth files and campaign settings written when the hook was called
    ``multi_contact_damping`` keep their meaning; the field is one, under its current name."""
    from demcal.analyse.campaign import CampaignConfig

    on = DEMParameters.from_names({"multi_contact_damping": True, "e_pw": E})
    assert on == DEMParameters(e_pw=E, contact_effective_mass=True)
    assert "multi_contact_damping" not in DEMParameters.names() and on.to_dict()["contact_effective_mass"]
    assert DEMParameters().with_(multi_contact_damping="true").contact_effective_mass
    with pytest.raises(InputError, match="given twice"):
        DEMParameters.from_names({"multi_contact_damping": True, "contact_effective_mass": False})
    config = CampaignConfig.from_dict({"model_extensions": {"multi_contact_damping": True}, "progress": False})
    assert config.model_extensions == {"contact_effective_mass": True}
