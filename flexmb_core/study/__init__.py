"""Studies over many runs of a scene: parameter sweeps (``flexmb sweep``) on Dask distributed.

``cluster`` (the Dask client every study verb uses), ``design`` (which values each run gets), ``runs`` (a run's effective scene, key and task),
``table`` (run files and the sweep table), ``plot``, ``progress`` and ``sweep`` (the verb).
Importing this package imports neither Dask nor matplotlib.
"""

from .design import Param, design, latin_hypercube, parse_param
from .runs import RunSpec, run_one
from .sweep import SweepEvent, SweepResult, execute, plan, sweep

__all__ = ["Param", "RunSpec", "SweepEvent", "SweepResult", "design", "execute", "latin_hypercube",
           "parse_param", "plan", "run_one", "sweep"]
