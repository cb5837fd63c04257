"""``@njit(**KERNEL)`` kernels only (:mod:`flexmb_core.jit`): one element per call, group loops,
scatters.

Every kernel takes float64/int64 C-contiguous arrays so that it compiles exactly one
signature (``tests/unit/test_signatures.py`` checks it).
"""
