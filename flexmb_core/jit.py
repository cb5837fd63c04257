"""The numba options of every kernel a step runs: ``@njit(**KERNEL)``.

``cache=True``: compiled once per machine (:mod:`flexmb_core.numba_cache` keeps the cache in step
with the sources).

``_nrt=False``: no numba runtime in the step's kernels. With it, numba counts the references of
every array a kernel receives, slices or views, by atomic increments and decrements: measured with
``perf`` on the B1 cantilever (4 cubic frame elements, after the load ramp), ``NRT_incref`` and
``NRT_decref`` took 16 % of a step, about 90 of each per step. The step's kernels allocate
nothing (the packs and scratch arrays are made once, in Python), return no array and keep no view
beyond the call, so the references are the caller's and counting them buys nothing. Without the
runtime numba refuses, when it compiles, any allocation (``np.empty``) or any function returning a
new array in these kernels: that rule of the time loop is then checked by the compiler
(``tests/unit/test_signatures.py`` checks that every step kernel is compiled this way). The
functions these kernels call inherit the option. It is an option of numba's CPU target
(``numba.core.cpu.CPUTargetOptions._nrt``) that numba's own tests use but its documentation does
not list: a numba without it refuses to compile the kernels ("Unrecognized options"), so they
would fail loudly rather than count references again.
"""

from __future__ import annotations

KERNEL = {"cache": True, "_nrt": False}
