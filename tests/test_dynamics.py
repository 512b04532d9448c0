"""Kinematic bicycle model and oriented-box footprints."""

import math

import numpy as np
import pytest

from simcore.dynamics import (
    MAX_SPEED,
    VEHICLE_LENGTH,
    VEHICLE_WIDTH,
    WHEELBASE,
    bicycle_step,
    box_corners,
    boxes_overlap,
    turning_radius,
)


def fit_circle(x, y):
    """Least-squares circle through points (Kasa fit): returns centre and radius."""
    a = np.column_stack([x, y, np.ones_like(x)])
    b = x * x + y * y
    cx2, cy2, c = np.linalg.lstsq(a, b, rcond=None)[0]
    cx, cy = cx2 / 2, cy2 / 2
    return cx, cy, math.sqrt(c + cx * cx + cy * cy)


@pytest.mark.parametrize("steering", [0.2, 0.1, 0.05, -0.2, -0.13])
def test_constant_steering_follows_the_closed_form_circle(steering):
    expected = abs(0.5 * WHEELBASE / math.sin(math.atan(0.5 * math.tan(steering))))  # written out
    assert turning_radius(steering) == pytest.approx(expected)
    x = y = heading = 0.0
    speed, dt = 5.0, 0.001
    xs, ys = [], []
    steps = int(2 * math.pi * expected / speed / dt)
    for _ in range(steps):
        x, y, heading, speed = bicycle_step(x, y, heading, speed, 0.0, steering, dt)
        xs.append(x)
        ys.append(y)
    cx, cy, radius = fit_circle(np.array(xs), np.array(ys))
    assert radius == pytest.approx(expected, rel=1e-3)
    assert turning_radius(steering) == pytest.approx(radius, rel=1e-3)
    # starting at the origin heading east, the centre lies abeam of the rear axle (half a
    # wheelbase behind the reference point), on the left for positive steering
    beta = math.atan(0.5 * math.tan(steering))
    assert cx == pytest.approx(-0.5 * WHEELBASE, abs=1e-3 * expected)
    assert cy == pytest.approx(math.copysign(expected * math.cos(beta), steering), rel=1e-3)
    assert math.hypot(x, y) < 0.01 * expected  # one full lap comes back to the start
    assert abs(heading) == pytest.approx(2 * math.pi, rel=1e-2)  # having turned once around
    assert math.copysign(1, heading) == math.copysign(1, steering)
    assert speed == 5.0  # zero acceleration keeps the speed


def test_smallest_turning_radius_is_13_4_m():
    assert turning_radius(0.2) == pytest.approx(13.39, abs=0.01)


def test_turning_radius_is_symmetric_and_shrinks_with_steering():
    radii = [turning_radius(d) for d in (0.05, 0.1, 0.15, 0.2)]
    assert radii == sorted(radii, reverse=True)
    for d in (0.05, 0.2):
        assert turning_radius(-d) == pytest.approx(turning_radius(d))


def test_zero_steering_drives_straight_and_speed_is_clamped():
    x, y, heading, speed = bicycle_step(0.0, 0.0, 0.3, 4.0, 0.0, 0.0, 0.1)
    assert (x, y) == pytest.approx((0.4 * math.cos(0.3), 0.4 * math.sin(0.3)))
    assert heading == 0.3
    # many steps at zero steering stay on the line through the start along the heading
    x = y = 0.0
    heading, speed = -2.0, 6.0
    for _ in range(200):
        x, y, heading, speed = bicycle_step(x, y, heading, speed, 0.5, 0.0, 0.05)
    assert heading == -2.0
    assert -x * math.sin(-2.0) + y * math.cos(-2.0) == pytest.approx(0.0, abs=1e-9)  # no lateral drift
    travelled = sum(6.0 + 0.5 * 0.05 * k for k in range(200)) * 0.05  # Euler: old speed each step
    assert math.hypot(x, y) == pytest.approx(travelled)
    *_, speed = bicycle_step(0.0, 0.0, 0.0, 0.1, -3.0, 0.0, 0.1)
    assert speed == 0.0  # no reversing
    *_, speed = bicycle_step(0.0, 0.0, 0.0, MAX_SPEED, 3.0, 0.0, 0.1)
    assert speed == MAX_SPEED
    # braking from a stand does not move the car backwards
    x, y, heading, speed = bicycle_step(1.0, 2.0, 0.7, 0.0, -3.0, 0.2, 0.1)
    assert (x, y, heading, speed) == (1.0, 2.0, 0.7, 0.0)
    # arrays are clamped element-wise
    speeds = bicycle_step(np.zeros(3), np.zeros(3), np.zeros(3), np.array([0.2, 5.0, 19.9]),
                          np.array([-3.0, 1.0, 3.0]), np.zeros(3), 0.1)[3]
    assert speeds == pytest.approx([0.0, 5.1, MAX_SPEED])


def test_vectorised_step_matches_scalar_step():
    state = np.array([[0.0, 1.0, 0.2, 5.0], [3.0, -1.0, -1.0, 2.0]])
    controls = np.array([[1.0, 0.1], [-2.0, -0.2]])
    batch = bicycle_step(*state.T, controls[:, 0], controls[:, 1])
    for i in range(2):
        single = bicycle_step(*state[i], *controls[i])
        assert np.array(batch)[:, i] == pytest.approx(np.array(single))


def test_box_corners_are_oriented():
    corners = box_corners(1.0, 2.0, math.pi / 2)[0]
    # heading north: the front-left corner is north-west of the centre
    assert corners[0] == pytest.approx((1.0 - VEHICLE_WIDTH / 2, 2.0 + VEHICLE_LENGTH / 2))
    assert np.linalg.norm(corners[0] - corners[3]) == pytest.approx(VEHICLE_WIDTH)
    assert np.linalg.norm(corners[0] - corners[1]) == pytest.approx(VEHICLE_LENGTH)


@pytest.mark.parametrize("b, overlap", [
    ((4.0, 0.0, 0.0), True),  # nose to tail, 0.5 m overlap
    ((5.0, 0.0, 0.0), False),  # 0.5 m gap
    ((0.0, 1.7, 0.0), True),  # side by side, touching
    ((0.0, 2.0, 0.0), False),  # side by side, 0.2 m apart
    ((4.5, 0.0, 0.0), True),  # nose to tail, exactly touching
    ((0.0, 1.8, 0.0), True),  # side by side, exactly touching
    ((0.0, 0.0, math.pi / 2), True),  # crossed on the same centre
    ((3.0, 3.0, math.pi / 4), True),  # rotated: the diagonal box's corner reaches in
    ((3.1, 0.0, math.pi / 2), True),  # T-bone: 0.9 m half width reaches the 2.25 m nose
    ((3.2, 0.0, math.pi / 2), False),  # T-bone with a 5 cm gap
    ((4.5, 4.5, math.pi / 4), False),  # bounding boxes overlap, boxes do not
])
def test_separating_axis_overlap(b, overlap):
    a = box_corners(0.0, 0.0, 0.0)
    other = box_corners(*b)
    assert boxes_overlap(a, other)[0] == overlap
    assert boxes_overlap(other, a)[0] == overlap


def test_overlap_is_vectorised_over_pairs():
    a = box_corners(np.zeros(3), np.zeros(3), np.zeros(3))
    b = box_corners(np.array([4.0, 5.0, 0.0]), np.array([0.0, 0.0, 2.0]), np.zeros(3))
    assert boxes_overlap(a, b).tolist() == [True, False, False]
