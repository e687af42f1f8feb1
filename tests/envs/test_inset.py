"""The magnified inset of a 2σ region too small to see on the frame (envs/_inset.py).

The oracle is the covariance: a region drawn with ``4P`` (σ doubled) must measure twice
the one drawn with ``P`` in the inset (pixels of the estimate's colour counted along the
region's axes), the magnification must be a power of ten, and the truth and the
measurement must sit at that magnification's offsets from the estimate, measured from
the plant's own drawing (its pixels per unit of state, as tests/envs/test_overlay.py
measures them). A region that shows on the frame leaves today's drawing as it was.
"""

from __future__ import annotations

import numpy as np
import pytest
from frames import (
    ESTIMATE,
    MEASUREMENT,
    centroid,
    pixels_of,
    plant_at,
    plant_in_state,
    truth_centroids,
)

import fir_gym
from fir_gym.envs import _inset
from fir_gym.envs._draw import GREY
from fir_gym.envs._inset import MARGIN, inset_size, magnification


def pixels_per_unit(p, i):
    """∂ pixel / ∂ x_i of the plant's own drawing (centroids of the truth at x ± e_i)."""
    step = np.zeros_like(p.state)
    step[i] = 1.0
    below, above = plant_at(p, p.state - step), plant_at(p, p.state + step)
    return (truth_centroids(above) - truth_centroids(below))[0] / 2.0


def boxes(frame):
    """The two bottom corners where insets go, as (row slice, column slice)."""
    h, w = frame.shape[:2]
    size = inset_size(w, h)
    rows = slice(h - MARGIN - size, h - MARGIN)
    return [(rows, slice(MARGIN, MARGIN + size)), (rows, slice(w - MARGIN - size, w - MARGIN))]


def inset_pixels(drawn, colour):
    """Pixels of ``colour`` in the one inset that holds the estimate's colour, in the
    inset's own coordinates."""
    found = []
    for rows, cols in boxes(drawn):
        marks = pixels_of(drawn[rows, cols], ESTIMATE)
        if len(marks):
            found.append(pixels_of(drawn[rows, cols], colour))
    assert len(found) == 1, f"{len(found)} insets hold the estimate"
    return found[0]


def power_of_ten(value):
    k = np.round(np.log10(value))
    assert abs(value / 10**k - 1) < 0.12, value             # within a pixel or two of 10^k
    return 10.0**k


def test_the_magnification_is_a_power_of_ten_that_fits_the_region():
    size = 100
    reach = _inset.REACH * size                               # 40 pixels
    assert magnification(reach / 10, size) == 10              # 4 px: ×10 fills the reach
    assert magnification(reach / 10 * 1.01, size) is None    # bigger: it shows on the frame
    assert magnification(0.01, size) == 1000                  # drawn 10 px
    assert magnification(0.02, size) == 1000                  # drawn 20 px: to scale
    assert magnification(0.05, size) == 100                   # 5 px at ×100
    for bad in (0.0, -1.0, np.nan, np.inf, 1e-300):
        assert magnification(bad, size) is None
    for r in np.geomspace(1e-7, 3.9, 200):
        m = magnification(r, size)
        assert m is not None and reach / 10 < m * r <= reach * (1 + 1e-12)


def test_an_orbit_bar_under_a_pixel_is_magnified_and_doubles_with_sigma():
    """Orbit-v0 draws the radius only: its 2σ region is a vertical bar. With σ_r so small
    that the bar is 0.01 px on the frame, the inset draws it magnified; 4P draws it twice
    as long (within a pixel or two), at a power-of-ten magnification."""
    p = plant_in_state("fir_gym/Orbit-v0")
    frame = p.render()
    per_unit = abs(pixels_per_unit(p, 0)[1])                  # rows per unit of r
    sigma_r = 0.005 / per_unit                                # 2σ = 0.01 px on the frame
    extents, columns = [], []
    for scale in (1.0, 4.0):
        P = scale * np.diag([sigma_r**2, 1e-6])
        marks = inset_pixels(p.draw_estimate(frame, p.state, P), ESTIMATE)
        extents.append(np.ptp(marks[:, 1]) + 1)
        columns.append(np.ptp(marks[:, 0]) + 1)
    assert abs(extents[1] - 2 * extents[0]) <= 2, extents
    assert extents[0] >= 15 and max(columns) <= 8            # a bar (caps, ring) along r
    m = power_of_ten((extents[0] - 1.5) / (4 * sigma_r * per_unit))
    assert m == 1000


def test_a_phase_plane_ellipse_doubles_along_both_axes():
    """VanDerPol-v0's region is an ellipse; in the inset it is {v : vᵀ (m²S)⁻¹ v = 4}, S the
    covariance carried to pixels by the drawing's measured scale, and 4P doubles both axes."""
    p = plant_in_state("fir_gym/VanDerPol-v0")
    frame = p.render()
    D = np.stack([pixels_per_unit(p, 0), pixels_per_unit(p, 1)], axis=1)
    shape = np.array([[0.30, 0.12], [0.12, 0.20]])
    S0 = D @ shape @ D.T
    c = (0.01 / 2) ** 2 / np.linalg.eigvalsh(S0)[-1]            # major 2σ radius: 0.01 px
    w, V = np.linalg.eigh(S0)
    half_axes = []
    for scale in (1.0, 4.0):
        P = scale * c * shape
        marks = inset_pixels(p.draw_estimate(frame, p.state, P), ESTIMATE)
        centre = centroid(marks)                                 # symmetric about the centre
        v = marks - centre
        v = v[np.hypot(*v.T) > _inset.INSET_RING + 2]             # the outline, not the ring
        along = v @ V                                              # minor, major components
        half_axes.append(np.abs(along).max(axis=0))
        S = scale * c * S0
        m = power_of_ten(half_axes[-1][1] / (2 * np.sqrt(scale * c * w[1])))
        d = np.sqrt(np.einsum("ni,ij,nj->n", v, np.linalg.inv(m**2 * S), v))
        np.testing.assert_allclose(d, 2.0, atol=2 * 1.5 / (2 * m * np.sqrt(scale * c * w[0])))
    np.testing.assert_allclose(half_axes[1], 2 * half_axes[0], atol=1.5)


def test_the_truth_and_the_measurement_are_drawn_at_the_same_magnification():
    p = plant_in_state("fir_gym/Orbit-v0")
    frame = p.render()
    rows_per_r = pixels_per_unit(p, 0)[1]                     # negative: r grows upwards
    sigma_r = 0.01 / abs(rows_per_r)                           # 2σ = 0.02 px on the frame
    x_hat = p.state + np.array([1.5 * sigma_r, 0.0])           # the truth 1.5σ below
    y = [p.state[0] - 1.0 * sigma_r]                           # the measurement 2.5σ below
    drawn = p.draw_estimate(frame, x_hat, np.diag([sigma_r**2, 1e-6]), y)
    estimate = inset_pixels(drawn, ESTIMATE)
    centre = centroid(estimate)
    m = power_of_ten((np.ptp(estimate[:, 1]) - 0.5) / (4 * sigma_r * abs(rows_per_r)))
    truth = centroid(inset_pixels(drawn, p.truth_color))
    np.testing.assert_allclose(truth - centre, [0.0, m * -1.5 * sigma_r * rows_per_r],
                               atol=1.5)
    cross = centroid(inset_pixels(drawn, MEASUREMENT))
    np.testing.assert_allclose(cross - centre, [0.0, m * -2.5 * sigma_r * rows_per_r],
                               atol=1.5)
    # with another frame's view the plant's own state is not that frame's truth: not drawn
    other = p.draw_estimate(frame, x_hat, np.diag([sigma_r**2, 1e-6]), view=p.frame_view)
    assert not len(inset_pixels(other, p.truth_color))
    given = p.draw_estimate(frame, x_hat, np.diag([sigma_r**2, 1e-6]), view=p.frame_view,
                            truth=p.state)
    assert np.array_equal(inset_pixels(given, p.truth_color), inset_pixels(drawn, p.truth_color))


@pytest.mark.parametrize("env_id", fir_gym.ENV_IDS)
def test_a_region_that_shows_on_the_frame_draws_as_before(env_id):
    """A large covariance: no inset, the frame is the drawing without one (byte for byte
    today's drawing); a tiny one adds the inset and changes nothing else but its leader."""
    p = plant_in_state(env_id)
    frame = p.render()
    n = len(p.state)
    x_hat = p.state + 0.05
    large = np.eye(n) * 0.05
    drawn = p.draw_estimate(frame, x_hat, large)
    assert np.array_equal(drawn, p.draw_estimate(frame, x_hat, large, inset=False))
    tiny = np.eye(n) * 1e-12
    with_inset = p.draw_estimate(frame, x_hat, tiny)
    without = p.draw_estimate(frame, x_hat, tiny, inset=False)
    changed = np.any(with_inset != without, axis=-1)
    inside = np.zeros_like(changed)
    for rows, cols in boxes(frame):
        inside[rows, cols] = True
    assert changed[inside].any()
    leader = with_inset[changed & ~inside]                      # only the grey leader line
    assert np.all(leader == np.array(GREY, dtype=np.uint8))


def test_the_pendulum_gets_one_inset_per_body_in_opposite_corners():
    p = plant_in_state("fir_gym/PendulumSlider-v0")
    frame = p.render()
    drawn = p.draw_estimate(frame, p.state + 0.01, np.eye(4) * 1e-10)
    for rows, cols in boxes(frame):
        assert len(pixels_of(drawn[rows, cols], ESTIMATE)) > 20
