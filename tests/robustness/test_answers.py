"""The README's answers name a weak reference: PPO on the true state scoring far below the
LQG on the true state (synthetic cells whose verdict is known by construction)."""

from __future__ import annotations

from fir_gym.robustness.answers import WEAK_REFERENCE, _reference


def cell(ppo_true: float, others: dict[str, float]):
    rows = [{"name": "lqg-true", "kind": "lqg-true", "iqm": -10.0},
            {"name": "true (nominal)", "kind": "true", "regime": "nominal", "iqm": ppo_true}]
    rows += [{"name": f"{k} (nominal)", "kind": k, "regime": "nominal", "iqm": v}
             for k, v in others.items()]
    return ("fir_gym/X-v0", "nominal", 0.0, rows, [])


def test_a_true_state_ppo_near_the_lqg_is_not_flagged():
    near = -10.0 * (1 + WEAK_REFERENCE) + 0.01
    assert _reference([cell(near, {"measurement": -30.0})]) == ""


def test_a_weak_true_state_ppo_is_flagged_with_the_kinds_above_it():
    text = _reference([cell(-50.0, {"measurement": -20.0, "ekf": -60.0, "ekf+gate": -15.0})])
    assert "5×" in text and "(-50 against -10)" in text
    # the kinds above it, gated rows left out (the gate changes the estimate, not the policy)
    assert "1 nominal-trained kinds" in text and "(measurement;" in text
    assert "measure training, not estimation" in text


def test_a_weak_reference_nobody_beats_understates_the_gap():
    text = _reference([cell(-20.0, {"measurement": -30.0})])
    assert "2×" in text and "understate" in text
