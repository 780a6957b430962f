"""Motion and sensor models, KLD, resampling and clusters against known answers."""

from __future__ import annotations

import numpy as np
import pytest

from gatmo.errors import ConfigError
from gatmo.localization import _kernels as K
from gatmo.localization.config import AmclConfig
from gatmo.localization.motion import sample_motion
from gatmo.localization.particles import (
    cluster_estimate,
    kld_limit,
    kld_resample,
    systematic_indices,
)
from gatmo.localization.sensor import (
    SensorModel,
    beam_reference,
    likelihood_field_reference,
    select_beams,
)
from gatmo.maps.likelihood import LikelihoodField
from gatmo.maps.raycast import RangeTable, march_table
from tests.helpers import make_scan, room_grid


def test_corrected_diff_model_moments():
    rng = np.random.default_rng(0)
    n = 200_000
    parts = np.zeros((n, 3))
    a = (0.1, 0.05, 0.2, 0.02, 0.0)
    out = sample_motion(parts, np.zeros(3), np.array([1.0, 0.0, 0.3]), "diff-corrected", a, rng)
    # rot1 = 0, trans = 1, rot2 = 0.3: x ~ trans_hat cos(rot1_hat)
    trans_sd = np.sqrt(a[2] * 1.0 + a[3] * 0.0 + a[3] * 0.3**2)
    rot1_sd = np.sqrt(a[0] * 0 + a[1] * 1.0)
    trans_hat = np.hypot(out[:, 0], out[:, 1])
    assert abs(trans_hat.mean() - 1.0) < 0.01 and abs(trans_hat.std() - trans_sd) < 0.01
    rot1 = np.arctan(out[:, 1] / out[:, 0])  # mod pi: trans_hat may come out negative
    assert abs(rot1.std() - rot1_sd) < 0.01
    th_sd = np.sqrt(rot1_sd**2 + (a[0] * 0.3**2 + a[1]))
    assert abs(out[:, 2].mean() - 0.3) < 0.01 and abs(out[:, 2].std() - th_sd) < 0.01


def test_ros1_diff_uses_variance_as_std():
    rng = np.random.default_rng(1)
    parts = np.zeros((100_000, 3))
    a = (0.0, 0.0, 0.2, 0.0, 0.0)
    out = sample_motion(parts, np.zeros(3), np.array([1.0, 0.0, 0.0]), "diff", a, rng)
    assert abs(out[:, 0].std() - 0.2) < 0.005  # 0.2 * 1^2, not its square root
    out = sample_motion(parts, np.zeros(3), np.array([1.0, 0.0, 0.0]), "diff-corrected", a, rng)
    assert abs(out[:, 0].std() - np.sqrt(0.2)) < 0.005


def test_omni_moves_sideways():
    rng = np.random.default_rng(2)
    parts = np.zeros((10, 3))
    out = sample_motion(parts, np.zeros(3), np.array([0.0, 1.0, 0.0]), "omni-corrected",
                        (0, 0, 0, 0, 0), rng)
    np.testing.assert_allclose(out, [[0.0, 1.0, 0.0]] * 10, atol=1e-12)


def _world():
    grid = room_grid(8, 6, 0.05, boxes=[(2, 2, 2.5, 3), (5, 1, 5.3, 2.5)])
    scan = make_scan(grid, (3.5, 3.0, 0.4), n_beams=61, max_range_m=8.0)
    rng = np.random.default_rng(3)
    parts = np.array([3.5, 3.0, 0.4]) + rng.normal(0, [0.3, 0.3, 0.2], size=(40, 3))
    return grid, scan, parts


def test_likelihood_field_kernel_matches_reference_and_hand_value():
    grid, scan, parts = _world()
    f = LikelihoodField(grid, 2.0)
    r, a, rmax = select_beams(scan, 61, None, None, keep_max_range=False)
    lp = np.zeros(3)
    got = K.likelihood_field_kernel(parts, lp, r, a, f.dist_m, 0.05, 0.0, 0.0, 2.0, 0.95, 0.05,
                                    0.2, rmax)
    ref = likelihood_field_reference(parts, lp, r, a, f, 0.95, 0.05, 0.2, rmax)
    np.testing.assert_allclose(got, ref, rtol=1e-12)
    # hand value: one beam ending exactly on a wall cell -> z = 0 -> pz = z_hit + z_rand/rmax
    one = K.likelihood_field_kernel(np.array([[3.0, 3.0, 0.0]]), lp, np.array([4.92]),
                                    np.array([0.0]), f.dist_m, 0.05, 0.0, 0.0, 2.0, 0.95, 0.05,
                                    0.2, 8.0)
    assert np.isclose(one[0], 1.0 + (0.95 + 0.05 / 8.0) ** 3)
    off = K.likelihood_field_kernel(np.array([[3.0, 3.0, 0.0]]), lp, np.array([40.0]),
                                    np.array([0.0]), f.dist_m, 0.05, 0.0, 0.0, 2.0, 0.95, 0.05,
                                    0.2, 80.0)
    assert np.isclose(off[0], 1.0 + (0.95 * np.exp(-4 / 0.08) + 0.05 / 80.0) ** 3)


def test_beam_kernel_matches_reference():
    grid, scan, parts = _world()
    r, a, rmax = select_beams(scan, 31, None, None, keep_max_range=True)
    args = (0.5, 0.1, 0.05, 0.35, 0.2, 0.1, rmax)
    got = K.beam_kernel(parts[:8], np.zeros(3), r, a, grid.cells, 0.05, 0.0, 0.0, *args)
    ref = beam_reference(parts[:8], np.zeros(3), r, a, grid, *args)
    # the reference marches in 0.5 mm steps and can miss a cell touched only at its corner
    np.testing.assert_allclose(got, ref, rtol=5e-3)


def _beam_terms(r, rmax, z_short=0.1, lam=0.2, z_max=0.05, z_rand=0.35):
    short = z_short * lam * np.exp(-lam * r)
    const = np.where(r >= rmax, z_max, z_rand / rmax)
    return short, const


def test_beam_march_kernel_equals_cell_walk_kernel():
    grid, scan, parts = _world()
    grid.cells[60:70, 20:25] = -1  # unknown blocks rays too
    scan.ranges_m[::7] = 8.0  # max-range readings: z_max
    parts = np.vstack([parts, [[-1.0, 3.0, 0.0], [2.2, 2.5, 0.0]]])  # off the map; in a box
    r, a, rmax = select_beams(scan, 61, None, None, keep_max_range=True)
    assert (r >= rmax).any()
    lp = np.array([0.1, 0.02, 0.05])
    walk = K.beam_kernel(parts, lp, r, a, grid.cells, 0.05, 0.0, 0.0, 0.5, 0.1, 0.05, 0.35,
                         0.2, 0.2, rmax)
    short, const = _beam_terms(r, rmax)
    sd = march_table(grid)
    for kern in (K.beam_march_kernel, K.beam_march_kernel_serial):
        got = kern(parts, lp, r, np.cos(a), np.sin(a), short, const, sd, 0.05, 0.0, 0.0, 0.5,
                   0.2, rmax, 1.0)
        np.testing.assert_allclose(got, walk, rtol=1e-12)


def test_beam_lut_kernel_close_to_exact():
    grid, scan, parts = _world()
    r, a, rmax = select_beams(scan, 61, None, None, keep_max_range=True)
    lut = RangeTable(grid, rmax)
    short, const = _beam_terms(r, rmax)
    lp = np.zeros(3)
    exact = K.beam_march_kernel(parts, lp, r, np.cos(a), np.sin(a), short, const,
                                march_table(grid), 0.05, 0.0, 0.0, 0.5, 0.2, rmax, 1.0)
    beam_bins = lut.beam_bins(a)
    got = [kern(parts, lp, r, beam_bins, np.cos(a), np.sin(a), short, const, lut.index,
                lut.ranges, lut.scale_cells, 0.05, 0.0, 0.0, 0.5, 0.2, rmax)
           for kern in (K.beam_lut_kernel, K.beam_lut_kernel_serial)]
    np.testing.assert_array_equal(got[0], got[1])
    # same ranking of particles, per-particle p within a few percent (measured: 1.3 % median)
    rel = np.abs(got[0] / exact - 1)
    assert np.median(rel) < 0.03 and rel.max() < 0.25
    assert np.argmax(got[0]) == np.argmax(exact)
    # the same through the kernel's own ranges: the table's cast at each particle
    ranges = lut.cast(grid, parts, a)
    ref = []
    for i in range(len(parts)):
        z = r - ranges[i]
        pz = 0.5 * np.exp(-(z**2) / (2 * 0.2**2)) + np.where(z < 0, short, 0.0) + const
        ref.append(1.0 + (pz**3).sum())
    np.testing.assert_allclose(got[0], ref, rtol=1e-12)


@pytest.mark.parametrize("caster", ["march", "dda", "lut"])
def test_sensor_model_ray_casters_agree(caster):
    grid, scan, parts = _world()
    cfg = AmclConfig(laser_model="beam", z_hit=0.5, z_short=0.1, z_max=0.05, z_rand=0.35,
                     sigma_hit_m=0.2, lambda_short=0.2, max_beams=61)
    r, a, rmax = select_beams(scan, 61, None, None, keep_max_range=True)
    ref = np.log(K.beam_kernel(parts, np.zeros(3), r, a, grid.cells, 0.05, 0.0, 0.0, 0.5, 0.1,
                               0.05, 0.35, 0.2, 0.2, rmax))
    logw, n = SensorModel(LikelihoodField(grid, 2.0), cfg, ray_caster=caster).weigh(
        parts, scan, False)
    assert n == len(r)
    if caster == "lut":
        assert np.median(np.abs(logw - ref)) < 0.03
    else:
        np.testing.assert_allclose(logw, ref, rtol=1e-12)
    with pytest.raises(ConfigError, match="ray_caster"):
        SensorModel(LikelihoodField(grid, 2.0), cfg, ray_caster="bresenham").weigh(
            parts, scan, False)


def test_ray_tables_follow_map_changes():
    grid, scan, parts = _world()
    field = LikelihoodField(grid.copy(), 2.0)
    cfg = AmclConfig(laser_model="beam", z_hit=0.9, z_rand=0.1, max_beams=61)
    model = SensorModel(field, cfg)
    model.weigh(parts, scan, False)
    lut_model = SensorModel(field, cfg, ray_caster="lut")
    lut_model.weigh(parts, scan, False)
    for k in range(3):
        patch = np.full((10, 12), 100 if k != 1 else 0, dtype=np.int8)
        field.update_region(patch, 60 + 5 * k, 30)
        got, _ = model.weigh(parts, scan, False)
        fresh, _ = SensorModel(LikelihoodField(field.grid.copy(), 2.0), cfg).weigh(parts, scan,
                                                                                False)
        np.testing.assert_array_equal(got, fresh)
        np.testing.assert_array_equal(model._march, march_table(field.grid))
        got, _ = lut_model.weigh(parts, scan, False)  # the table follows by region updates
        fresh, _ = SensorModel(LikelihoodField(field.grid.copy(), 2.0), cfg,
                               ray_caster="lut").weigh(parts, scan, False)
        np.testing.assert_array_equal(got, fresh)
    field.set_grid(grid.copy())
    got, _ = model.weigh(parts, scan, False)
    fresh, _ = SensorModel(LikelihoodField(grid.copy(), 2.0), cfg).weigh(parts, scan, False)
    np.testing.assert_array_equal(got, fresh)


def test_true_pose_scores_best_in_every_model():
    grid, scan, parts = _world()
    parts[0] = [3.5, 3.0, 0.4]
    for model, caster in [("likelihood_field", "march"), ("likelihood_field_prob", "march"),
                          ("beam", "march"), ("beam", "dda"), ("beam", "lut")]:
        cfg = AmclConfig(laser_model=model, z_hit=0.9, z_rand=0.1, max_beams=61)
        logw, n = SensorModel(LikelihoodField(grid, 2.0), cfg, ray_caster=caster).weigh(
            parts, scan, False)
        assert n > 50 and np.argmax(logw) == 0, (model, caster)


def test_invalid_readings_are_ignored():
    grid, scan, _ = _world()
    scan.ranges_m[:10] = np.nan
    scan.ranges_m[10:20] = np.inf
    scan.ranges_m[20:25] = -1.0
    r, _, _ = select_beams(scan, 61, None, None, keep_max_range=False)
    assert np.all(np.isfinite(r)) and np.all(r > 0) and len(r) <= 61 - 25


def test_beam_subsampling_step_as_amcl():
    grid = room_grid()
    scan = make_scan(grid, (3, 3, 0), n_beams=181, max_range_m=30)
    r, a, _ = select_beams(scan, 30, None, None, keep_max_range=True)
    assert len(r) == 181 // 6 + 1  # step = (181 - 1) // (30 - 1) = 6
    np.testing.assert_allclose(np.diff(a), np.diff(scan.angles_rad)[0] * 6)


@pytest.mark.parametrize("k", [2, 5, 50, 500])
def test_kld_limit_formula(k):
    err, z = 0.05, 2.33
    b = 2 / (9 * (k - 1))
    expect = int(np.ceil((k - 1) / (2 * err) * (1 - b + np.sqrt(b) * z) ** 3))
    assert kld_limit(k, err, z, 1, 10**9) == expect
    assert kld_limit(k, err, z, 100, 200) == min(max(expect, 100), 200)


def test_systematic_resampling_is_unbiased():
    rng = np.random.default_rng(5)
    w = rng.random(50)
    w /= w.sum()
    counts = np.zeros(50)
    for _ in range(2000):
        counts += np.bincount(systematic_indices(w, 1000, rng), minlength=50)
    np.testing.assert_allclose(counts / 2000, 1000 * w, atol=0.05)
    idx = systematic_indices(w, 1000, rng)  # low variance: each count within 1 of N w_i
    assert np.all(np.abs(np.bincount(idx, minlength=50) - 1000 * w) < 1.0 + 1e-9)


def test_kld_resample_shrinks_a_tight_cloud_and_keeps_a_wide_one():
    rng = np.random.default_rng(6)
    tight = rng.normal([5, 5, 0], [0.1, 0.1, 0.05], size=(3000, 3))
    w = np.full(3000, 1 / 3000)
    assert len(kld_resample(tight, w, rng, err=0.05, z=0.99, min_n=100, max_n=3000)) < 500
    wide = np.column_stack([rng.uniform(0, 50, 3000), rng.uniform(0, 50, 3000),
                            rng.uniform(-3, 3, 3000)])
    assert len(kld_resample(wide, w, rng, err=0.05, z=0.99, min_n=100, max_n=3000)) == 3000


def test_cluster_estimate_picks_heaviest_cluster():
    rng = np.random.default_rng(7)
    a = rng.normal([1, 1, 3.1], [0.05, 0.05, 0.02], size=(300, 3))
    a[:, 2] = (a[:, 2] + np.pi) % (2 * np.pi) - np.pi  # straddles +-pi
    b = rng.normal([8, 8, 0], [0.05, 0.05, 0.02], size=(300, 3))
    w = np.concatenate([np.full(300, 2.0), np.full(300, 1.0)])
    mean, cov = cluster_estimate(np.vstack([a, b]), w / w.sum())
    assert np.hypot(*(mean[:2] - [1, 1])) < 0.02
    assert abs(np.angle(np.exp(1j * (mean[2] - 3.1)))) < 0.01
    assert cov[0, 0] < 0.01 and cov[2, 2] < 0.01


def test_table_kernel_equals_direct_kernel_after_region_updates():
    grid, scan, parts = _world()
    field = LikelihoodField(grid.copy(), 2.0)
    cfg = AmclConfig(z_hit=0.9, z_rand=0.1, max_beams=61)
    model = SensorModel(field, cfg)
    r, a, rmax = select_beams(scan, 61, None, None, keep_max_range=False)
    for k in range(3):
        if k:
            patch = np.full((10, 12), 100 if k == 1 else 0, dtype=np.int8)
            field.update_region(patch, 60 + 5 * k, 30)
        logw, _ = model.weigh(parts, scan, False)
        direct = K.likelihood_field_kernel(parts, np.zeros(3), r, a, field.dist_m, 0.05, 0.0,
                                           0.0, 2.0, 0.9, 0.1, 0.2, rmax)
        np.testing.assert_allclose(logw, np.log(direct), rtol=1e-12)

