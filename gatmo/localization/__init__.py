"""Monte Carlo localization in the spirit of ROS/Nav2 AMCL."""

from gatmo.localization.config import AmclConfig
from gatmo.localization.mcl import MonteCarloLocalizer, PoseEstimate

__all__ = ["AmclConfig", "MonteCarloLocalizer", "PoseEstimate"]
