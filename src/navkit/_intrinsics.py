"""Numba intrinsics shared by the compiled kernels (imported only by kernel modules, so that
``import navkit`` does not load Numba).

``prefetch(a, q)``: a hint to the CPU to load the cache line of ``a[q]`` - LLVM's
``llvm.prefetch`` (read, high temporal locality, data cache). It changes no result and never
faults (an address outside the array is allowed). Used where a kernel's next reads hop
between rows in a way the hardware prefetcher does not follow (the obstacles' robust vertex
normals, the planes' border refinement; ``docs/kernels.md``).
"""

from __future__ import annotations

from llvmlite import binding as llvm_binding
from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

__all__ = ["prefetch"]

# the intrinsic's name mangles its pointer type: opaque pointers from LLVM 17 on, typed ``i8*``
# before (the LLVM of older llvmlite releases, which numba >= 0.59 allows)
_PREFETCH_NAME = (
    "llvm.prefetch.p0" if llvm_binding.llvm_version_info[0] >= 17 else "llvm.prefetch.p0i8"
)


@intrinsic
def prefetch(_typingctx, arr, idx):  # type: ignore[no-untyped-def]  # pragma: no cover
    """``prefetch(a, q)``: load the cache line of ``a.reshape(-1)[q]`` (``a`` C-contiguous,
    ``q`` an integer) ahead of its use. No effect on any result."""
    sig = types.void(arr, idx)

    def codegen(context, builder, signature, args):  # type: ignore[no-untyped-def]
        ary = context.make_array(signature.args[0])(context, builder, args[0])
        ptr = builder.gep(ary.data, [args[1]])
        i8p = ir.IntType(8).as_pointer()
        i32 = ir.IntType(32)
        fnty = ir.FunctionType(ir.VoidType(), [i8p, i32, i32, i32])
        fn = cgutils.get_or_insert_function(builder.module, fnty, _PREFETCH_NAME)
        builder.call(fn, [builder.bitcast(ptr, i8p), i32(0), i32(3), i32(1)])
        return context.get_dummy_value()

    return sig, codegen
