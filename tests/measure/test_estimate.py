"""Estimate summaries and outlier screening against hand calculations and printed tables."""

from __future__ import annotations

import math

import pytest

from demcal.errors import InputError
from demcal.measure.estimate import (Estimate, grubbs_critical, mean_sd_ci95, parse_outlier_rule,
                              screen_outliers, summarise)

SOURCE = {"file": "f.csv", "sheet": "s", "sha256": "0" * 64}


def test_mean_sd_ci95_student_t_table():
    # 24, 25, 26: mean 25, sd 1; t(0.975, 2) = 4.303 (printed t tables), half width 4.303 / sqrt(3)
    mean, sd, (lo, hi) = mean_sd_ci95([24.0, 25.0, 26.0])
    assert mean == 25.0 and sd == pytest.approx(1.0)
    assert hi - 25.0 == pytest.approx(4.303 / math.sqrt(3), abs=5e-4)
    assert 25.0 - lo == pytest.approx(hi - 25.0)


def test_mean_sd_ci95_small_samples():
    assert mean_sd_ci95([3.0])[0] == 3.0
    assert math.isnan(mean_sd_ci95([3.0])[1])
    assert math.isnan(mean_sd_ci95([])[0])


def test_mad_rule_hand_example():
    # median 10.025; |deviations| .025 .075 .125 .025 .075 1.975 -> MAD .075, scale .1112;
    # 1.975 / .1112 = 17.8 > 3.5 (rejected), .125 / .1112 = 1.12 (kept)
    reasons = screen_outliers([10.0, 10.1, 9.9, 10.05, 9.95, 12.0], "mad")
    assert [r is None for r in reasons] == [True] * 5 + [False]
    assert "3.5 x 1.4826 MAD" in reasons[5]
    # a stricter limit of 1.0 also rejects 9.9 (1.124)
    reasons = screen_outliers([10.0, 10.1, 9.9, 10.05, 9.95, 12.0], "mad:1.0")
    assert [r is None for r in reasons] == [True, True, False, True, True, False]


def test_mad_rule_when_mad_is_zero():
    # MAD 0 -> 1.2533 x mean absolute deviation = 1.2533 / 6 = 0.209; |2 - 1| / 0.209 = 4.8
    reasons = screen_outliers([1.0, 1.0, 1.0, 1.0, 1.0, 2.0])
    assert reasons[:5] == [None] * 5 and "mean absolute deviation" in reasons[5]
    assert screen_outliers([1.0] * 6) == [None] * 6


def test_small_samples_not_screened_by_mad():
    assert screen_outliers([1.0, 1.0, 100.0, 1.0]) == [None] * 4


@pytest.mark.parametrize("n,table", [(3, 1.1543), (5, 1.7150), (10, 2.2900), (20, 2.7082)])
def test_grubbs_critical_values_match_printed_table(n, table):
    # two-sided alpha 0.05 critical values, Grubbs (1969) / NIST e-Handbook table
    assert grubbs_critical(n, 0.05) == pytest.approx(table, abs=2e-3)


def test_grubbs_rejects_the_gross_value_only():
    x = [2.1, 2.0, 1.9, 2.05, 1.95, 2.0, 5.0]
    reasons = screen_outliers(x, "grubbs")
    assert [r is None for r in reasons] == [True] * 6 + [False]
    assert "Grubbs" in reasons[6]


@pytest.mark.parametrize("bad", ["median", "mad:-1", "grubbs:2", "mad:x"])
def test_bad_outlier_rule(bad):
    with pytest.raises(InputError):
        parse_outlier_rule(bad)


def test_parse_outlier_rule_defaults():
    assert parse_outlier_rule("MAD") == ("mad", 3.5)
    assert parse_outlier_rule("grubbs:0.01") == ("grubbs", 0.01)
    assert parse_outlier_rule("none") == ("none", None)


def test_summarise_reports_every_rejection_and_round_trips():
    values = [10.0, 10.1, 9.9, 10.05, 9.95, 12.0]
    plain = summarise("q", values, [1, 2, 4, 5, 6, 7], unit="mm", source=SOURCE, method="m")
    assert plain.n == 6 and plain.rows_rejected == []  # no screening unless asked
    est = summarise("q", values, [1, 2, 4, 5, 6, 7], unit="mm", source=SOURCE, method="m",
                    outliers="mad", rejected=[{"row": 3, "reason": "marked bad by the lab"}],
                    per_row=[{"id": f"x{i}"} for i in range(6)])
    assert est.rows_used == [1, 2, 4, 5, 6]
    assert [r["row"] for r in est.rows_rejected] == [3, 7]
    assert est.n == 5 and est.value == pytest.approx(10.0)
    assert est.per_row[5]["used"] is False and est.per_row[5]["id"] == "x5"
    d = est.to_dict()
    assert set(d) >= {"value", "sd", "n", "ci95", "unit", "rows_used", "rows_rejected", "source"}
    assert "per_row" not in d
    again = Estimate.from_dict(est.to_dict(per_row=True))
    assert again == est
