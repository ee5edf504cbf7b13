"""Contact effective mass: dashpots that damp the mass a contact moves (``contact_effective_mass``).

References used here: rigid-body impact theory with Newton's restitution (Stronge 2000, ch. 2-3;
Brach 2007, ch. 3), for one off-centre impact in closed form, and the flat landing of a
segment, whose contacts press together like one.
"""

import math

import pytest

from demcal.errors import InputError
from demcal.simulate.clump import segment_from_parameters
from demcal.simulate.extensions import engine_hooks, with_contact_effective_mass
from demcal.simulate.params import DEMParameters
from demcal.simulate.rigs import run_rig

E = 0.36


def test_contact_effective_mass_restores_the_contact_restitution_of_a_flat_landing():
    """A segment landing flat touches the plate with all its spheres at once; each contact
    damping with the whole mass leaves it far below the contact restitution (the glued-sphere
    damping, Kodam et al. 2010). Damping the effective mass: five equal dashpots in parallel are
    one dashpot of five times the stiffness, whose restitution is the contact one. End on (one
    contact) nothing changes."""
    params = DEMParameters(e_pw=E)
    on = with_contact_effective_mass(params)

    def rebound(p, orientation):
        return run_rig("drop", p, 0, orientation_deg=orientation).observable["apparent_restitution"]

    flat_off, flat_on = rebound(params, 0.0), rebound(on, 0.0)
    assert flat_off < 0.5 * E                        # the artefact the extension answers
    assert flat_on == pytest.approx(E, rel=0.05)
    assert rebound(on, 90.0) == rebound(params, 90.0)   # end on: one contact, bit for bit
    # switched off by default, recorded when on, and left out of the run keys when off
    assert not DEMParameters().contact_effective_mass and "contact_effective_mass" not in params.to_dict()
    assert [h["extension"] for h in engine_hooks(on)] == ["contact_effective_mass"]
    assert DEMParameters(**on.to_dict()) == on
    with pytest.raises(InputError, match="contact_effective_mass"):
        DEMParameters(contact_effective_mass=0.5)


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


@pytest.mark.parametrize("tilt_deg", [10.0, 30.0, 60.0])
def test_an_off_centre_impact_rebounds_as_the_rigid_body(tilt_deg):
    """A tilted segment striking a frictionless plate with its end sphere: one contact whose
    normal moves only the effective mass m_eff = 1 / (1/m + a^2 / I) (lever a, the end sphere's
    horizontal distance from the centre of mass). Rigid-body impact theory with restitution e
    at the contact gives the centre of mass the rebound ratio (1 + e) m_eff / m - 1. A dashpot
    set with the whole mass m realises a far lower e there; with the extension the dashpot
    damps m_eff and the twin follows the theory. A stiff plate and a short fall keep the turn
    during contact negligible, as the theory's instantaneous impulse assumes."""
    params = DEMParameters(e_pw=E, mu_s_pw=0.0, mu_r_pw=0.0, shear_modulus_pa=1e9)
    body = segment_from_parameters(params)
    lever = 0.5 * (params.segment_length_m - params.segment_diameter_m) * math.cos(math.radians(tilt_deg))
    m_eff = 1.0 / (1.0 / body.mass + lever ** 2 / max(body.principal_moments))  # transverse axis

    def realised_restitution(p):
        ratio = run_rig("drop", p, 0, height=0.1, orientation_deg=tilt_deg).observable["velocity_ratio"]
        return (1.0 + ratio) * body.mass / m_eff - 1.0

    assert realised_restitution(with_contact_effective_mass(params)) == pytest.approx(E, rel=0.02)
    assert realised_restitution(params) < 0.9 * E              # whole-mass dashpot: overdamped
