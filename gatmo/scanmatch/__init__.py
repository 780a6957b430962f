"""Scan matching: 2D ICP and scan-matching odometry."""

from gatmo.scanmatch.icp import IcpResult, icp_2d
from gatmo.scanmatch.odometry import IcpConfig, MatchResult, ScanMatchOdometry

__all__ = ["IcpConfig", "IcpResult", "MatchResult", "ScanMatchOdometry", "icp_2d"]
