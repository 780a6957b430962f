"""gatmo: Monte Carlo localization plus an object map that keeps up with moved furniture.

Subpackages: ``gatmo.maps`` (grids, map I/O, likelihood field, ray casting), ``gatmo.datasets``
(CARMEN logs, ROS bags, TUM trajectories, Wean Hall logs, the simulator), ``gatmo.localization``
(Monte Carlo localization), ``gatmo.scanmatch`` (ICP, map building), ``gatmo.objects``
(GATMO proper), ``gatmo.pipeline`` (composition) and ``gatmo.cli``.
"""

__version__ = "0.1.0"
