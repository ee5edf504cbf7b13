"""The LIGGGHTS-PUBLIC 3.8 deck of the paper's repose case (simulate/liggghts).

Most tests read the generated script and meshes and need no LIGGGHTS; the last one runs the
deck for 200 steps and is skipped when the binary is absent.
"""

import math

import numpy as np
import pytest

from demcal.simulate.liggghts import deck as dk
from demcal.simulate.liggghts.run import find_liggghts, parse_log, read_positions, run_liggghts
from demcal.errors import InputError

CASE = dk.ReposeCase()
G = 9.81


def _commands(script: str) -> list:
    """Script lines without comments, blank lines or trailing comments, split into words."""
    out = []
    for line in script.splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            out.append(line.split())
    return out


def _find(commands, *prefix):
    hits = [c for c in commands if c[:len(prefix)] == list(prefix)]
    assert len(hits) == 1, f"expected one command starting {prefix}, found {len(hits)}"
    return hits[0]


def _after(words, key, n=1):
    i = words.index(key)
    return words[i + 1:i + 1 + n]


@pytest.fixture(scope="module")
def deck10(tmp_path_factory):
    return dk.write_deck(tmp_path_factory.mktemp("deck10"), seed=1, duration=10.0)


# ---- numbers of the case ---------------------------------------------------------------
def test_cylinder_mass_inertia_against_quadrature():
    """Closed forms against a midpoint quadrature over the 11 x 25 mm cylinder at 912 kg/m3."""
    d, length, rho = 0.011, 0.025, 912.0
    mass, i_ax, i_tr = dk.cylinder_mass_inertia(d, length, rho)
    n = 160
    r = 0.5 * d
    c = (np.arange(n) + 0.5) / n
    x, y, z = np.meshgrid((c - 0.5) * length, (c - 0.5) * d, (c - 0.5) * d, indexing="ij")
    inside = y ** 2 + z ** 2 <= r * r
    dm = rho * (length / n) * (d / n) ** 2
    assert mass == pytest.approx(inside.sum() * dm, rel=2e-3)
    assert i_ax == pytest.approx(dm * ((y ** 2 + z ** 2) * inside).sum(), rel=3e-3)
    assert i_tr == pytest.approx(dm * ((x ** 2 + z ** 2) * inside).sum(), rel=3e-3)
    # the number quoted for the case (2.17e-3 kg)
    assert mass == pytest.approx(2.167e-3, abs=1e-6)


def test_youngs_moduli_from_shear_moduli():
    # E = 2 G (1 + nu): particle G 1e7, nu 0.25; steel G 8e10, nu 0.3
    assert CASE.particle_youngs_modulus == pytest.approx(2.5e7)
    assert CASE.steel_youngs_modulus == pytest.approx(2.08e11)


def test_ten_seconds_is_134467_steps_and_plate_moves_at_4s(deck10):
    assert deck10.n_steps == 134467
    labels = [label for label, _ in deck10.phases]
    assert labels == ["fill_and_settle", "plate_lift", "heap_settle"]
    steps = dict(deck10.phases)
    assert steps["fill_and_settle"] * CASE.time_step == pytest.approx(4.0, abs=CASE.time_step)
    # the plate rises at least the carton height (it clears the heap) before it is stopped
    lift = steps["plate_lift"] * CASE.time_step * CASE.plate_lift_speed
    assert CASE.box_height < lift < CASE.box_height + 0.05


def test_script_issues_plate_motion_only_between_the_first_and_second_run(deck10):
    commands = _commands(deck10.script.read_text())
    runs = [i for i, c in enumerate(commands) if c[0] == "run"]
    assert [int(commands[i][1]) for i in runs] == [n for _, n in deck10.phases]
    lift = _find(commands, "fix", "lift")
    i_lift = commands.index(lift)
    assert runs[0] < i_lift < runs[1]
    assert lift[2:] == ["all", "move/mesh", "mesh", "plate", "linear", "0.0", "0.0", "0.1"]
    assert commands.index(["unfix", "lift"]) == runs[1] + 1


def test_short_run_has_no_plate_motion(tmp_path):
    d = dk.write_deck(tmp_path, seed=3, duration=1.5)
    assert d.phases == (("fill_and_settle", 20170),)
    assert "move/mesh" not in d.script.read_text()


def test_script_has_the_case_styles_and_numbers(deck10):
    c = _commands(deck10.script.read_text())
    assert _find(c, "units")[1] == "si"
    assert _find(c, "atom_style")[1] == "granular"
    assert _find(c, "newton")[1] == "off"  # fix multisphere requires it
    assert _find(c, "pair_style")[1:] == ["gran", "model", "hertz", "tangential", "history",
                                          "rolling_friction", "cdt"]
    assert float(_find(c, "timestep")[1]) == 7.43678e-5
    assert float(_find(c, "neighbor")[1]) == pytest.approx(0.5 * 5.5e-3)
    assert _find(c, "fix", "gravi")[3:] == ["gravity", "9.81", "vector", "0.0", "0.0", "-1.0"]

    def values(fix_id, n):
        words = _find(c, "fix", fix_id)
        return [float(v) for v in words[-n:]]

    # type 1 = segment, type 2 = steel; pair matrices row by row (11 12 21 22)
    assert values("m1", 2) == pytest.approx([2.5e7, 2.08e11])
    assert values("m2", 2) == pytest.approx([0.25, 0.3])
    assert values("m3", 4) == pytest.approx([0.32, 0.36, 0.36, 0.36])
    assert values("m4", 4) == pytest.approx([0.65, 0.22, 0.22, 0.22])
    assert values("m5", 4) == pytest.approx([0.53, 0.15, 0.15, 0.15])

    floor = _find(c, "fix", "floor")
    assert floor[-5:] == ["primitive", "type", "2", "zplane", "0.0"]
    carton = _find(c, "fix", "carton")
    assert carton[carton.index("meshes") + 1:] == list(dk.MESH_NAMES)
    for name in dk.MESH_NAMES:
        assert _find(c, "fix", name)[3:] == ["mesh/surface", "file", f"{name}.stl", "type", "2"]


def test_template_is_five_spheres_with_cylinder_mass_and_inertia(deck10):
    c = _commands(deck10.script.read_text())
    t = _find(c, "fix", "pts")
    assert t[3] == "particletemplate/multisphere"
    assert int(_after(t, "nspheres")[0]) == 5
    spheres = np.array(_after(t, "spheres", 20), dtype=float).reshape(5, 4)
    assert spheres[:, 0] == pytest.approx([-7e-3, -3.5e-3, 0.0, 3.5e-3, 7e-3])
    assert np.all(spheres[:, 1:3] == 0) and spheres[:, 3] == pytest.approx(5.5e-3)
    # clump length = 2 * 7 mm + 2 * 5.5 mm = 25 mm, as the segment
    assert np.ptp(spheres[:, 0]) + 2 * spheres[0, 3] == pytest.approx(0.025)
    m = float(_after(t, "mass")[0])
    assert m == pytest.approx(math.pi * 0.0055 ** 2 * 0.025 * 912, rel=1e-8)
    ixx, ixy, ixz, iyy, iyz, izz = (float(v) for v in _after(t, "inertia_tensor", 6))
    assert (ixy, ixz, iyz) == (0, 0, 0)
    assert ixx == pytest.approx(m * 0.0055 ** 2 / 2, rel=1e-8)  # axis along the sphere line
    assert iyy == izz == pytest.approx(m * (3 * 0.0055 ** 2 + 0.025 ** 2) / 12, rel=1e-8)
    assert "use_volume" in t and int(_after(t, "type")[0]) == 1
    _find(c, "fix", "ms", "all", "multisphere")


def test_insertion_is_500_bodies_in_one_second_in_the_fill_region(deck10):
    c = _commands(deck10.script.read_text())
    ins = _find(c, "fix", "ins")
    assert ins[3] == "insert/rate/region"
    assert int(_after(ins, "nparticles")[0]) == 500
    assert float(_after(ins, "particlerate")[0]) == 500.0
    assert _after(ins, "orientation") == ["random"] and _after(ins, "all_in") == ["yes"]
    assert _after(ins, "overlapcheck") == ["yes"] and _after(ins, "region") == ["fill"]
    assert int(_after(ins, "seed")[0]) == deck10.liggghts_seeds[2]
    region = _find(c, "region", "fill")
    assert [float(v) for v in region[3:9]] == pytest.approx([0.01, 0.19, 0.01, 0.09, 0.10, 0.24])
    # the last batch is due before t = 1 s
    every = int(_after(ins, "insert_every")[0])
    batches = math.ceil(500 / (500 * every * CASE.time_step))
    assert (batches - 1) * every * CASE.time_step < 1.0


# ---- carton meshes ----------------------------------------------------------------------
def _ray_hits(origin, direction, triangles) -> bool:
    """Does the ray origin + s direction (s > 0) cross any triangle (Moller-Trumbore)?"""
    for a, b, c in triangles:
        e1, e2 = b - a, c - a
        p = np.cross(direction, e2)
        det = e1 @ p
        if abs(det) < 1e-14:
            continue
        t = origin - a
        u = (t @ p) / det
        q = np.cross(t, e1)
        v = (direction @ q) / det
        s = (e2 @ q) / det
        if u >= 0 and v >= 0 and u + v <= 1 and s > 0:
            return True
    return False


def test_stl_meshes_round_trip_and_lie_on_the_carton_faces(deck10):
    L, W, H = CASE.box_length, CASE.box_width, CASE.box_height
    planes = {"back": (0, 0.0), "plate": (0, L), "side_y0": (1, 0.0), "side_y1": (1, W)}
    total_area = 0.0
    for name, path in deck10.meshes.items():
        tri = dk.read_ascii_stl(path)
        np.testing.assert_allclose(tri, dk.carton_meshes(CASE)[name], atol=1e-12)
        axis, value = planes[name]
        assert np.allclose(tri[:, :, axis], value)
        total_area += 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum()
        assert tri[:, :, 2].min() == 0.0 and tri[:, :, 2].max() == H
    assert total_area == pytest.approx(2 * (L + W) * H)


def test_meshes_close_the_carton_sideways(deck10):
    """From any point inside the carton, every horizontal ray meets a wall."""
    tri = np.concatenate([dk.read_ascii_stl(p) for p in deck10.meshes.values()])
    rng = np.random.default_rng(7)
    L, W, H = CASE.box_length, CASE.box_width, CASE.box_height
    points = rng.uniform([0, 0, 0], [L, W, H], size=(200, 3))
    angles = rng.uniform(0, 2 * np.pi, size=200)
    for p, a in zip(points, angles):
        for d in ([1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [np.cos(a), np.sin(a), 0]):
            assert _ray_hits(p, np.array(d, dtype=float), tri)
    # without the plate, the way out at x = L is open (and only there)
    no_plate = np.concatenate([dk.read_ascii_stl(p) for n, p in deck10.meshes.items() if n != "plate"])
    assert not _ray_hits(np.array([L / 2, W / 2, H / 2]), np.array([1.0, 0, 0]), no_plate)
    assert _ray_hits(np.array([L / 2, W / 2, H / 2]), np.array([-1.0, 0, 0]), no_plate)


# ---- seeds and input checks -------------------------------------------------------------
def test_liggghts_seeds_are_distinct_primes_above_10000():
    seeds = [s for k in range(50) for s in dk.liggghts_seeds(k)]
    assert len(set(seeds)) == len(seeds)
    for s in seeds:
        assert s > 10000 and all(s % k for k in range(2, math.isqrt(s) + 1))
    assert dk.liggghts_seeds(4) == dk.liggghts_seeds(4)


@pytest.mark.parametrize("kwargs, name", [
    ({"restitution_pp": 1.5}, "restitution_pp"),
    ({"time_step": -1e-5}, "time_step"),
    ({"particle_poisson": 0.5}, "particle_poisson"),
    ({"fill_region": (0.01, 0.19, 0.01, 0.09, 0.1, 0.3)}, "fill_region"),
    ({"n_segments": 2.5}, "n_segments"),
])
def test_bad_case_parameters_are_named(kwargs, name):
    with pytest.raises(InputError, match=name):
        dk.ReposeCase(**kwargs)


def test_bad_seed_and_duration_are_refused(tmp_path):
    with pytest.raises(InputError, match="seed"):
        dk.write_deck(tmp_path, seed=-1)
    with pytest.raises(InputError, match="duration"):
        dk.write_deck(tmp_path, seed=1, duration=0.0)


# ---- log and dump readers (on text as LIGGGHTS 3.8 writes it) ----------------------------
LOG_SAMPLE = """\
LIGGGHTS (Version LIGGGHTS-PUBLIC 3.8.0, compiled 2022-01-26-19:42:32 by buildd, git commit unknown)
WARNING: Energy calculated for multisphere particles is currently not correct (./src/fix_multisphere.cpp:1312)
    Step    Atoms            tke            rke            CPU 
       0        0              0              0              0 
INFO: Particle insertion ins: inserted 25 particle templates (mass 5.416891e-02) at step 1
 - a total of 25 particle templates (mass 5.416891e-02) inserted so far.
    1345      375    0.031891705  0.00013019777    0.071415271 
Loop time of 0.0714185 on 1 procs for 1345 steps with 375 atoms, finish time Sat Nov 21 08:03:42 2026
    Step    Atoms            tke            rke            CPU 
    1345      375    0.031891705  0.00013019777              0 
    2690      625     0.10735769   0.0039281725      0.1792032 
Loop time of 0.268541 on 1 procs for 1748 steps with 625 atoms, finish time Sat Nov 21 08:03:43 2026
"""


def test_parse_log_reads_version_loops_and_thermo():
    log = parse_log(LOG_SAMPLE)
    assert log["version"] == "LIGGGHTS-PUBLIC 3.8.0"
    assert [lp["steps"] for lp in log["loops"]] == [1345, 1748]
    assert [lp["loop_s"] for lp in log["loops"]] == [0.0714185, 0.268541]
    assert log["thermo"][:, 0].tolist() == [0, 1345, 2690]  # the repeated first line dropped
    assert log["thermo"][1, 2] == pytest.approx(0.031891705)
    assert len(log["warnings"]) == 1 and not log["errors"]


def test_read_positions_sorts_by_atom_id(tmp_path):
    path = tmp_path / "dump.txt"
    path.write_text("ITEM: TIMESTEP\n5\nITEM: NUMBER OF ATOMS\n2\nITEM: BOX BOUNDS ff ff ff\n"
                    "0 1\n0 1\n0 1\nITEM: ATOMS id mol x y z radius \n"
                    "7 2 0.5 0.25 0.125 0.0055 \n3 1 0.1 0.2 0.3 0.0055 \n")
    atom, body, pos, rad = read_positions(path)
    assert atom.tolist() == [3, 7] and body.tolist() == [1, 2]
    np.testing.assert_array_equal(pos, [[0.1, 0.2, 0.3], [0.5, 0.25, 0.125]])
    assert rad.tolist() == [0.0055, 0.0055]


# ---- a real LIGGGHTS run ----------------------------------------------------------------
@pytest.mark.skipif(find_liggghts() is None, reason="LIGGGHTS binary not installed")
def test_liggghts_runs_200_steps_of_the_deck(tmp_path):
    dt = CASE.time_step
    result = run_liggghts(seed=5, workdir=tmp_path, duration=200 * dt, nice=0,
                          dump_interval=100 * dt)
    assert result["version"].startswith("LIGGGHTS-PUBLIC 3.8")
    assert result["steps"] == 200 and result["lost_spheres"] == 0
    # the first batch (25 bodies) is inserted at step 1; nothing more before step 673
    assert result["bodies"] == 25 and result["spheres"] == 125
    assert np.all(np.bincount(result["body_id"])[np.unique(result["body_id"])] == 5)
    assert result["radii"] == pytest.approx(5.5e-3)

    def snapshot(step):
        atom, body, pos, _ = read_positions(tmp_path / "post" / f"dump.{step}")
        return body, pos

    body, p100 = snapshot(100)
    body200, p200 = snapshot(200)
    assert np.array_equal(body, body200)
    for b in np.unique(body):
        x = p200[body == b]
        # rigid 5-sphere line: neighbours 3.5 mm apart, ends 14 mm apart
        gaps = np.sort(np.linalg.norm(x[:, None] - x[None], axis=-1)[np.triu_indices(5, 1)])
        assert gaps[:4] == pytest.approx(3.5e-3, abs=2e-7) and gaps[-1] == pytest.approx(14e-3, abs=2e-7)
        # whole clump inside the fill region (all_in yes): centre at least 12.5 mm from its faces
        centre = p100[body == b].mean(axis=0)
        lo = np.array(CASE.fill_region[0::2]) + CASE.clump_half_length
        hi = np.array(CASE.fill_region[1::2]) - CASE.clump_half_length
        assert np.all(centre >= lo - 1e-6) and np.all(centre <= hi + 1e-6)
    # free fall from rest (no contact yet): every sphere drops g dt^2 ((200-s)^2 - (100-s)^2) / 2
    # between steps 100 and 200, s = 0 or 1 the step the body started; no drift sideways,
    # no rotation
    drop = p100[:, 2] - p200[:, 2]
    expected = [0.5 * G * dt * dt * ((200 - s) ** 2 - (100 - s) ** 2) for s in (1, 0)]
    assert np.all((drop > expected[0] * (1 - 1e-3)) & (drop < expected[1] * (1 + 1e-3)))
    np.testing.assert_allclose(p200[:, :2], p100[:, :2], atol=1e-7)


@pytest.mark.parametrize("shape", ["sphere:0.0066", "kernel:0.009:0.006:0.006"])
def test_any_shape_runs_in_liggghts_from_demcals_export(shape, tmp_path):
    """Another material's case takes its particle from demcal's LIGGGHTS export: the inserted
    bodies are the template's spheres at its radii, every one present after 200 steps."""
    from dataclasses import replace as with_

    from demcal.simulate.params import DEMParameters, parse_shape

    params = DEMParameters(shape=parse_shape(shape), particle_density_kg_m3=1200.0, shear_modulus_pa=1.04e6,
                           dt=None)
    case = dk.ReposeCase.for_params(params)
    template = params.template()
    assert case.spheres_per_particle == template.n_spheres
    assert case.clump_half_length == pytest.approx(template.bounding_radius)
    script = dk.render_script(case, seed=3)
    assert ("particletemplate/sphere" in script) == (template.n_spheres == 1)
    assert "soft_particles yes" in script      # E = 2.6 MPa: LIGGGHTS refuses it otherwise
    if find_liggghts() is None:
        pytest.skip("LIGGGHTS not installed")
    case = with_(case, fill_time=0.05)   # every body inserted in the first batch
    result = run_liggghts(seed=3, workdir=tmp_path, duration=200 * case.time_step, case=case, nice=0)
    assert result["lost_spheres"] == 0 and result["bodies"] > 0
    assert result["spheres"] == result["bodies"] * template.n_spheres
    np.testing.assert_allclose(np.sort(np.unique(np.round(result["radii"], 9))),
                               np.sort(np.unique(np.round(template.radii, 9))), rtol=1e-6)


def test_lifting_cylinder_deck_is_a_tube_mesh_lifted_between_runs(tmp_path):
    """The lifting cylinder's deck: a 64-gon tube around x = y = D/2 whose flats lie within
    0.12 % of the circle, lifted by move/mesh between the fill and the settle, filled inside it."""
    from demcal.simulate.params import DEMParameters
    from demcal.simulate.rigs.lifting_cylinder import CylinderGeometry
    from demcal.simulate.shapes.sphere import Sphere

    params = DEMParameters(shape=Sphere(0.00646), particle_density_kg_m3=1200, shear_modulus_pa=1.04e6, dt=None)
    case = dk.CylinderCase.for_cylinder(params, CylinderGeometry(0.06, 0.12, 0.01), lift_start=2.0)
    assert case.n_segments == 721 and case.box_length == case.box_width == 0.06
    deck = dk.write_deck(tmp_path, seed=2, duration=20.0, case=case)
    tube = dk.read_ascii_stl(deck.meshes["tube"])
    assert set(deck.meshes) == {"tube"} and tube.shape == (128, 3, 3)
    rho = np.hypot(tube[..., 0] - 0.03, tube[..., 1] - 0.03)
    np.testing.assert_allclose(rho, 0.03, rtol=1e-8)          # vertices on the circle (9 digits in the STL)
    mid = tube.mean(axis=1)                                             # flats inside it by 1 - cos(pi/64)
    assert np.hypot(mid[:, 0] - 0.03, mid[:, 1] - 0.03).min() > 0.03 * math.cos(math.pi / 64) * 0.999
    # the fill region lies inside the tube: its corners within the radius
    x0, x1, y0, y1, z0, z1 = case.fill_region
    assert max(math.hypot(x - 0.03, y - 0.03) for x in (x0, x1) for y in (y0, y1)) < 0.03
    commands = _commands(deck.script.read_text())
    runs = [i for i, c in enumerate(commands) if c[0] == "run"]
    lift = _find(commands, "fix", "lift")
    assert lift[2:] == ["all", "move/mesh", "mesh", "tube", "linear", "0.0", "0.0", "0.01"]
    assert runs[0] < commands.index(lift) < runs[1]
    assert _find(commands, "fix", "carton")[-1] == "tube"
    # lifted from 2 s until its rim is the clearance above its height
    steps = dict(deck.phases)
    assert steps["fill_and_settle"] * case.time_step == pytest.approx(2.0, abs=case.time_step)
    assert steps["plate_lift"] * case.time_step * 0.01 == pytest.approx(0.12 + case.plate_clearance, abs=1e-5)


def test_funnel_deck_is_a_cone_mesh_poured_into_and_holds_its_stream(tmp_path):
    """The funnel's deck: a 64-gon cone from the outlet to the rim around x = y = D/2, poured into
    from above the rim, nothing lifted; in LIGGGHTS the stream stays inside the cone and runs out
    of the outlet onto the floor."""
    from demcal.simulate.params import DEMParameters
    from demcal.simulate.rigs import rig
    from demcal.simulate.rigs.funnel import FunnelGeometry
    from demcal.simulate.shapes.sphere import Sphere

    params = DEMParameters(shape=Sphere(0.00646), particle_density_kg_m3=1200, shear_modulus_pa=1.04e6, dt=None)
    geo = FunnelGeometry(0.04, 0.12, 0.08, 0.07, fill_count=300)
    case = rig("funnel").liggghts_case(params, geo, 4.0)
    deck = dk.write_deck(tmp_path, seed=2, duration=1.2, case=case)
    cone = dk.read_ascii_stl(deck.meshes["funnel"])
    assert set(deck.meshes) == {"funnel"} and cone.shape == (128, 3, 3)
    rho = np.hypot(cone[..., 0] - 0.06, cone[..., 1] - 0.06)
    # vertices on the outlet circle at z = 70 mm and on the rim circle at z = 150 mm
    np.testing.assert_allclose(rho[cone[..., 2] < 0.1], 0.02, rtol=1e-8)
    np.testing.assert_allclose(rho[cone[..., 2] > 0.1], 0.06, rtol=1e-8)
    commands = _commands(deck.script.read_text())
    assert not [c for c in commands if "move/mesh" in c]
    assert [c[1] for c in commands if c[0] == "run"] == [str(case.steps(1.2))]
    x0, x1, y0, y1, z0, z1 = case.fill_region
    assert z0 == pytest.approx(0.15) and max(math.hypot(x - 0.06, y - 0.06) for x in (x0, x1) for y in (y0, y1)) < 0.06
    if find_liggghts() is None:
        pytest.skip("LIGGGHTS not installed")
    result = run_liggghts(seed=2, workdir=tmp_path, duration=1.2, case=case, nice=0)
    p = result["positions"]
    assert result["lost_spheres"] == 0 and result["bodies"] > 100
    # inside the funnel's height every seed is inside its cone; some have reached the floor
    inside = (p[:, 2] > 0.07) & (p[:, 2] < 0.15)
    r_cone = 0.02 + (p[inside, 2] - 0.07) * (0.04 / 0.08)
    assert np.all(np.hypot(p[inside, 0] - 0.06, p[inside, 1] - 0.06) < r_cone)
    assert np.sum(p[:, 2] < 0.02) > 10
    # the rig reads LIGGGHTS' spheres from the deck's record, as the check does
    heap = rig("funnel").measure(p, result["radii"], result["deck"]["case"])
    assert set(heap) >= {"angle_deg", "angle_profile_deg", "notes"}


def test_drum_deck_turns_its_tube_and_end_plates_about_the_axis_after_the_fill(tmp_path):
    """The drum's deck: a 64-gon tube along y and two square end plates, all three turned by
    move/mesh rotate about the drum's axis at its period from the rotation's start; filled inside
    the tube. In LIGGGHTS its bed is read by the rig's own estimator."""
    from demcal.simulate.params import DEMParameters
    from demcal.simulate.rigs import rig
    from demcal.simulate.rigs.drum import DrumGeometry
    from demcal.simulate.shapes.sphere import Sphere

    params = DEMParameters(shape=Sphere(0.00646), particle_density_kg_m3=1200, shear_modulus_pa=1.04e6, dt=None)
    case = rig("drum").liggghts_case(params, DrumGeometry(0.12, 0.03, 10.0, 0.4), 1.0)
    deck = dk.write_deck(tmp_path, seed=1, duration=1.6, case=case)
    tube = dk.read_ascii_stl(deck.meshes["drum"])
    assert set(deck.meshes) == {"drum", "end_y0", "end_y1"} and tube.shape == (128, 3, 3)
    np.testing.assert_allclose(np.hypot(tube[..., 0] - 0.06, tube[..., 2] - 0.07), 0.06, rtol=1e-8)
    commands = _commands(deck.script.read_text())
    runs = [i for i, c in enumerate(commands) if c[0] == "run"]
    spins = [i for i, c in enumerate(commands) if c[3:5] == ["move/mesh", "mesh"]]
    assert len(runs) == 2 and len(spins) == 3 and all(runs[0] < i < runs[1] for i in spins)
    for i in spins:     # 10 rpm: a 6 s period about the axis through (60, ., 70) mm along y
        assert commands[i][6:] == ["rotate", "origin", "0.06", "0.015", "0.07", "axis", "0.0", "1.0", "0.0",
                                   "period", "6"]
    x0, x1, y0, y1, z0, z1 = case.fill_region
    assert max(math.hypot(x - 0.06, z - 0.07) for x in (x0, x1) for z in (z0, z1)) < 0.06
    if find_liggghts() is None:
        pytest.skip("LIGGGHTS not installed")
    result = run_liggghts(seed=1, workdir=tmp_path, duration=1.6, case=case, nice=0)
    p = result["positions"]
    assert result["lost_spheres"] == 0 and result["bodies"] > 200
    assert np.all(np.hypot(p[:, 0] - 0.06, p[:, 2] - 0.07) < 0.06)          # inside the tube
    heap = rig("drum").measure(p, result["radii"], result["deck"]["case"])
    assert 0.0 < heap["angle_profile_deg"] < 60.0
