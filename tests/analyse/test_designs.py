"""Designs: Plackett-Burman from its generator, Box-Behnken in Design-Expert's standard order,
coding of levels."""

import numpy as np
import pytest

from demcal.analyse.designs import (PB_GENERATORS, box_behnken, factor_letters, plackett_burman,
                             run_order, to_actual, to_coded)
from demcal.errors import InputError


def test_pb12_equals_bhh_printed_matrix(external):
    # BHH 2nd ed. 12-run Plackett-Burman as shipped in BsMD (PB12Des): same rows, same
    # columns, same signs - no permutation needed.
    bhh = external("screening_pb/pb12_design_matrix_bhh.csv").iloc[:, 1:].to_numpy(float)
    assert np.array_equal(plackett_burman(11, 12).coded, bhh)


def test_pb12_generator_plackett_burman1946():
    d = plackett_burman(7, 12)
    # First column is the published generator followed by the row of minuses.
    assert d.coded[:, 0].tolist() == [1, 1, -1, 1, 1, 1, -1, -1, -1, 1, -1, -1]
    assert d.columns == ("A", "B", "C", "D", "E", "F", "G", "dummy_1", "dummy_2", "dummy_3",
                         "dummy_4")
    assert d.factors.shape == (12, 7) and d.n_runs == 12


@pytest.mark.parametrize("runs", sorted(PB_GENERATORS))
def test_pb_columns_orthogonal_and_balanced(runs):
    x = plackett_burman(1, runs).coded
    assert x.shape == (runs, runs - 1)
    assert np.array_equal(x.T @ x, runs * np.eye(runs - 1))  # X'X = N I
    assert np.all(x.sum(axis=0) == 0)


def test_pb_rejects_bad_sizes():
    with pytest.raises(InputError, match="runs must be one of"):
        plackett_burman(3, 10)
    with pytest.raises(InputError, match="takes 1..11 factors"):
        plackett_burman(12, 12)


def test_bbd3_design_expert_standard_order():
    # Design-Expert's standard order for a 3-factor Box-Behnken with 5 centre points.
    expected = [[-1, -1, 0], [1, -1, 0], [-1, 1, 0], [1, 1, 0],
                [-1, 0, -1], [1, 0, -1], [-1, 0, 1], [1, 0, 1],
                [0, -1, -1], [0, 1, -1], [0, -1, 1], [0, 1, 1],
                [0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0]]
    d = box_behnken(3, centre_points=5)
    assert d.coded.tolist() == expected
    assert d.columns == ("A", "B", "C") and d.centre_points == 5


@pytest.mark.parametrize("k,runs", [(3, 12), (4, 24), (5, 40)])
def test_bbd_properties(k, runs):
    x = box_behnken(k, centre_points=3).coded
    assert x.shape == (runs + 3, k)
    assert np.all(x.sum(axis=0) == 0)
    # every pair of factors appears at its four corners exactly once
    assert np.allclose(x.T @ x, np.eye(k) * (x ** 2).sum(axis=0)[0])


def test_coding_round_trip_and_hand_values():
    low, high = [0.2, 0.30, 0.1], [0.4, 0.40, 0.3]
    # hand: (0.32 - 0.3)/0.1 = 0.2, (0.36 - 0.35)/0.05 = 0.2, (0.22 - 0.2)/0.1 = 0.2
    assert np.allclose(to_coded([0.32, 0.36, 0.22], low, high), [0.2, 0.2, 0.2])
    pts = np.random.default_rng(1).uniform(-1, 1, size=(20, 3))
    assert np.allclose(to_coded(to_actual(pts, low, high), low, high), pts)
    with pytest.raises(InputError, match="factor 1"):
        to_coded([0, 0], [0, 1], [1, 1])


def test_letters_skip_i_and_run_order_is_seeded():
    assert factor_letters(11) == tuple("ABCDEFGHJKL")
    assert np.array_equal(run_order(17, 3), run_order(17, 3))
    assert sorted(run_order(17, 3)) == list(range(17))
