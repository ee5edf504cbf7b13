"""Static and rolling friction from inclined-plane tests."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from demcal.errors import InputError
from demcal.measure.estimate import summarise
from demcal.measure.friction import from_tilt_angle, from_tilt_height, rolling_from_rollout

EXTERNAL = Path("/work/shared/external/lab_tests")


def test_tilt_angle_hand_values():
    assert from_tilt_angle(math.radians(45.0)) == pytest.approx(1.0)
    assert from_tilt_angle(math.radians(30.0)) == pytest.approx(1 / math.sqrt(3))
    # the source paper's mu_s p-p 0.65 corresponds to 33.0 deg
    assert from_tilt_angle(math.radians(33.0)) == pytest.approx(0.6494, abs=1e-4)


@pytest.mark.parametrize("angle", [0.0, math.pi / 2, -0.1])
def test_tilt_angle_outside_range(angle):
    with pytest.raises(InputError, match="angle"):
        from_tilt_angle(angle)


def test_rollout_hand_values():
    # theta 30 deg, H 50 mm, S 150 mm: 50 x 0.5 / (50 x 0.8660 + 150 x 0.5) = 25 / 118.30 = 0.2113
    assert rolling_from_rollout(math.radians(30), 0.05, 0.15) == pytest.approx(0.21132, abs=1e-5)
    # no run-out on the plate: the particle stopped at the foot, so mu_r = tan(theta)
    assert rolling_from_rollout(math.radians(20), 0.05, 0.0) == pytest.approx(math.tan(math.radians(20)))


def test_rollout_energy_balance():
    # work of the rolling resistance along slope and plate equals the potential energy released
    theta, H, S = math.radians(25), 0.08, 0.31
    mu = rolling_from_rollout(theta, H, S)
    work = mu * math.cos(theta) * H / math.sin(theta) + mu * S
    assert work == pytest.approx(H)


def _tilt_board():
    return pd.read_csv(EXTERNAL / "tilt_board_friction_upright_notes.csv")


def test_tilt_board_upright_notes_mu_is_tangent_not_h_over_l():
    d = _tilt_board()
    h, L = d.height_at_sliding_cm / 100, d.board_length_cm / 100
    mu = from_tilt_height(h, L)
    # foam die on cardboard: the source used h/L = 14/29.5 = 0.474; tan(asin(0.474)) = 0.539
    die = d.index[(d.object == "foam die (65 mm cube)") & (d.surface == "cardboard box")][0]
    assert d.authors_mu_h_over_L[die] == pytest.approx(14 / 29.5, abs=1e-3)
    assert mu[die] == pytest.approx(0.539, abs=1e-3)
    # the source's column is h/L (to its rounding) except where its notes say it used other
    # numbers: "mu = 5/30" (L 29.5 logged) and "height 13-14 cm, mu = 13/24" (h 13.5 logged)
    ratio = (h / L).to_numpy()
    differ = np.flatnonzero(np.abs(ratio - d.authors_mu_h_over_L) > 0.006)
    assert list(differ) == [0, 7]
    assert d.authors_mu_h_over_L[0] == pytest.approx(5 / 30, abs=0.01)
    assert d.authors_mu_h_over_L[7] == pytest.approx(13 / 24, abs=0.005)
    # tan > sin always, increasingly so on steeper boards
    assert np.all(mu > ratio)


def test_tilt_board_inconsistent_row_is_rejected_visibly():
    d = _tilt_board()
    rows = list(range(1, len(d) + 1))
    mu = from_tilt_height(d.height_at_sliding_cm / 100, d.board_length_cm / 100)
    flagged = d.note.fillna("").str.contains("inconsistent")
    assert flagged.sum() == 1
    rejected = [{"row": r, "reason": f"source note: {n}"}
                for r, n, f in zip(rows, d.note, flagged) if f]
    keep = ~flagged.to_numpy()
    est = summarise("static_friction.board", mu[keep], np.array(rows)[keep], unit="1",
                    source={"file": "tilt_board_friction_upright_notes.csv", "sheet": None,
                            "sha256": None},
                    method="tilt board", outliers="none", rejected=rejected)
    assert est.rows_rejected == rejected and est.rows_rejected[0]["row"] == 10
    assert "inconsistent in source" in est.rows_rejected[0]["reason"]
    assert est.n == len(d) - 1 and 10 not in est.rows_used
    assert est.value == pytest.approx(np.mean(mu[keep]))


def test_tilt_height_checks():
    with pytest.raises(InputError, match="board_length"):
        from_tilt_height(0.3, 0.3)
