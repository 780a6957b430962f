"""gatmo: Monte Carlo localization plus an object map that keeps up with moved furniture.

Subpackages: ``gatmo.maps`` (grids, map I/O, likelihood field, ray casting), ``gatmo.datasets``
(CARMEN logs, ROS bags, TUM trajectories, Wean Hall logs, the simulator), ``gatmo.localization``
(Monte Carlo localization), ``gatmo.scanmatch`` (ICP, map building), ``gatmo.objects``
(GATMO proper), ``gatmo.pipeline`` (composition) and ``gatmo.cli``.
"""

import os as _os

__version__ = "0.1.0"

# numba's parallel kernels run on OpenMP (libgomp), whose idle threads spin by default: two
# gatmo processes sharing the cores (a benchmark's --procs 2, a second job) then slowed each
# other's scans 3-7x, single scans to 1-4 s (docs/experiments.md, forty-eighth session).
# Waiting passively costs a lone process nothing measurable. A value the user set wins; it
# must be in the environment before the OpenMP runtime starts, so it is set on import.
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
