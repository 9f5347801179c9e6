"""The bundled leaf task types (seed 000 Sec. VI, Fig. 11-14), one module each, registered here.

=============================  ====================  ================================================
task type                      module                seed 000
=============================  ====================  ================================================
take-off                       :mod:`.take_off`      Sec. VI-A, Fig. 11
fly-to                         :mod:`.fly_to`        Sec. VI-B, Fig. 12
land                           :mod:`.land`          Sec. VI-C, Fig. 13
wait                           :mod:`.wait`          Sec. VI-D
scan-ground                    :mod:`.scan_ground`   Sec. VI-E, Fig. 14
external-velocity              :mod:`.external_velocity`  Sec. VI-F
hover                          :mod:`.hover`         ours (the behaviors layer's missions)
request-operator-assistance    :mod:`.operator_assistance`  ours
=============================  ====================  ================================================

Each module holds one :class:`~companion.tst.leaves.base.LeafType`: its parameters, ``check()``,
``get_constraints()``, plan, ``expand()``, Fig. 4 flags and executor. To add a task type, write such a
class and :func:`~companion.tst.registry.register` an instance (as ``tests/test_tst_new_leaf_type.py``
does); nothing else changes. Importing :mod:`companion.tst` registers the bundled ones.
"""

from __future__ import annotations

from companion.tst.leaves.base import LeafType
from companion.tst.leaves.external_velocity import EXTERNAL_VELOCITY
from companion.tst.leaves.fly_to import FLY_TO
from companion.tst.leaves.hover import HOVER
from companion.tst.leaves.land import LAND
from companion.tst.leaves.operator_assistance import REQUEST_OPERATOR_ASSISTANCE
from companion.tst.leaves.scan_ground import SCAN_GROUND
from companion.tst.leaves.take_off import TAKE_OFF
from companion.tst.leaves.wait import WAIT
from companion.tst.registry import register

__all__ = ["BUNDLED", "LeafType"]

#: The platform's leaf task types, in the order seed 000 Sec. VI lists them (ours last).
BUNDLED: tuple[LeafType, ...] = (TAKE_OFF, FLY_TO, LAND, WAIT, SCAN_GROUND, EXTERNAL_VELOCITY, HOVER,
                                 REQUEST_OPERATOR_ASSISTANCE)

for _leaf in BUNDLED:
    register(_leaf)
