"""Mitsuba plugins of nidar_mi, one per module; installed as :mod:`nidar_mi.plugins`.

A Python plugin class derives from a class of one Mitsuba variant (``mi.Sensor`` is the active
variant's ``Sensor``). So a plugin module is executed once per variant, with that variant active:
it defines its class at module level and ends by registering it, as mitsuba3's own Python
plugins do. :func:`register_all` (called by :func:`nidar_mi.backend.set_variant`) executes every
module of :data:`PLUGIN_MODULES` for the active variant, once, and makes
``nidar_mi.plugins.<name>`` that variant's module; :func:`plugin_module` returns the module of any
variant registered so far. Importing a plugin module needs an active variant.

Invalid parameters: a plugin's constructor raises the package's one error type,
:class:`~nidar_mi.errors.NidarError`, with one line naming the plugin and the parameter. Mitsuba
turns an exception raised in a Python plugin's ``__init__`` into a ``RuntimeError`` whose text
carries the Python traceback, ending with ``NidarError: <message>`` (the exception object itself
is not kept); :func:`parameter_error` reads the message back, and
:func:`nidar_mi.scene.load_scene` reports it.
"""

from __future__ import annotations

import importlib.util
import sys
from types import ModuleType

__all__ = [
    "PLUGIN_MODULES",
    "parameter_error",
    "plugin_module",
    "register_all",
]

#: Plugin modules, in registration order.
PLUGIN_MODULES = ("lidar", "retroreflector", "roughdiffuse")

_by_variant: dict[str, dict[str, ModuleType]] = {}


def parameter_error(err: BaseException) -> str | None:
    """The message of the :class:`~nidar_mi.errors.NidarError` a plugin raised that made a
    Mitsuba load fail, or None.

    Args:
        err: the exception ``mi.load_string`` / ``mi.load_dict`` raised (or the error itself).
    """
    from nidar_mi.errors import NidarError

    if isinstance(err, NidarError):
        return str(err)
    marker = f"{NidarError.__name__}: "
    text = str(err)
    if marker not in text:
        return None
    message = text.rpartition(marker)[2]
    return " ".join(line.strip() for line in message.splitlines() if line.strip())


def register_all() -> None:
    """Register every plugin for the active Mitsuba variant (executing its module once)."""
    import mitsuba as mi

    variant = mi.variant()
    if variant is None:
        raise RuntimeError("set a Mitsuba variant before registering the plugins")
    if variant not in _by_variant:
        _by_variant[variant] = {name: _execute(name, variant) for name in PLUGIN_MODULES}
    for name, module in _by_variant[variant].items():
        sys.modules[f"{__name__}.{name}"] = module
        setattr(sys.modules[__name__], name, module)


def plugin_module(name: str, variant: str | None = None) -> ModuleType:
    """The plugin module ``name`` as executed for ``variant`` (default: the active one).

    Raises:
        KeyError: the plugins were not registered for that variant.
    """
    import mitsuba as mi

    return _by_variant[variant or mi.variant()][name]


def _execute(name: str, variant: str) -> ModuleType:
    """Execute plugin module ``name`` with ``variant`` active; its last lines register it.

    A module imported directly under the same variant is taken as it is (not executed twice).
    """
    full = f"{__name__}.{name}"
    module = sys.modules.get(full)
    if module is not None and getattr(module, "VARIANT", None) == variant:
        return module
    spec = importlib.util.find_spec(full)
    module = importlib.util.module_from_spec(spec)
    sys.modules[full] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[full]
        raise
    return module
