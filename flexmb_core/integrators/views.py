"""C-contiguous n-d views into a flat pack, built in place of ``pack[a:b].reshape(shape)``.

The numba kernels read ~150 items of four flat packs (:mod:`.packs`) as 2-, 3- and 4-d arrays,
re-made at every call of the assembly. Numba's ``reshape`` checks and computes the strides in a
runtime helper: ~40 ns per view, measured (`benchmarks`-style njit loop, numba 0.68), ~26 views per
frame group and assembly, ≈ 1 µs of a 5 µs B1 residual. These intrinsics fill the array structure
directly (the data pointer at the item's offset, C strides from the shape, the pack's meminfo and
parent, so the pack stays alive and read-only packs give read-only views): the same type and the
same elements as the ``reshape``, at no measurable cost. The caller guarantees the item lies in the
pack (the layout table is built with the packs, :class:`~.packs.ModelPacks`).
"""

from __future__ import annotations

from numba import types
from numba.core import cgutils
from numba.core.imputils import impl_ret_borrowed
from numba.extending import intrinsic
from numba.np.arrayobj import make_array, populate_array


def _c_view(ndim: int):
    @intrinsic
    def c_view(typingctx, pack, start, shape):
        """``pack[start:start + prod(shape)].reshape(shape)`` for a 1-d C ``pack``."""
        if not (isinstance(pack, types.Array) and pack.ndim == 1 and pack.layout == "C"
                and isinstance(shape, types.UniTuple) and shape.count == ndim
                and isinstance(shape.dtype, types.Integer) and isinstance(start, types.Integer)):
            return None
        view = types.Array(pack.dtype, ndim, "C", readonly=not pack.mutable)

        def codegen(context, builder, sig, args):
            src = make_array(sig.args[0])(context, builder, args[0])
            out = make_array(view)(context, builder)
            dims = [context.cast(builder, d, shape.dtype, types.intp)
                    for d in cgutils.unpack_tuple(builder, args[2], ndim)]
            itemsize = context.get_constant(types.intp, context.get_abi_sizeof(context.get_data_type(pack.dtype)))
            strides = [itemsize]
            for d in reversed(dims[1:]):
                strides.insert(0, builder.mul(strides[0], d))
            first = context.cast(builder, args[1], sig.args[1], types.intp)
            populate_array(out, data=builder.gep(src.data, [first]), shape=dims, strides=strides,
                           itemsize=itemsize, meminfo=src.meminfo, parent=src.parent)
            return impl_ret_borrowed(context, builder, view, out._getvalue())
        return view(pack, start, shape), codegen
    return c_view


c_view2 = _c_view(2)
c_view3 = _c_view(3)
c_view4 = _c_view(4)
