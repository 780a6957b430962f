"""The oracle benchmark's split of a pose error series into bands."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.bench_gatmo_oracle import error_band


def test_bands_add_up_to_the_error_and_separate_time_scales():
    rng = np.random.default_rng(0)
    n = 600
    t = np.arange(n)
    err = np.stack([0.05 + 0.03 * np.sin(2 * np.pi * t / n),  # constant + slow
                    0.02 * rng.standard_normal(n),  # fast
                    np.zeros(n)], axis=1)
    trusted = np.ones(n, dtype=bool)
    slow, mid, fast = (error_band(err, trusted, b) for b in ("slow", "mid", "fast"))
    np.testing.assert_allclose(slow + mid + fast, err, atol=1e-12)
    assert np.all(error_band(err, trusted, "none") == 0.0)
    assert np.array_equal(error_band(err, trusted, "all"), err)
    const = error_band(err, trusted, "const")
    assert const.shape == err.shape and abs(const[0, 0] - 0.05) < 0.01
    # the slow sine lands in the slow band, the white noise in the fast one
    assert np.std(slow[50:-50, 0] - err[50:-50, 0]) < 0.005
    assert np.std(fast[:, 1]) > 0.8 * 0.02 and np.std(slow[:, 1]) < 0.005
    with pytest.raises(ValueError):
        error_band(err, trusted, "other")
