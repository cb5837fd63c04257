"""The packs' items as C-contiguous n-d views, by their layout rows: ``view1`` … ``view4``.

The numba kernels read ~150 items of four flat packs (:mod:`.packs`) as 1- to 4-d arrays, re-made
at every call of the assembly; an item is named by its row ``[offset, d0, d1, d2, d3, size]`` of
the packs' layout table. Numba's ``reshape`` checks and computes the strides in a runtime helper:
~40 ns per view, measured (`benchmarks`-style njit loop, numba 0.68), ~26 views per frame group
and assembly, ≈ 1 µs of a 5 µs B1 residual. These intrinsics fill the array structure directly
(the data pointer at the item's offset, C strides from the shape, the pack's meminfo and parent,
so the pack stays alive and read-only packs give read-only views): the same type and the same
elements as ``pack[offset:offset + size].reshape(d0, …)``, at no measurable cost.

They are intrinsics rather than functions because the step's kernels run without numba's runtime
(:mod:`flexmb_core.jit`), and numba compiles no function that returns a new array there; an
intrinsic is lowered in place. So they exist in numba code only: Python slices the pack itself.
The caller guarantees the item lies in the pack (the layout table is built with the packs,
:class:`~.packs.ModelPacks`).
"""

from __future__ import annotations

from numba import types
from numba.core.imputils import impl_ret_borrowed
from numba.extending import intrinsic
from numba.np.arrayobj import make_array, populate_array


def _row_view(ndim: int):
    @intrinsic
    def row_view(typingctx, pack, row):
        """The item of a pack that a layout row ``[offset, d0, d1, d2, d3, size]`` names:
        ``pack[offset:offset + size]`` (1-d) or its reshape to ``(d0, …)`` (n-d)."""
        if not (isinstance(pack, types.Array) and pack.ndim == 1 and pack.layout == "C"
                and isinstance(row, types.Array) and row.ndim == 1
                and isinstance(row.dtype, types.Integer)):
            return None
        view = types.Array(pack.dtype, ndim, "C", readonly=not pack.mutable)

        def codegen(context, builder, sig, args):
            src = make_array(sig.args[0])(context, builder, args[0])
            entries = make_array(sig.args[1])(context, builder, args[1])

            def entry(k):
                value = builder.load(builder.gep(entries.data, [context.get_constant(types.intp, k)]))
                return context.cast(builder, value, row.dtype, types.intp)
            dims = [entry(5)] if ndim == 1 else [entry(1 + k) for k in range(ndim)]
            out = make_array(view)(context, builder)
            itemsize = context.get_constant(types.intp, context.get_abi_sizeof(context.get_data_type(pack.dtype)))
            strides = [itemsize]
            for d in reversed(dims[1:]):
                strides.insert(0, builder.mul(strides[0], d))
            # the pack's meminfo and parent: the view keeps the pack alive
            populate_array(out, data=builder.gep(src.data, [entry(0)]), shape=dims, strides=strides,
                           itemsize=itemsize, meminfo=src.meminfo, parent=src.parent)
            return impl_ret_borrowed(context, builder, view, out._getvalue())
        return view(pack, row), codegen
    return row_view


# The packs' items by their layout rows, in numba code only (an intrinsic has no Python body)
view1 = _row_view(1)
view2 = _row_view(2)
view3 = _row_view(3)
view4 = _row_view(4)
