"""The paper study's helpers (blendtrack.paper_eval): confidence intervals and parameter sets."""

from __future__ import annotations

import math

import pytest

from blendtrack import paper_eval as pe


def test_ci95_by_hand() -> None:
    # Values 1, 2, 3: mean 2, sample sd 1, t(0.975, 2) = 4.303 -> half-width 4.303 / sqrt(3).
    m, h = pe.ci95([1.0, 2.0, 3.0])
    assert m == pytest.approx(2.0)
    assert h == pytest.approx(4.303 / math.sqrt(3.0), rel=1e-4)  # the quantile to the 4 figures printed tables give
    # Ten values: t(0.975, 9) = 2.262.
    vals = [float(i) for i in range(10)]
    m, h = pe.ci95(vals)
    sd = math.sqrt(sum((v - 4.5) ** 2 for v in vals) / 9)
    assert h == pytest.approx(2.262 * sd / math.sqrt(10), rel=1e-4)
    # NaN values are left out; one value has no interval.
    assert pe.ci95([math.nan, 5.0])[0] == 5.0 and math.isnan(pe.ci95([5.0])[1])
    assert pe.fmt_ci([1.0, 2.0, 3.0], 2) == f"2.00 ± {4.303 / math.sqrt(3.0):.2f}"


def test_parameter_sets() -> None:
    assert pe.paper_config("Stanley").lateral_controller == "stanley"
    assert pe.paper_config("auto alpha").alpha_mode == "auto"
    tuned = {
        "parameters": {
            "pure pursuit": {"pure_pursuit_gain_s": 0.5, "pure_pursuit_min_lookahead_m": 1.5},
            "Stanley": {"stanley_gain": 1.5},
            "rear law (alpha 0)": {"target_distance_min_m": 4.0, "target_distance_gain_s": 0.25, "curvature_lookahead_gain_s": 0.5},
            "blend": {"lat_blend_factor": 0.75},
        }
    }
    blend = pe.fair_config("blend", tuned)
    assert (blend.stanley_gain, blend.target_distance_min_m, blend.lat_blend_factor) == (1.5, 4.0, 0.75)
    assert pe.fair_config("pure pursuit", tuned).pure_pursuit_gain_s == 0.5
    assert pe.fair_config("pure pursuit", tuned).stanley_gain == 1.0  # not its own: the default
    assert "Nuerburgring" not in pe.held_out_tracks() and "test_track" not in pe.held_out_tracks()


def test_clothoid_closed_form_against_simulation() -> None:
    # The rear law's steady error on a clothoid entry, c (L - 2 v tau) d^2 / 4
    # (docs/paper.md), against the closed-loop simulation: within 5 %.
    for d, lookahead, tau in ((8.0, 16.0, 0.0), (4.0, 24.0, 0.0), (8.0, 16.0, 0.1)):
        sim, closed = pe.clothoid_plateau_m(d, lookahead, 8.0, tau)
        assert sim == pytest.approx(closed, rel=0.05), (d, lookahead, tau)
    # Without the look-ahead error there would be nothing: the closed form is
    # proportional to L d^2 (doubling d quadruples it, in simulation too).
    a, _ = pe.clothoid_plateau_m(4.0, 16.0, 8.0)
    b, _ = pe.clothoid_plateau_m(8.0, 16.0, 8.0)
    assert b / a == pytest.approx(4.0, rel=0.05)
