"""Mitsuba plugins of nidar_mi, one per module; installed as :mod:`nidar_mi.plugins`.

Each module has a ``register()`` that defines its plugin class for the active variant and
registers it with Mitsuba. :func:`register_all` is called by :func:`nidar_mi.backend.set_variant`.
"""

import importlib

#: Plugin modules, in registration order.
PLUGIN_MODULES = ("lidar", "retroreflector")

__all__ = ["PLUGIN_MODULES", "register_all"]


def register_all() -> None:
    """Register every plugin of this package for the active Mitsuba variant."""
    for name in PLUGIN_MODULES:
        importlib.import_module(f"{__name__}.{name}").register()
