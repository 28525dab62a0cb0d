"""Small-vector algebra over the last axis, written once for the model modules.

Each helper takes batches of 3-vectors (and 3x3 matrices) with any leading shape, real
or complex (complex-step safe: no ``abs``, no ``conj``). They exist because numpy's
general forms pay per call for generality these hot paths do not use: ``np.cross``
moves axes and broadcasts (~15 us on one vector, against ~4 us here), ``np.sum`` goes
through a Python wrapper. Each computes exactly what the general form computes, in the
same order of floating-point operations, so replacing one with the other changes no
bit of any result (tests/model/test_rotations.py checks this).
"""

from __future__ import annotations

import numpy as np

__all__ = ["cross", "dot", "mv", "mtv", "broadcast", "stack3"]


def cross(a, b):
    """``a x b`` over the last axis, shapes (..., 3) -> broadcast shape (..., 3).

    The same products and differences as ``np.cross`` (bit for bit).
    """
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return stack3(a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0)


def stack3(x, y, z):
    """``np.stack([x, y, z], -1)`` of broadcastable arrays, assigned into one array
    (``np.stack`` spends ~10 us a call in its Python wrapper; the same values)."""
    shape = np.broadcast_shapes(np.shape(x), np.shape(y), np.shape(z))
    out = np.empty(shape + (3,), dtype=np.result_type(x, y, z))
    out[..., 0], out[..., 1], out[..., 2] = x, y, z
    return out


def dot(a, b):
    """``a . b`` over the last axis, shape (...): ``np.sum(a * b, axis=-1)``."""
    return (a * b).sum(-1)


def mv(R, v):
    """Batched ``R @ v``, shapes (..., 3, 3), (..., 3) -> (..., 3)."""
    return np.einsum("...ij,...j->...i", R, v)


def mtv(R, v):
    """Batched ``R^T @ v``, shapes (..., 3, 3), (..., 3) -> (..., 3)."""
    return np.einsum("...ji,...j->...i", R, v)


def broadcast(a, shape):
    """``np.broadcast_to(a, shape)``, or ``a`` itself when it has that shape already (the
    one-sample hot paths: a read-only view costs ~8 us)."""
    return a if a.shape == shape else np.broadcast_to(a, shape)
