"""Drawing an estimate over a plant's frame (envs/_overlay.py), checked against the plant's
own drawing: a marker for ``x̂`` sits where the plant, put at ``x̂``, draws its bodies."""

from __future__ import annotations

import pickle

import gymnasium as gym
import numpy as np
import pytest
from frames import (
    ESTIMATE,
    MEASUREMENT,
    STATES,
    centroid,
    near,
    pixels_of,
    plant_at,
    plant_in_state,
    same_mapping,
    truth_centroids,
)

import fir_gym
from fir_gym.envs import _font
from fir_gym.envs._overlay import RING_RADIUS

ENV_IDS = fir_gym.ENV_IDS
#: an estimate a little off each state, in the coordinates the picture shows
OFFSETS = {
    "fir_gym/Orbit-v0": (2.0, 0.3),
    "fir_gym/UncertainOscillator-v0": (0.3, 0.1, 0.0),
    "fir_gym/CarrierMotion-v0": (-0.25, 0.1),
    "fir_gym/VanDerPol-v0": (-0.4, 0.5),
    "fir_gym/PendulumSlider-v0": (-0.03, 0.0, -0.4, 0.0),
}


#: pixels: how far a patch's centroid may sit from the point it is drawn around (the
#: rasteriser rounds a rectangle's edges outwards, up to a pixel a side; MuJoCo's slider
#: box shows a side face in perspective)
TOL = 1.5


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_the_picture_is_where_the_plant_draws_its_state(env_id):
    """The state-to-pixel map against the frame: it must land on the plant's own bodies."""
    p = plant_in_state(env_id)
    np.testing.assert_allclose(p.state_to_pixels(p.state), truth_centroids(p), atol=TOL)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_an_estimate_ring_is_drawn_where_the_plant_would_draw_the_estimate(env_id):
    p = plant_in_state(env_id)
    frame = p.render()
    assert not len(pixels_of(frame, ESTIMATE))             # the plant never uses the colour
    x_hat = p.state + np.asarray(OFFSETS[env_id])
    drawn = p.draw_estimate(frame, x_hat)
    assert drawn is not frame and not len(pixels_of(frame, ESTIMATE))   # a copy
    oracle = plant_at(p, x_hat)
    assert same_mapping(oracle.frame_view, p.frame_view)
    marks = pixels_of(drawn, ESTIMATE)
    bodies = truth_centroids(oracle)
    for where in bodies:
        ring = near(marks, where, RING_RADIUS + 3)
        assert len(ring) >= 2 * np.pi * RING_RADIUS        # a whole ring, not a stray pixel
        np.testing.assert_allclose(centroid(ring), where, atol=TOL)
    if len(bodies) == 1:         # nothing else in the estimate's colour but the legend's swatch
        rest = marks[~((marks[:, 0] < 40) & (marks[:, 1] < 60))]
        assert len(near(rest, bodies[0], RING_RADIUS + 3)) == len(rest)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_the_measurement_is_marked_where_it_puts_the_state(env_id):
    p = plant_in_state(env_id)
    frame = p.render()
    x = np.asarray(STATES[env_id], dtype=np.float64)
    implied = x + np.asarray(OFFSETS[env_id])              # the state a measurement reads
    y = p._noise_free_measurement(implied, None)
    drawn = p.draw_estimate(frame, x, measurement=y)
    marks = pixels_of(drawn, MEASUREMENT)
    marks = marks[~((marks[:, 0] < 40) & (marks[:, 1] < 60))]          # not the legend
    oracle = truth_centroids(plant_at(p, implied))
    if env_id.endswith("VanDerPol-v0"):                    # x1 only: a vertical line at x1
        np.testing.assert_allclose(marks[:, 0], oracle[0, 0], atol=TOL)
        assert np.ptp(marks[:, 1]) > 0.9 * p.frame_view.height
        return
    for where in oracle:
        np.testing.assert_allclose(centroid(near(marks, where, 8)), where, atol=TOL)


def _pixels_per_unit(p, i):
    """How far (pixels) the plant's drawing moves per unit of state component i."""
    x = p.state.copy()
    step = np.zeros_like(x)
    step[i] = 1.0                 # wide: the centroids' rounding is then small per unit
    below, above = plant_at(p, x - step), plant_at(p, x + step)
    assert same_mapping(below.frame_view, p.frame_view)
    assert same_mapping(above.frame_view, p.frame_view)
    return (truth_centroids(above) - truth_centroids(below))[0] / 2.0


def test_the_2sigma_error_bar_of_a_radius_spans_four_sigma():
    """Orbit-v0 draws the radius only: its 2σ region is a vertical bar of ±2σ_r, whatever
    the velocity's variance (the picture does not depend on it)."""
    p = plant_in_state("fir_gym/Orbit-v0")
    frame = p.render()
    per_unit = _pixels_per_unit(p, 0)
    assert abs(per_unit[0]) < 1e-9 and per_unit[1] < 0      # up the frame as r grows
    sigma_r = 0.6
    for var_v in (1e-4, 10.0):
        drawn = p.draw_estimate(frame, p.state, np.diag([sigma_r**2, var_v]))
        centre = truth_centroids(p)[0]
        marks = pixels_of(drawn, ESTIMATE)
        bar = marks[np.abs(marks[:, 0] - centre[0]) <= 1.0]
        bar = bar[np.abs(bar[:, 1] - centre[1]) > RING_RADIUS + 2]
        half = 2 * sigma_r * abs(per_unit[1])
        top, bottom = bar[:, 1].min(), bar[:, 1].max()
        assert abs((bottom - top) / 2 - half) <= 1.0          # the caps' line width aside
        assert abs((bottom + top) / 2 - centre[1]) <= TOL


def test_the_2sigma_ellipse_of_the_phase_point():
    """VanDerPol-v0's picture is the phase plane: the 2σ ellipse is {v : vᵀ S⁻¹ v = 4} with
    S the covariance carried to pixels by the drawing's own scale (measured, not read)."""
    p = plant_in_state("fir_gym/VanDerPol-v0")
    frame = p.render()
    D = np.stack([_pixels_per_unit(p, 0), _pixels_per_unit(p, 1)], axis=1)   # ∂pixel/∂x
    P = np.array([[0.30, 0.12], [0.12, 0.20]])
    S = D @ P @ D.T
    drawn = p.draw_estimate(frame, p.state, P)
    centre = truth_centroids(p)[0]
    marks = pixels_of(drawn, ESTIMATE)
    marks = marks[~((marks[:, 0] < 40) & (marks[:, 1] < 60))]
    v = marks - centre
    outline = v[np.hypot(*v.T) > RING_RADIUS + 3]
    d = np.sqrt(np.einsum("ni,ij,nj->n", outline, np.linalg.inv(S), outline))
    minor = 2 * np.sqrt(np.linalg.eigvalsh(S)[0])
    np.testing.assert_allclose(d, 2.0, atol=2 * 1.5 / minor)
    angles = np.arctan2(outline[:, 1], outline[:, 0])
    assert len(np.unique(np.floor((angles + np.pi) / (2 * np.pi / 36)))) == 36   # closed


def test_a_region_thinner_than_a_pixel_or_not_finite_draws_no_region():
    """On the frame itself; a region that has a size is magnified in an inset instead
    (tests/envs/test_inset.py), one without (zero, NaN) nowhere."""
    p = plant_in_state("fir_gym/VanDerPol-v0")
    frame = p.render()
    ring_only = p.draw_estimate(frame, p.state)
    legend = slice(0, 60), slice(0, 140)
    outside = np.ones(frame.shape[:2], dtype=bool)
    outside[legend] = False
    for P in (np.zeros((2, 2)), np.full((2, 2), np.nan), np.diag([1e-12, 1e-12])):
        drawn = p.draw_estimate(frame, p.state, P, inset=False)
        assert np.array_equal(drawn[outside], ring_only[outside])
    for P in (np.zeros((2, 2)), np.full((2, 2), np.nan)):
        drawn = p.draw_estimate(frame, p.state, P)
        assert np.array_equal(drawn[outside], ring_only[outside])


@pytest.mark.parametrize("bad", [np.nan, np.inf, 1e300])
def test_an_estimate_off_the_numbers_draws_nothing_and_does_not_raise(bad):
    p = plant_in_state("fir_gym/Orbit-v0")
    frame = p.render()
    drawn = p.draw_estimate(frame, [bad, 0.0], np.eye(2), measurement=[bad])
    marks = pixels_of(drawn, ESTIMATE)
    assert not len(marks[~((marks[:, 0] < 40) & (marks[:, 1] < 60))])


def test_bad_arguments_name_what_was_expected():
    p = plant_in_state("fir_gym/Orbit-v0")
    frame = p.render()
    with pytest.raises(ValueError, match="estimate must have 2"):
        p.draw_estimate(frame, [1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="covariance must have shape"):
        p.draw_estimate(frame, p.state, np.eye(3))
    with pytest.raises(ValueError, match="frame must be a 300x400"):
        p.draw_estimate(frame[:10], p.state)
    fresh = gym.make("fir_gym/Orbit-v0", render_mode="rgb_array").unwrapped
    fresh.reset(seed=0)
    with pytest.raises(ValueError, match="render"):
        fresh.draw_estimate(frame, fresh.state)


def test_the_view_records_the_time_of_the_frame():
    p = plant_in_state("fir_gym/Orbit-v0")
    for _ in range(7):
        p.step(np.zeros(1))
    p.render()
    assert p.frame_view.step == 7 and p.frame_view.time == pytest.approx(7 * p.model.dt)


def test_a_plant_with_its_view_survives_pickle_and_draws_alike():
    p = plant_in_state("fir_gym/PendulumSlider-v0")
    frame = p.render()
    q = pickle.loads(pickle.dumps(p))
    assert q.frame_view == p.frame_view
    x_hat = p.state + 0.01
    assert np.array_equal(q.draw_estimate(frame, x_hat, np.eye(4) * 1e-4),
                          p.draw_estimate(frame, x_hat, np.eye(4) * 1e-4))


def test_every_glyph_is_five_by_at_most_nine():
    for char, rows in _font._GLYPHS.items():
        rows = rows.split()
        assert len(rows) <= _font.GLYPH_HEIGHT, char
        assert all(len(r) == _font.GLYPH_WIDTH and set(r) <= {"#", "."} for r in rows), char
    assert _font.text_mask("ab").shape == (9, 11)
    assert np.array_equal(_font.glyph("\u2603"), _font.glyph("?"))    # unknown: "?"
