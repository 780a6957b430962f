"""The rearranged-room simulator: gatmo's built-in data (see :func:`simulate_scenario`)."""

from gatmo.datasets.sim.config import SimConfig
from gatmo.datasets.sim.presets import make_world
from gatmo.datasets.sim.scenario import (
    ScenarioResult,
    SimRun,
    load_scenario,
    simulate_run,
    simulate_run_detailed,
    simulate_scenario,
)
from gatmo.datasets.sim.world import World, rasterize

__all__ = ["ScenarioResult", "SimConfig", "SimRun", "World", "load_scenario", "make_world",
           "rasterize", "simulate_run", "simulate_run_detailed", "simulate_scenario"]
