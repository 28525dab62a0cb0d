"""The small-vector algebra of the model modules: :mod:`gainsched._vec` (a base-layer
module, so that the firmware's rotations use it without the model), re-exported."""

from __future__ import annotations

from .._vec import broadcast, cross, dot, mtv, mv, stack3

__all__ = ["cross", "dot", "mv", "mtv", "broadcast", "stack3"]
