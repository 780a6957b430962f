"""The particle-set kernels (motion, KLD resampling, clusters, converged) against their numpy
references on the same random draws, and against known answers."""

from __future__ import annotations

import numpy as np
import pytest

from gatmo.config import dump_model
from gatmo.geometry import wrap_angle
from gatmo.localization import AmclConfig, MonteCarloLocalizer
from gatmo.localization import _kernels as K
from gatmo.localization.motion import sample_motion, sample_motion_reference
from gatmo.localization.particles import (
    BIN_TH_RAD,
    BIN_XY_M,
    CLUSTER_MAX_CELLS,
    N_TH_BINS,
    cluster_estimate,
    cluster_estimate_reference,
    cluster_labels_reference,
    is_converged,
    is_converged_reference,
    kld_limit,
    kld_resample,
    kld_resample_reference,
)
from gatmo.localization.sensor import SensorModel
from gatmo.maps.likelihood import LikelihoodField
from tests.helpers import make_scan, room_grid

MODELS = ["diff", "diff-corrected", "omni", "omni-corrected"]


def _clouds(rng):
    """Particle sets: tight, wide, two modes, headings straddling -pi/pi, a few, one."""
    tight = rng.normal([3.0, -2.0, 0.4], [0.1, 0.1, 0.05], size=(3000, 3))
    wide = np.column_stack([rng.uniform(-20, 30, 4000), rng.uniform(-5, 40, 4000),
                            rng.uniform(-np.pi, np.pi, 4000)])
    two = np.vstack([rng.normal([1, 1, 0], [0.2, 0.2, 0.1], size=(800, 3)),
                     rng.normal([9, 4, 2], [0.4, 0.3, 0.2], size=(1200, 3))])
    wrap = rng.normal([5.0, 5.0, np.pi], [0.6, 0.6, 0.3], size=(2000, 3))
    wrap[:, 2] = wrap_angle(wrap[:, 2])
    return [tight, wide, two, wrap, tight[:7], tight[:1]]


def test_wrap_is_wrap_angle_bit_for_bit():
    x = np.random.default_rng(0).uniform(-40, 40, 20000)
    x[:6] = [-np.pi, np.pi, 0.0, -0.0, 3 * np.pi, -3 * np.pi]
    got = np.array([K._wrap.py_func(v) for v in x])
    np.testing.assert_array_equal(got, wrap_angle(x))


@pytest.mark.parametrize("model", MODELS)
def test_motion_kernel_matches_reference_on_the_same_normals(model):
    rng = np.random.default_rng(1)
    for parts in _clouds(rng):
        for prev, now in [(np.zeros(3), np.array([0.3, 0.05, 0.2])),
                          (np.array([1.0, 2.0, 3.0]), np.array([0.8, 2.3, -2.9])),
                          (np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, 1.0]))]:
            normals = rng.standard_normal((3, len(parts)))
            alphas = (0.2, 0.1, 0.3, 0.05, 0.1)
            got = sample_motion(parts, prev, now, model, alphas, rng, normals=normals)
            ref = sample_motion_reference(parts, prev, now, model, alphas, normals)
            np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12)
    # drawn from the generator: the reference on the same generator's standard normals
    parts = _clouds(rng)[0]
    got = sample_motion(parts, np.zeros(3), np.array([0.2, 0.0, 0.1]), model,
                        (0.1,) * 5, np.random.default_rng(7))
    normals = np.random.default_rng(7).standard_normal((3, len(parts)))
    ref = sample_motion_reference(parts, np.zeros(3), np.array([0.2, 0.0, 0.1]), model,
                                  (0.1,) * 5, normals)
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12)


def test_motion_without_noise_is_the_odometry_step():
    parts = np.array([[1.0, 2.0, np.pi / 2], [0.0, 0.0, -3.0]])
    step_prev, step_now = np.array([5.0, 5.0, 0.0]), np.array([6.0, 5.0, 0.5])
    normals = np.ones((3, 2))
    for model in MODELS:
        got = sample_motion(parts, step_prev, step_now, model, (0.0,) * 5, None, normals)
        # 1 m ahead in each particle's heading, then turn 0.5 rad
        expect = parts + np.column_stack([np.cos(parts[:, 2]), np.sin(parts[:, 2]),
                                          [0.5, 0.5]])
        expect[:, 2] = wrap_angle(expect[:, 2])
        np.testing.assert_allclose(got, expect, atol=1e-12)


def test_kld_kernel_equals_reference_on_the_same_uniforms():
    rng = np.random.default_rng(2)
    for parts in _clouds(rng):
        n = len(parts)
        for w in (np.full(n, 1.0 / n), rng.random(n) ** 4):
            w = w / w.sum()
            for min_n, max_n in [(100, 3000), (1, 5000), (500, 500), (1, 1)]:
                u = rng.random(max_n + 1)
                got = K.kld_resample_kernel(parts, w, u[0], u[1:], 0.05, 0.99, min_n, max_n,
                                            BIN_XY_M, BIN_TH_RAD)
                ref = kld_resample_reference(parts, w, u[0], u[1:], err=0.05, z=0.99,
                                             min_n=min_n, max_n=max_n)
                np.testing.assert_array_equal(got, ref)
    # through the generator: max_n + 1 uniforms, offset first
    parts = _clouds(rng)[2]
    w = np.full(len(parts), 1.0 / len(parts))
    got = kld_resample(parts, w, np.random.default_rng(3), err=0.05, z=0.99, min_n=10,
                       max_n=2000)
    u = np.random.default_rng(3).random(2001)
    ref = kld_resample_reference(parts, w, u[0], u[1:], err=0.05, z=0.99, min_n=10, max_n=2000)
    np.testing.assert_array_equal(got, ref)


def test_kld_set_size_is_the_bound_of_its_bins():
    rng = np.random.default_rng(4)
    for parts in _clouds(rng)[:4]:
        w = np.full(len(parts), 1.0 / len(parts))
        new = kld_resample(parts, w, rng, err=0.05, z=0.99, min_n=50, max_n=8000)
        k = len({tuple(b) for b in np.floor(np.column_stack(
            [new[:, :2] / BIN_XY_M, wrap_angle(new[:, 2]) / BIN_TH_RAD])).astype(int)})
        # the prefix stops as soon as its size reaches the bound of the bins it occupies
        assert len(new) == 8000 or len(new) >= kld_limit(k, 0.05, 0.99, 50, 8000) - 1
        assert len(new) >= 50


def test_kld_resampling_at_fixed_size_is_unbiased():
    rng = np.random.default_rng(5)
    parts = np.column_stack([np.arange(40.0), np.zeros(40), np.zeros(40)])
    w = rng.random(40)
    w /= w.sum()
    counts = np.zeros(40)
    for _ in range(500):
        new = kld_resample(parts, w, rng, err=0.05, z=0.99, min_n=1000, max_n=1000)
        assert len(new) == 1000
        c = np.bincount(new[:, 0].astype(int), minlength=40)
        assert np.all(np.abs(c - 1000 * w) < 1.0 + 1e-9)  # systematic: within 1 of N w_i
        counts += c
    np.testing.assert_allclose(counts / 500, 1000 * w, atol=0.05)


def test_kld_prefix_is_a_uniform_random_subset():
    # equal weights over 2 far-apart blobs: the kept prefix must hold both about equally
    rng = np.random.default_rng(6)
    parts = np.vstack([np.tile([0.1, 0.1, 0.0], (2000, 1)), np.tile([20.1, 0.1, 0.0], (2000, 1))])
    w = np.full(4000, 1 / 4000)
    share = []
    for _ in range(300):
        new = kld_resample(parts, w, rng, err=0.05, z=0.99, min_n=1, max_n=4000)
        assert len(new) == kld_limit(2, 0.05, 0.99, 1, 4000)  # 2 bins
        share.append((new[:, 0] < 10).mean())
    assert abs(np.mean(share) - 0.5) < 0.02


def _bin_centre(kx, ky, kt):
    return [(kx + 0.5) * BIN_XY_M, (ky + 0.5) * BIN_XY_M, -np.pi + (kt + 0.5) * BIN_TH_RAD]


def test_cluster_labels_kernel_equals_reference():
    rng = np.random.default_rng(8)
    for parts in _clouds(rng):
        got = K.cluster_labels_kernel(parts, BIN_XY_M, BIN_TH_RAD, N_TH_BINS, CLUSTER_MAX_CELLS)
        np.testing.assert_array_equal(got, cluster_labels_reference(parts))
    # a spread over more than CLUSTER_MAX_CELLS bins: one cluster
    far = np.array([[0.0, 0.0, -3.0], [5000.0, 5000.0, 3.0]])
    got = K.cluster_labels_kernel(far, BIN_XY_M, BIN_TH_RAD, N_TH_BINS, CLUSTER_MAX_CELLS)
    assert got.tolist() == [0, 0] == cluster_labels_reference(far).tolist()


def test_clusters_join_across_pi_in_chains():
    # a: (x 0, first heading bin); b: a staircase from (x 0, last bin) down to (x 35, first
    # bin); c: (x 35, last bin). a-b meet across -pi/pi at x 0, b-c at x 35: one cluster.
    # (Joining label pairs one after the other used to depend on the order of the pairs.)
    pts = [_bin_centre(0, 0, 0)] + [_bin_centre(k, 0, 35 - k) for k in range(36)]
    pts += [_bin_centre(35, 0, 35), _bin_centre(60, 0, 10)]  # and a separate one
    parts = np.array(pts)
    got = K.cluster_labels_kernel(parts, BIN_XY_M, BIN_TH_RAD, N_TH_BINS, CLUSTER_MAX_CELLS)
    np.testing.assert_array_equal(got, cluster_labels_reference(parts))
    assert set(got[:-1].tolist()) == {1} and got[-1] == 4  # raster-order labels, 2 and 3 joined


def test_cluster_estimate_kernel_matches_reference():
    rng = np.random.default_rng(9)
    for parts in _clouds(rng):
        n = len(parts)
        for w in (np.full(n, 1.0 / n), rng.random(n) ** 3, np.zeros(n)):
            m1, c1 = cluster_estimate(parts, w)
            m2, c2 = cluster_estimate_reference(parts, w)
            np.testing.assert_allclose(m1, m2, rtol=1e-10, atol=1e-10)
            np.testing.assert_allclose(c1, c2, rtol=1e-9, atol=1e-12)


def test_cluster_tie_goes_to_the_first_cluster_in_bin_order():
    a = np.tile(_bin_centre(10, 3, 5), (50, 1))
    b = np.tile(_bin_centre(2, 7, 20), (50, 1))  # smaller x: first in raster order
    parts = np.vstack([a, b])
    mean, cov = cluster_estimate(parts, np.full(100, 0.01))
    np.testing.assert_allclose(mean, _bin_centre(2, 7, 20), atol=1e-12)
    assert np.all(np.abs(cov) < 1e-9)
    mean2, _ = cluster_estimate_reference(parts, np.full(100, 0.01))
    np.testing.assert_allclose(mean, mean2, atol=1e-12)


def test_converged_kernel():
    rng = np.random.default_rng(10)
    for parts in _clouds(rng):
        for d in (0.05, 0.5, 3.0, 100.0):
            assert is_converged(parts, d) == is_converged_reference(parts, d)
    line = np.array([[0.0, 0.0, 0.0], [0.9, 0.0, 0.0]])  # mean 0.45 away from each
    assert is_converged(line, 0.46) and not is_converged(line, 0.44)


def test_beam_ray_caster_is_a_config_field_that_reaches_the_sensor_model():
    grid = room_grid(8, 6, 0.05, boxes=[(2, 2, 2.5, 3), (5, 1, 5.3, 2.5)])
    scan = make_scan(grid, (3.5, 3.0, 0.4), n_beams=61, max_range_m=8.0)
    parts = np.array([3.5, 3.0, 0.4]) + np.random.default_rng(3).normal(0, [0.3, 0.3, 0.2],
                                                                         size=(40, 3))
    assert AmclConfig().beam_ray_caster == "march"
    assert "beam_ray_caster: march" in dump_model(AmclConfig())
    with pytest.raises(ValueError, match="beam_ray_caster"):
        AmclConfig(beam_ray_caster="bresenham")
    out = {}
    for caster in ("march", "lut", "dda"):
        cfg = AmclConfig(laser_model="beam", beam_ray_caster=caster, max_beams=61)
        loc = MonteCarloLocalizer(grid, cfg)
        assert loc.sensor.ray_caster == caster
        out[caster], _ = loc.sensor.weigh(parts, scan, False)
        direct, _ = SensorModel(LikelihoodField(grid, cfg.laser_likelihood_max_dist_m), cfg,
                                ray_caster=caster).weigh(parts, scan, False)
        np.testing.assert_array_equal(out[caster], direct)
    np.testing.assert_allclose(out["march"], out["dda"], rtol=1e-12)
    assert not np.array_equal(out["lut"], out["march"])  # the table's ranges are approximate
    assert np.median(np.abs(out["lut"] - out["march"])) < 0.05
