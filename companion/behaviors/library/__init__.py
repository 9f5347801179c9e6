"""The bundled behavior library (seed 001 Sec. 5.1.2): one module per behavior's execution controller.

Importing this package imports every module in it, and each registers its controller
(:func:`companion.behaviors.controller.register`). A new behavior is one module here plus a
descriptor in the catalog (``mission_specs/behavior_catalog.yaml``).
"""

import importlib
import pkgutil

for _info in pkgutil.iter_modules(__path__):
    importlib.import_module(f"{__name__}.{_info.name}")
