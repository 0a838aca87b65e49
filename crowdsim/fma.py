"""`fma(a, b, c)`: a * b + c rounded once (LLVM's fused multiply-add), for numba kernels.

numpy's small matrix products go through OpenBLAS, whose x86-64 kernels (with FMA) accumulate each two-term dot
product from +0.0 with fused multiply-adds: ``A @ v`` gives ``fma(a0, v0, fma(a1, v1, 0))`` per row, and
``X @ R.T`` with two or more rows gives ``fma(x1, r1, fma(x0, r0, 0))`` per entry (one row goes the first way).
Compiled code that must reproduce numpy's numbers bit for bit, so that episodes do not change when a step gets
faster, uses this (`envs.scoring.kernels`; `tests/envs/test_kernels.py` checks the observation against numpy's and skips
on a machine whose BLAS rounds otherwise).
"""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

_F64 = ir.DoubleType()


@intrinsic
def fma(typingctx, a, b, c):
    """float64 a * b + c with a single rounding (numba nopython code only)."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(_F64, [_F64, _F64, _F64]),
                                            "llvm.fma.f64")
        return builder.call(fn, args)

    return sig, codegen
