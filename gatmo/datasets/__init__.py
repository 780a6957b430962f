"""Readers and writers for logs and trajectories, and the rearranged-room simulator."""

from gatmo.datasets.types import ReadStats, Scan, ScanSource

__all__ = ["ReadStats", "Scan", "ScanSource"]
