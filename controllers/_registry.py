"""Built-in laws by short name, and plug-ins by import path ``"package.module:Class"``.

Built-in and plug-in laws are found the same way and constructed the same way,
``Cls(model, *, Ts, **options)`` (`controllers._interface`); nothing else distinguishes
them.
"""
from __future__ import annotations

import functools
import importlib
import inspect
import os
import types

from reduced_model.code import invalidate_stale_plugin_caches

from ._baselines import JointPD, RigidComputedTorque
from ._ekf import ExtendedKalmanFilter, PositionEKF
from ._lqr import GainScheduledLQR
from ._pbc import IdealisedPBC, PassivityBasedController
from ._replay import TorqueReplay
from ._smo import BoundaryLayerSMO, PaperSMO, PositionOnlySMO

__all__ = ["CONTROLLERS", "OBSERVERS", "PluginError", "resolve", "accepted_options"]

CONTROLLERS: dict[str, type] = {
    "pbc": PassivityBasedController, "pbc-idealised": IdealisedPBC, "pd": JointPD,
    "ct": RigidComputedTorque, "lqr": GainScheduledLQR, "replay": TorqueReplay,
}
OBSERVERS: dict[str, type] = {
    "smo-paper": PaperSMO, "smo-bl": BoundaryLayerSMO, "smo-pos": PositionOnlySMO,
    "ekf": ExtendedKalmanFilter, "ekf-pos": PositionEKF,
}


class PluginError(ValueError):
    """A law that cannot be found, imported or constructed (one line, says why)."""


def resolve(kind: str, builtins: dict[str, type], role: str) -> type:
    """The class named by ``kind``: a built-in short name, or ``"package.module:Class"``.

    What a scenario's ``controller.kind`` or ``observer.kind`` names is found here: the
    module is imported (from the current directory first, as ``python -m`` finds
    modules), the class looked up, its constructor's signature read.  Nothing is built.

    Parameters
    ----------
    kind : str
        A key of ``builtins`` (``"pbc"``), or an import path ``"package.module:Class"``
        (``Class`` may be dotted: a class nested in another).
    builtins : dict of str to type
        The built-in laws of the role (`CONTROLLERS` or `OBSERVERS`).
    role : str
        ``"controller"`` or ``"observer"``: named in the errors.

    Returns
    -------
    type
        The class (not an instance).

    Raises
    ------
    PluginError
        One line saying why: an unknown short name (with the built-in ones), a module
        that does not import (with its exception, and where modules are looked for), no
        such attribute, not a class, a constructor whose signature cannot be read.

    Examples
    --------
    >>> from controllers import CONTROLLERS, resolve
    >>> resolve("pbc", CONTROLLERS, "controller").__name__
    'PassivityBasedController'
    >>> resolve("controllers:JointPD", CONTROLLERS, "controller") is CONTROLLERS["pd"]
    True
    >>> resolve("pdd", CONTROLLERS, "controller")
    Traceback (most recent call last):
        ...
    controllers._registry.PluginError: unknown controller 'pdd' (built-in: pbc, ...; or a plug-in as "package.module:Class")
    """
    if ":" not in kind:
        if kind not in builtins:
            raise PluginError(f"unknown {role} {kind!r} (built-in: {', '.join(builtins)}; "
                              "or a plug-in as \"package.module:Class\")")
        return builtins[kind]
    module_name, _, attr = kind.partition(":")
    if not module_name or not attr:
        raise PluginError(f"{kind!r} is not an import path \"package.module:Class\"")
    invalidate_stale_plugin_caches(module_name)  # before numba can load its old code
    try:
        module = importlib.import_module(module_name)
    except Exception as exc:  # noqa: BLE001 - any import failure is the user's to see
        hint = ""
        if isinstance(exc, ModuleNotFoundError) and module_name.split(".")[0] == (
                exc.name or "").split(".")[0]:
            hint = (f" (a plug-in's module must be importable: installed, on PYTHONPATH, or "
                    f"in the directory the command runs from, here {os.getcwd()})")
        raise PluginError(f"cannot import {module_name!r}: {type(exc).__name__}: {exc}{hint}") \
            from None
    cls = module
    for part in attr.split("."):
        cls = getattr(cls, part, None)
        if cls is None:
            raise PluginError(f"module {module_name!r} has no {attr!r}")
    if not inspect.isclass(cls):
        raise PluginError(f"{kind!r} is not a class")
    try:
        inspect.signature(cls)
    except (TypeError, ValueError):  # a builtin type (dict, type): no readable signature
        raise PluginError(f"{kind!r}: the signature of its constructor cannot be read (a law "
                          "is a class constructed as Cls(model, *, Ts, **options))") from None
    return cls


@functools.cache  # a signature costs ~0.15 ms; every scenario check asks twice
def accepted_options(cls: type) -> types.MappingProxyType | None:
    """Keyword arguments of ``cls(model, ...)`` with their defaults (``inspect.empty`` if
    required): a law's ``Ts`` and options, a plant's settings; None if it takes
    ``**kwargs`` (anything goes)."""
    params = list(inspect.signature(cls).parameters.values())[1:]  # after ``model``
    if any(p.kind is p.VAR_KEYWORD for p in params):
        return None
    return types.MappingProxyType({p.name: p.default for p in params
                                   if p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD)})
