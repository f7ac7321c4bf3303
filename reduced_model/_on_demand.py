"""Kernels compiled on demand: compiled callers reach them through function pointers that
a process fills when it first builds a model that needs them.

The paper's plants and laws have branches for what the paper's arm does not have: the
exact kinematics (`reduced_model._exact_pointers`) and the joints' friction and drives
(`reduced_model._joint_pointers`).  Called directly, numba compiled those kernels on a
cold cache for every run, the paper's arm included, and LLVM optimised them again inside
every caller that linked them (on the reference machine ≈ 19 s for the exact kinematics, 16 s
for the joints, plus the callers' share).  Called through a pointer, a caller holds one
indirect call; the kernels themselves are C-callable entry points (`ENTRIES`) compiled,
or loaded from numba's cache, when their module is first imported by `load`.  Each entry
module imports the kernels it wraps, and nothing imports it but `load`: the modules
that call through the pointers are not imported back (no import cycle).

The pointers live in a small table in this process's memory, which this module makes
known to LLVM under the symbol ``flexarm_on_demand_kernels``: compiled callers refer to
the table by that name, not by its address, so the machine code numba caches finds the
table of whichever process loads it.  A slot not loaded holds a null pointer, and a
caller that reaches it raises `RuntimeError` instead of calling it (a model unpickled in
another process, whose kernels nobody loaded there).
"""
from __future__ import annotations

import ctypes
import importlib

import llvmlite.binding as llvm
from llvmlite import ir
from numba import njit, types
from numba.core.extending import intrinsic
from numba.np.arrayobj import make_array

__all__ = ["ENTRIES", "slot", "load", "entry", "call"]

#: (module, entry point) of each slot of the table, in order.
ENTRIES = (("reduced_model._exact_entries", "mass_bias"),
           ("reduced_model._exact_entries", "coriolis"),
           ("reduced_model._exact_entries", "elastic"),
           ("reduced_model._exact_entries", "tips"),
           ("reduced_model._joint_entries", "advance"))
_SYMBOL = "flexarm_on_demand_kernels"
_table = (ctypes.c_void_p * len(ENTRIES))()
llvm.add_symbol(_SYMBOL, ctypes.addressof(_table))


def slot(module: str, name: str) -> int:
    """The slot of the entry point ``name`` of ``module`` (a compile-time constant for the
    callers that keep it in a global)."""
    return ENTRIES.index((module, name))


def load(module: str) -> None:
    """Compile or load the entry points of ``module`` (one of `ENTRIES`' modules) and point
    their slots at them; once per process."""
    slots = [slot for slot, (owner, _) in enumerate(ENTRIES) if owner == module]
    if not slots:
        raise ValueError(f"no kernels are loaded on demand from {module!r}")
    if all(_table[slot] for slot in slots):
        return
    entries = importlib.import_module(module)  # compiles or loads them: the import is the work
    for slot in slots:
        _table[slot] = getattr(entries, ENTRIES[slot][1]).address


@intrinsic
def _address(typingctx, slot):
    """The pointer in ``slot`` of the table (0: not loaded)."""
    if not isinstance(slot, types.Integer):
        return None

    def codegen(context, builder, sig, args):
        i64 = ir.IntType(64)
        table = builder.module.globals.get(_SYMBOL)
        if table is None:  # declared here, defined by the process (`llvm.add_symbol`)
            table = ir.GlobalVariable(builder.module, ir.ArrayType(i64, len(ENTRIES)), _SYMBOL)
        index = context.cast(builder, args[0], sig.args[0], types.intp)
        return builder.load(builder.gep(table, [ir.Constant(ir.IntType(32), 0), index]))

    return types.int64(slot), codegen


@njit(cache=True, inline="always")
def entry(slot):
    """The address of the entry point in ``slot``; raises when it is not loaded."""
    address = _address(slot)
    if address == 0:
        raise RuntimeError("a kernel compiled on demand is not loaded in this process: "
                           "see reduced_model._on_demand.load")
    return address


@intrinsic
def call(typingctx, address, arguments):
    """Call the C function at ``address`` with the tuple ``arguments``: each array as its
    data pointer (C-contiguous arrays only), each integer or flag as an int64, each real
    as a float64."""
    if not isinstance(address, types.Integer) or not isinstance(arguments, types.BaseTuple):
        return None
    for t in arguments:
        if isinstance(t, types.Array) and t.layout != "C":
            return None
        if not isinstance(t, (types.Array, types.Integer, types.Boolean, types.Float)):
            return None

    def codegen(context, builder, sig, args):
        values = []
        for i, t in enumerate(sig.args[1]):
            value = builder.extract_value(args[1], i)
            if isinstance(t, types.Array):
                values.append(make_array(t)(context, builder, value).data)
            else:
                target = types.float64 if isinstance(t, types.Float) else types.int64
                values.append(context.cast(builder, value, t, target))
        function = ir.FunctionType(ir.VoidType(), [v.type for v in values])
        builder.call(builder.inttoptr(args[0], function.as_pointer()), values)
        return context.get_dummy_value()

    return types.void(address, arguments), codegen
