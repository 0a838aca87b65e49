"""`fma(a, b, c)`: a * b + c rounded once (LLVM's fused multiply-add), for numba kernels.

numpy's small matrix-vector products go through OpenBLAS, whose kernels on this project's x86-64 machines round
each row's two-term dot product as ``fma(x0, h0, x1 * h1)`` (a test checks this against ``rows @ h``). Compiled
code that must reproduce those numbers bit for bit, so that episodes do not change, uses this.
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
