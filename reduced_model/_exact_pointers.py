"""The exact-kinematics kernels as the paper's kernels call them: through the pointers of
`reduced_model._on_demand`, so that they are compiled only in a process that packs a
model with exact kinematics (`load_exact_kernels`), not for every run of the paper's
linear kinematics.  Each takes the arguments of its kernel in
`reduced_model._exact_kernels`; the entry points it calls are in
`reduced_model._exact_entries`."""
from __future__ import annotations

from numba import njit

from . import _on_demand

__all__ = ["load_exact_kernels", "exact_mass_bias_into", "exact_coriolis_matrix_into",
           "exact_elastic_into", "exact_tips_into"]

_ENTRIES = "reduced_model._exact_entries"
_MASS_BIAS, _CORIOLIS, _ELASTIC, _TIPS = (_on_demand.slot(_ENTRIES, name)
                                          for name in ("mass_bias", "coriolis", "elastic", "tips"))


def load_exact_kernels() -> None:
    """Compile or load the exact kernels in this process (`reduced_model._kernels.pack_model`
    calls it for every exact model)."""
    _on_demand.load(_ENTRIES)


# Every entry point takes a model's `ExactRef` and a workspace's `ExactScratch` unpacked,
# then the kernel's own arguments.
@njit(cache=True, inline="always")
def exact_mass_bias_into(ref, scratch, Q, Qd, M, h, with_bias):
    _on_demand.call(_on_demand.entry(_MASS_BIAS), (
        ref.reals, ref.reals.shape[0], ref.N, ref.n1, ref.n2, ref.offset, scratch.wc,
        scratch.wc.shape[0], scratch.oc, scratch.wr, scratch.wr.shape[0], scratch.orr, Q, Qd,
        M, h, with_bias))


@njit(cache=True, inline="always")
def exact_coriolis_matrix_into(ref, scratch, Q, Qd, C):
    _on_demand.call(_on_demand.entry(_CORIOLIS), (
        ref.reals, ref.reals.shape[0], ref.N, ref.n1, ref.n2, ref.offset, scratch.wc,
        scratch.wc.shape[0], scratch.oc, scratch.wr, scratch.wr.shape[0], scratch.orr, Q, Qd,
        C))


@njit(cache=True, inline="always")
def exact_elastic_into(ref, Q, Qd, f, with_damping):
    _on_demand.call(_on_demand.entry(_ELASTIC), (
        ref.reals, ref.reals.shape[0], ref.N, ref.n1, ref.n2, ref.offset, Q, Qd, f,
        with_damping))


@njit(cache=True, inline="always")
def exact_tips_into(ref, Q, out):
    _on_demand.call(_on_demand.entry(_TIPS), (
        ref.reals, ref.reals.shape[0], ref.N, ref.n1, ref.n2, ref.offset, Q, out))
