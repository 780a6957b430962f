"""Odometry noise fitted to data (gatmo.localization.calibration) against known answers."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gatmo.geometry import compose, relative
from gatmo.localization.calibration import (
    apply_linear_calibration,
    fit_linear_calibration,
    fit_odometry_noise,
    motion_errors,
    reference_noise,
    update_steps,
)
from gatmo.localization.motion import sample_motion

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"


def wander(n: int, seed: int, step_m: float = 0.02, turns: bool = True) -> np.ndarray:
    """Odometry poses (n, 3): a robot driving step_m per tick with a slowly swinging turn rate
    and (``turns``) stops to turn in place."""
    rng = np.random.default_rng(seed)
    i = np.arange(n)
    v = np.where(((i // 800) % 5 == 4) & turns, 0.0, step_m)  # every fifth stretch: turn
    w = 0.02 * np.sin(i / 300.0) + 0.01 * rng.standard_normal(n) + np.where(v == 0, 0.03, 0.0)
    th = np.cumsum(w)
    return np.c_[np.cumsum(v * np.cos(th)), np.cumsum(v * np.sin(th)), th]


def truth_from_model(odom: np.ndarray, model: str, alphas, seed: int) -> np.ndarray:
    """The true path AMCL's motion model believes in: each update step of the odometry moved
    one particle, drawn with the given alphas (the model's generative story, exactly)."""
    rng = np.random.default_rng(seed)
    truth = np.zeros_like(odom)
    truth[0] = (1.0, -2.0, 0.4)  # any frame: only relative motions count
    for i in range(1, len(odom)):
        truth[i] = sample_motion(truth[i - 1:i].copy(), odom[i - 1], odom[i], model, alphas,
                                 rng)[0]
    return truth


@pytest.mark.parametrize(("model", "alphas"), [
    ("diff-corrected", (0.05, 0.01, 0.08, 0.03, 0.0)),
    ("diff", (0.2, 0.05, 0.3, 0.1, 0.0)),  # ROS 1: the weighted sum is the std
    ("omni-corrected", (0.05, 0.01, 0.08, 0.03, 0.04)),
])
def test_fit_recovers_the_alphas_the_odometry_was_drawn_with(model, alphas):
    dense = wander(60000, seed=1)
    odom = dense[update_steps(dense, 0.25, 0.2)]  # the filter's steps: each one an update
    truth = truth_from_model(odom, model, alphas, seed=2)
    fit = fit_odometry_noise(odom, truth, model=model, update_min_d_m=0.25,
                             update_min_a_rad=0.2)
    assert fit.steps + fit.rejected == len(odom) - 1
    assert fit.rejected < 0.01 * len(odom)  # 4 sigma of normals: a handful at most
    n = 5 if model.startswith("omni") else 4
    for got, want in zip(fit.alphas[:n], alphas[:n], strict=True):
        assert got == pytest.approx(want, rel=0.2)
    np.testing.assert_allclose(fit.z_std, 1.0, atol=0.05)


def test_a_wheel_scale_error_shows_in_the_travel_scale():
    dense = wander(20000, seed=9, turns=False)
    truth = dense[update_steps(dense, 0.25, 0.2)]
    steps = relative(truth[:-1], truth[1:]) * [1.03, 1.03, 1.0]  # wheels 3 % too large
    odom = np.zeros_like(truth)
    for i, s in enumerate(steps):
        odom[i + 1] = compose(odom[i], s)
    fit = fit_odometry_noise(odom, truth)
    assert fit.trans_scale == pytest.approx(1 / 1.03, abs=1e-3)
    assert fit.rot_scale == pytest.approx(1.0, abs=1e-3)
    assert fit.mean_error[1] > 0  # the odometry's steps are longer than the robot's


def test_fit_is_blind_to_the_reference_frame():
    dense = wander(20000, seed=3)
    odom = dense[update_steps(dense, 0.25, 0.2)]
    truth = truth_from_model(odom, "diff-corrected", (0.05, 0.01, 0.08, 0.03, 0.0), seed=4)
    moved = compose(np.array([30.0, -7.0, 2.0]), relative(truth[0], truth))
    a = fit_odometry_noise(odom, truth).alphas
    b = fit_odometry_noise(odom, moved).alphas
    np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-9)


def test_outliers_are_trimmed_and_do_not_move_the_fit():
    dense = wander(40000, seed=5)
    odom = dense[update_steps(dense, 0.25, 0.2)]
    alphas = (0.05, 0.01, 0.08, 0.03, 0.0)
    truth = truth_from_model(odom, "diff-corrected", alphas, seed=6)
    clean = fit_odometry_noise(odom, truth)
    # a reference that jumps 1 m at ten places (a loop closure, a relocalization)
    bad = truth.copy()
    for k in np.linspace(50, len(bad) - 50, 10).astype(int):
        bad[k:, 0] += 1.0
    fit = fit_odometry_noise(odom, bad)
    assert fit.rejected >= 10
    np.testing.assert_allclose(fit.alphas[:3], clean.alphas[:3], rtol=0.1)


def test_update_steps_follow_amcl_s_trigger():
    # x or y beyond update_min_d in the odom frame, or heading beyond update_min_a
    odom = np.array([[0, 0, 0], [0.1, 0, 0], [0.26, 0, 0], [0.3, 0.1, 0], [0.3, 0.3, 0],
                     [0.3, 0.3, 0.1], [0.3, 0.3, 0.25], [0.3, 0.3, -3.1]], dtype=float)
    np.testing.assert_array_equal(update_steps(odom, 0.25, 0.2), [0, 2, 4, 6, 7])


def test_motion_errors_of_a_perfect_odometry_are_zero_and_a_heading_error_shows_in_rot2():
    odom = np.array([[0.0, 0.0, 0.0], [1.0, 0.5, 0.3]])
    e, _ = motion_errors(odom[:1], odom[1:], odom[:1], odom[1:], "diff-corrected")
    np.testing.assert_allclose(e, 0.0, atol=1e-12)
    ref = odom.copy()
    ref[1, 2] += 0.05  # the robot turned 0.05 rad more than its wheels say
    e, f = motion_errors(odom[:1], odom[1:], ref[:1], ref[1:], "diff-corrected")
    np.testing.assert_allclose(e[0], [0.0, 0.0, -0.05], atol=1e-12)
    trans = np.hypot(1.0, 0.5)
    assert f[0, 1, 2] == pytest.approx(trans**2)  # trans's variance: alpha3 trans^2 + ...


def test_a_turn_in_place_has_no_rot1():
    odom = np.array([[0.0, 0.0, 0.0], [0.001, 0.0, 0.5]])
    e, _ = motion_errors(odom[:1], odom[1:], odom[:1], odom[1:] + [0.0, 0.002, 0.0],
                         "diff-corrected")
    assert np.isnan(e[0, 0]) and e[0, 2] == pytest.approx(0.0)


def test_linear_calibration_recovers_a_known_matrix_and_corrects_the_path():
    rng = np.random.default_rng(7)
    dense = wander(5000, seed=8)
    K = np.array([[1.05, 0.01, 0.0], [0.0, 0.98, 0.02], [0.0, 0.0, 0.93]])
    u = relative(dense[:-1], dense[1:])
    r = u @ K.T + rng.normal(0, 1e-5, u.shape)
    np.testing.assert_allclose(fit_linear_calibration(u, r), K, atol=2e-3)
    true = np.zeros_like(dense)
    for i, s in enumerate(r):
        true[i + 1] = compose(true[i], s)
    fixed = apply_linear_calibration(np.vstack([[0.0, 0.0, 0.0], dense[1:] - dense[0]]), K)
    assert np.abs(fixed[:, :2] - true[:, :2]).max() < np.abs(dense[:, :2] - dense[0, :2]
                                                             - true[:, :2]).max() / 10


@pytest.mark.skipif(not (DATA / "freiburg-course" / "odom_motions.dat").exists(),
                    reason="../shared/data (Freiburg course odometry motions) not found")
def test_real_freiburg_odometry_calibration_holds_on_the_motions_it_was_not_fitted_to():
    # 2,002 paired motions of a real robot: odometry and scan matching (Freiburg robot-mapping
    # course). Fitted on the first half, the matrix must cut the drift of the second half's
    # path: its end 22.5 m from the scan matcher's raw, 4.4 m calibrated. A single motion's error
    # is mostly random (1.6 cm either way): the systematic part is what adds up.
    u = np.loadtxt(DATA / "freiburg-course" / "odom_motions.dat")
    r = np.loadtxt(DATA / "freiburg-course" / "scanmatched_motions.dat")
    half = len(u) // 2
    K = fit_linear_calibration(u[:half], r[:half])
    before = np.linalg.norm(r[half:] - u[half:], axis=1).mean()
    after = np.linalg.norm(r[half:] - u[half:] @ K.T, axis=1).mean()
    assert after <= before

    def chain(steps):
        p = np.zeros((len(steps) + 1, 3))
        for i, s in enumerate(steps):
            p[i + 1] = compose(p[i], s)
        return p

    ref, raw, cal = chain(r[half:]), chain(u[half:]), chain(u[half:] @ K.T)
    assert np.hypot(*(cal[-1, :2] - ref[-1, :2])) < 0.3 * np.hypot(*(raw[-1, :2] - ref[-1, :2]))


def test_the_reference_s_own_noise_is_measured_and_kept_out_of_the_alphas():
    # a reference at every scan (2 cm apart) that jitters as a pose graph does: 1 cm across and
    # along, 0.3 deg. Over the filter's 0.1 m steps that is 0.14 rad of direction, which a fit
    # that ignores it puts into alpha2 (rotation per metre)
    dense = wander(20000, seed=10)
    truth = truth_from_model(dense, "diff-corrected", (0.05, 0.01, 0.08, 0.03, 0.0), seed=11)
    rng = np.random.default_rng(12)
    ref = truth + rng.normal(0.0, 1.0, truth.shape) * [0.01, 0.01, 0.005]
    rv = reference_noise(dense, ref)
    np.testing.assert_allclose(np.sqrt(rv), [0.01, 0.01, 0.005], rtol=0.1)
    # the wheels' own noise from scan to scan is not mistaken for it: under 1 mm / 0.06 deg
    assert np.all(np.sqrt(reference_noise(dense, truth)) < 0.001)
    kw = {"update_min_d_m": 0.1, "update_min_a_rad": 0.1}
    clean = fit_odometry_noise(dense, truth, **kw).alphas
    naive = fit_odometry_noise(dense, ref, **kw).alphas
    fixed = fit_odometry_noise(dense, ref, reference_var=rv, **kw)
    assert naive[1] > 100 * clean[1]
    assert abs(fixed.alphas[1] - clean[1]) < 0.1 * abs(naive[1] - clean[1])
    for i in (0, 2):  # rotation and translation noise per unit: as with the exact reference
        assert fixed.alphas[i] == pytest.approx(clean[i], rel=0.35)
    np.testing.assert_allclose(fixed.reference_std, np.sqrt(rv))
