"""The sweeps beyond the papers: mismatch × window on Orbit-v0, recovery after an uncertainty."""

import numpy as np
import pytest

from fir_gym.scenarios import sweeps


@pytest.fixture(scope="module")
def report(quick_report):
    return quick_report("sweeps")


def test_grid_is_complete(report):
    f = report.figures
    for r in f["ratios"]:
        assert (r, "EKF", None) in f["grid"] and (r, "UKF", None) in f["grid"]
        for N in f["windows"]:
            assert np.isfinite(f["grid"][(r, "EFIR", N)])
    assert len(report.comparisons) == len(f["ratios"]) + len(f["recovery"])
    assert all(c.paper is None for c in report.comparisons)      # experiments the papers left


def test_efir_error_is_noise_dominated_at_these_mismatches(report):
    """Over ≤ 0.5 time units the μ bias is ≪ σ_v, so a longer window only averages more noise:
    the end point of a line fit, ≈ 2σ_v/√N. With 4 runs × 200 steps the RMSE estimate is good
    to a few per cent; the factor-of-two margins below leave room for that and the bias."""
    f = report.figures
    for r in f["ratios"]:
        rmse = [f["grid"][(r, "EFIR", N)] for N in f["windows"]]
        assert all(np.diff(rmse) < 0)
        for N, v in zip(f["windows"], rmse, strict=True):
            assert 0.5 < v / (2 * f["sigma_v"] / np.sqrt(N)) < 2.0


def test_fir_recovers_within_its_window(report):
    for res in report.figures["recovery"].values():
        for name, r in res.items():
            if name.startswith("EFIR N="):
                assert r["recovery"] is not None and r["recovery"] <= int(name[7:])


def test_same_seed_same_figures(tiny_sweep):
    a = tiny_sweep.run(seed=2, quick=True, runs=2)
    b = tiny_sweep.run(seed=2, quick=True, runs=2)
    np.testing.assert_equal(a.figures, b.figures)


def test_plot(report, tmp_path):
    sweeps.plot(report, tmp_path)
    (path,) = report.images.values()
    assert (tmp_path / path).stat().st_size > 10_000
