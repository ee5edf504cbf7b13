"""Calibration against a virtual lab whose heap photos are repose-twin heaps at a known truth
(``photos="dem"``), with contact parameters away from the paper's: the truth must lie inside
the reported 95 % interval of every parameter, and the validation must find the calibrated
heap equivalent to the photographed ones.

The default suite uses a small carton of each shape: 60 segments, about 70 round seeds, and a
carton scaled to 0.5 of three-sphere kernels and of two-sphere clumps (the two together
3 min 25 s on 2 cores, 2026-11-29). Their heaps scatter by five to ten degrees, so the lab's heap-to-heap
sd sets the tolerance. The full cartons are opt-in (``-m validation``): the paper's (about 20
minutes on 2 cores, the paper's 16 photos) and each other shape's default carton, photographed
FULL_PHOTOS (30) times, with up to FULL_VALIDATION_CAP (80) validation runs. The round seed's
and the kernel's heaps scatter by about 1.4 deg, so the tolerance is about that: with 16 photos
and 40 runs the validation had about 89 % power when on target and 67 % at a bias of 0.5 deg
(``analyse.equivalence.tost_power``), and the round seed's ended *undecided* once (30.46 deg
[30.09, 30.84] against 30.99, tolerance 1.0); with 30 photos and 80 runs it has 99.7 % and 91 %.
On 2026-11-29, on 2 cores, alone, every truth lay inside its 95 % interval and each validation
was *equivalent*: the round seed's in 13 min 23 s (23 heaps at 30.56 deg against the photos'
30.41, tolerance 1.51), the kernel's in 22 min 58 s (56 heaps at 33.28 deg against 33.47,
tolerance 1.43) and the clump's in 12 min 38 s (40 heaps at 38.05 deg against 37.40, tolerance
3.01).

Measured over seeds (lab seed 20 + k, campaign seed k; k = 1 is the test's own), with the virtual
lab photographing each twin heap's own spheres: the round seed's carton passed for every k in
1..6 (2026-11-28, about 100 s each on 2 cores). Six passes in six bound the pass rate below by
0.61 (one-sided 95 %), no more."""

from dataclasses import replace

import pytest

from demcal.analyse.campaign import CampaignConfig, calibrate
from demcal.measure.pipeline import measure_workbook
from demcal.simulate.params import DEMParameters, parse_shape
from demcal.simulate.shapes.kernel import Kernel
from demcal.simulate.rigs.repose import ReposeGeometry
from demcal.simulate.virtual_lab import Truth, write_virtual_workbook

#: Away from the paper's measured values (e 0.3 / 0.35, mu_s 0.65 / 0.2, mu_r 0.53 / 0.15).
TRUTH = DEMParameters(e_pp=0.45, e_pw=0.5, mu_s_pp=0.55, mu_s_pw=0.3, mu_r_pp=0.45, mu_r_pw=0.1,
                      poisson_ratio=0.3)
SMALL = ReposeGeometry(box_length=0.10, box_width=0.05, box_height=0.12, fill_count=60)

#: The other shapes' truths: TRUTH's contact parameters on a seed's material (1200 kg/m^3, a
#: shear modulus of 1.04 MPa as Boac et al. 2010 give soybeans, the time step 0.2 of the
#: Rayleigh time): a round seed, a round-section kernel of three spheres, a two-sphere clump.
OTHER_SHAPES = {
    "sphere": parse_shape("sphere:0.0066"),
    "kernel": Kernel(0.009, 0.006, 0.006, n_spheres=3),
    "clump": parse_shape({"shape": "clump", "length_m": 0.008, "table": [[0, 0, 0, 0.002], [0.004, 0, 0, 0.002]]}),
}


def virtual_campaign(root, geometry, config, truth=TRUTH, **lab):
    vw = write_virtual_workbook(Truth(params=truth), root / "lab", rng=21, photos="dem", workers=2,
                                geometry=geometry, **lab)
    m = measure_workbook(vw.path)
    return calibrate(vw.path, root / "campaign", config, measurement=m)


def check_truth_and_verdict(res, truth=TRUTH):
    """The truth against the calibration's intervals, as a run of a calibrated method can be
    held to: with 7 parameters, each truth inside its 95 % interval happens in only 70 % of
    runs (0.95^7), so at most 2 of the 7 lie outside (a calibrated method has 3 or more in
    0.4 % of runs) and every one lies within 3.29 posterior sd of the posterior mean (its
    99.9 % interval; 0.7 % of runs miss one); and the validation finds the heaps equivalent."""
    params = res.calibration.parameters
    outside = []
    for name, p in params.items():
        value = getattr(truth, name)
        assert abs(value - p.posterior_mean) <= 3.29 * p.posterior_sd, (name, value, p.posterior_mean, p.posterior_sd)
        if not p.ci95[0] <= value <= p.ci95[1]:
            outside.append((name, value, p.ci95))
    assert len(params) == 7 and len(outside) <= 2, outside
    assert res.validation.verdict == "equivalent", res.validation.test["note"]


#: 30 photos and up to 32 validation runs: 98 % power to show equivalence when on target
#: (analyse.equivalence.tost_power at the small carton's heap sd of about 9 deg).
SMALL_CONFIG = CampaignConfig(workers=2, progress=False, seed=1, noise_repeats=4, initial_points=6, batch=3,
                              budget_runs=24, validation_first=8, validation_step=8, validation_cap=32)
SMALL_LAB = dict(n_drop=2, n_incline=6, n_photos=30, n_tracks=0, n_specimens=10, n_compression=3)


def test_small_carton_virtual_lab(tmp_path):
    res = virtual_campaign(tmp_path, SMALL, SMALL_CONFIG, **SMALL_LAB)
    # a heap of 60 segments scatters by several degrees: the lab's own heaps set the tolerance
    assert res.validation.tolerance_deg > 3.0
    check_truth_and_verdict(res)


#: Each shape's default carton scaled down: the round seed's to 0.35 (about 70 seeds), the
#: others' to 0.5 (at 0.35 their heaps are too low to read).
SHAPE_SCALES = {"sphere": 0.35, "kernel": 0.5, "clump": 0.5}


@pytest.mark.parametrize("shape", [
    "sphere",
    "kernel",
    "clump",
])
def test_small_carton_virtual_lab_of_each_shape(shape, tmp_path):
    truth = replace(TRUTH, shape=OTHER_SHAPES[shape], particle_density_kg_m3=1200.0, shear_modulus_pa=1.04e6,
                    dt=None)
    geometry = ReposeGeometry.for_particle(truth.shape).scaled(SHAPE_SCALES[shape])
    res = virtual_campaign(tmp_path, geometry, SMALL_CONFIG, truth=truth, drop_heights_mm=(400.0,),
                           orientation_range_deg=(0.0, 90.0), **SMALL_LAB)
    check_truth_and_verdict(res, truth)


FULL_PHOTOS, FULL_VALIDATION_CAP = 30, 80


@pytest.mark.validation
@pytest.mark.parametrize("shape", ["sphere", "kernel", "clump"])
def test_full_carton_virtual_lab_of_each_shape(shape, tmp_path):
    # each shape's default carton (1705 round seeds, 1136 kernels of 3 spheres, 852 clumps of 2)
    # with the paper carton's campaign, except that the lab photographs FULL_PHOTOS heaps and
    # the validation may run FULL_VALIDATION_CAP times (see the module docstring)
    truth = replace(TRUTH, shape=OTHER_SHAPES[shape], particle_density_kg_m3=1200.0, shear_modulus_pa=1.04e6,
                    dt=None)
    config = CampaignConfig(seed=1, progress=False, validation_cap=FULL_VALIDATION_CAP)
    res = virtual_campaign(tmp_path, ReposeGeometry.for_particle(truth.shape), config, truth=truth,
                           drop_heights_mm=(400.0,), orientation_range_deg=(0.0, 90.0), n_photos=FULL_PHOTOS)
    check_truth_and_verdict(res, truth)


@pytest.mark.validation
def test_paper_carton_virtual_lab(tmp_path):
    # 16 photographed heaps: at the paper carton's heap sd (about 2.5 deg, the tolerance then)
    # 40 validation runs have about 80 % power to show equivalence when on target; with 8 the
    # power is 0.44 (the validation's own power rows say so)
    res = virtual_campaign(tmp_path, None, CampaignConfig(seed=1, progress=False), n_photos=16)
    check_truth_and_verdict(res)
