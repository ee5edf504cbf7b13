"""DEMParameters: the paper's defaults and the ``--set NAME=VALUE`` interface."""

from __future__ import annotations

import pytest

from demcal.errors import InputError
from demcal.simulate import DEMParameters
from demcal.simulate.shapes.segment import Segment
from demcal.simulate.shapes.sphere import Sphere


def test_defaults_are_the_paper_values():
    p = DEMParameters()
    assert (p.poisson_ratio, p.shear_modulus_pa, p.particle_density_kg_m3) == (0.25, 1e7, 912.0)
    assert (p.e_pp, p.e_pw, p.mu_s_pp, p.mu_s_pw, p.mu_r_pp, p.mu_r_pw) == (0.3, 0.35, 0.65, 0.2, 0.53, 0.15)
    assert (p.wall_density_kg_m3, p.wall_poisson_ratio, p.wall_shear_modulus_pa) == (7850.0, 0.3, 8e10)
    assert p.shape == Segment(0.025, 0.011, 5) and p.dt == 7.43678e-5
    assert (p.mass_model, p.rolling_lever) == ("union", "liggghts_reff")


def test_engine_hooks_are_off_by_default():
    p = DEMParameters()
    assert (p.e_pp_exponent, p.e_pw_exponent, p.e_pp_v_ref, p.e_pw_v_ref, p.e_pp_v_min, p.e_pw_v_min) == \
        (0.0, 0.0, 1.0, 1.0, 0.0, 0.0)
    assert (p.rolling_model, p.rolling_damping_ratio, p.particle_sizes) == ("constant_torque", 0.3, None)
    q = DEMParameters.from_names({"e_pw_exponent": "0.25", "rolling_model": "epsd", "particle_sizes": "none"})
    assert q.e_pw_exponent == 0.25 and q.rolling_model == "epsd" and q.particle_sizes is None


def test_from_names_converts_strings():
    p = DEMParameters.from_names({"e_pp": "0.32", "spheres_per_clump": "7", "rolling_lever": "liggghts_reff"})
    assert p.e_pp == 0.32 and p.shape.n_spheres == 7 and p.rolling_lever == "liggghts_reff"
    assert DEMParameters().with_(mu_s_pw=0.22).mu_s_pw == 0.22


def test_unknown_name_lists_the_valid_ones():
    with pytest.raises(InputError) as info:
        DEMParameters().with_(e_ppp=0.3)
    assert "'e_ppp'" in str(info.value) and "e_pp" in str(info.value) and "rolling_lever" in str(info.value)


@pytest.mark.parametrize("changes,match", [
    ({"e_pp": 0.0}, "e_pp"), ({"e_pw": 1.2}, "e_pw"), ({"mu_s_pp": -0.1}, "mu_s_pp"),
    ({"poisson_ratio": 0.5}, "poisson_ratio"), ({"mass_model": "voxel"}, "mass_model"),
    ({"rolling_lever": "edem"}, "edem_com, edem_sphere, liggghts_reff"),
    ({"mass_model": "scaled"}, "mean_mass_kg"), ({"spheres_per_clump": "2.5"}, "integer"),
    ({"shear_modulus_pa": "soft"}, "needs a number"),
    ({"rolling_model": "type_c"}, "constant_torque, epsd"), ({"rolling_damping_ratio": -1.0}, "rolling_damping_ratio"),
    ({"e_pw_v_ref": -2.0}, "e_pw_v_ref"), ({"e_pw_exponent": float("nan")}, "e_pw_exponent"),
    ({"particle_sizes": ((0.01, 0.02),)}, "exceeds the length"), ({"particle_sizes": ()}, "at least one"),
    ({"particle_sizes": "0.025-0.011"}, "AxB"), ({"particle_sizes": ((0.025,),)}, "has 2 size"),
    ({"shape": "sphere:0.0066", "particle_sizes": ((0.006, 0.007),)}, "has 1 size"),
])
def test_invalid_values_name_the_parameter(changes, match):
    with pytest.raises(InputError, match=match):
        DEMParameters().with_(**changes)


def test_the_shape_and_time_step_are_parameters_and_the_segments_former_fields_still_read():
    p = DEMParameters.from_names({"segment_length_m": "0.03", "segment_diameter_m": 0.01, "dt": "none"})
    assert p.shape == Segment(0.03, 0.01, 5) and p.dt is None
    assert DEMParameters.from_names({"shape": "sphere:0.0066"}).shape == Sphere(0.0066)
    stored = DEMParameters(shape=Sphere(0.0066), dt=2e-6).to_dict()
    assert stored["shape"] == {"shape": "sphere", "diameter_m": 0.0066} and stored["dt"] == 2e-6
    assert DEMParameters.from_names(stored) == DEMParameters(shape=Sphere(0.0066), dt=2e-6)
    with pytest.raises(InputError, match="segment_length_m set.s. the size of a segment; the shape is sphere"):
        DEMParameters(shape=Sphere(0.0066)).with_(segment_length_m=0.02)
    with pytest.raises(InputError, match=r"sphere needs 1 size\(s\) \[m\] \(diameter_m\)"):
        DEMParameters.from_names({"shape": "sphere"})
    with pytest.raises(InputError, match="dt must be a time step > 0"):
        DEMParameters(dt=-1.0)
