"""Deterministic HDF5 for the gain table: groups and datasets without modification
times, and the checksums that make a table's bytes its identity (a dataset's SHA-256 over
its dtype, shape and bytes; the root's over the attributes and every dataset's digest;
docs/table-format.md).

h5py writes the file; what it does not do by itself is leave the times out of groups
and checksum the content, hence these few helpers.
"""

from __future__ import annotations

import hashlib

import h5py
import numpy as np

__all__ = ["create_dataset", "create_group", "dataset_sha256", "root_sha256", "datasets"]


def create_dataset(group, name, data, units=None, doc=None):
    ds = group.create_dataset(name, data=data, track_times=False)
    if units is not None:
        ds.attrs["units"] = units
    if doc is not None:
        ds.attrs["description"] = doc
    return ds


def create_group(parent, name):
    """A group without modification times (h5py's create_group always tracks them)."""
    gcpl = h5py.h5p.create(h5py.h5p.GROUP_CREATE)
    gcpl.set_obj_track_times(False)
    gid = h5py.h5g.create(parent.id, name.encode(), gcpl=gcpl)
    return h5py.Group(gid)


def dataset_sha256(value) -> str:
    """SHA-256 of a dataset's value: a header (dtype and shape), then the bytes."""
    if isinstance(value, str | bytes):
        head, raw = "bytes", value.encode() if isinstance(value, str) else value
    else:
        a = np.asarray(value)
        a = np.ascontiguousarray(a, dtype=a.dtype.newbyteorder("<"))
        head, raw = f"{a.dtype.str}{a.shape}", a.tobytes()
    return hashlib.sha256(head.encode() + b"\0" + raw).hexdigest()


def root_sha256(attrs, digests) -> str:
    """SHA-256 over the root attributes (but data_sha256) and every dataset's digest."""
    h = hashlib.sha256()
    for k in sorted(attrs):
        if k != "data_sha256":
            v = attrs[k]
            h.update(f"{k}={v.decode() if isinstance(v, bytes) else v!r}\0".encode())
    for name in sorted(digests):
        h.update(f"{name}:{digests[name]}\0".encode())
    return h.hexdigest()


def datasets(f) -> dict:
    out = {}
    f.visititems(lambda name, obj: out.__setitem__(name, obj) if isinstance(obj, h5py.Dataset)
                 else None)
    return out
