"""A local Ray instance shared by the Ray tests of one module."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="module")
def ray_local():
    """A local Ray instance with 2 CPUs for the tests of one module (skipped without ray)."""
    ray = pytest.importorskip(
        "ray", reason="ray not installed (the ray extra): pip install -e '.[test,ray]'")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        yield ray
    finally:
        ray.shutdown()
