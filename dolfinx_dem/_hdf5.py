"""Deleting objects of an HDF5 file, with the HDF5 library that DOLFINx has loaded.

A resumed run rewrites output times that a killed run may already have written after its last
checkpoint; DOLFINx's XDMFFile cannot overwrite a dataset, so those are deleted first. h5py
cannot do it here: its wheel brings a second HDF5 library whose symbols clash with DOLFINx's in
one process ("h5py is running against HDF5 1.10.8 when it was built against ...", then
``ValueError: Not a datatype``). So the few calls needed go through ctypes to the library
already in the process (Debian: ``libhdf5_openmpi.so.103``), on one process, while no one
else has the file open.
"""

from __future__ import annotations

import ctypes
import pathlib
import re
from collections.abc import Iterable

from dolfinx_dem.errors import OutputError

_H5F_ACC_RDWR = 1
_H5P_DEFAULT = 0
_H5E_DEFAULT = 0


def _library() -> ctypes.CDLL:
    """The HDF5 library mapped into this process by DOLFINx."""
    import dolfinx.io  # noqa: F401  (loads libhdf5)

    with open("/proc/self/maps") as f:
        paths = sorted({line.split()[-1] for line in f if re.search(r"/libhdf5(_\w+)?\.so[.\d]*$", line.strip())})
    if not paths:
        raise RuntimeError("the HDF5 library of DOLFINx is not loaded in this process")
    lib = ctypes.CDLL(paths[0])
    lib.H5Fopen.restype = ctypes.c_int64
    lib.H5Fopen.argtypes = [ctypes.c_char_p, ctypes.c_uint, ctypes.c_int64]
    lib.H5Fclose.argtypes = [ctypes.c_int64]
    lib.H5Lexists.argtypes = [ctypes.c_int64, ctypes.c_char_p, ctypes.c_int64]
    lib.H5Ldelete.argtypes = [ctypes.c_int64, ctypes.c_char_p, ctypes.c_int64]
    lib.H5Eset_auto2.argtypes = [ctypes.c_int64, ctypes.c_void_p, ctypes.c_void_p]
    lib.H5Gopen2.restype = ctypes.c_int64
    lib.H5Gopen2.argtypes = [ctypes.c_int64, ctypes.c_char_p, ctypes.c_int64]
    lib.H5Gclose.argtypes = [ctypes.c_int64]
    lib.H5Gget_info.argtypes = [ctypes.c_int64, ctypes.POINTER(_GroupInfo)]
    lib.H5Lget_name_by_idx.restype = ctypes.c_ssize_t
    lib.H5Lget_name_by_idx.argtypes = [ctypes.c_int64, ctypes.c_char_p, ctypes.c_int, ctypes.c_int, ctypes.c_uint64,
                                       ctypes.c_char_p, ctypes.c_size_t, ctypes.c_int64]
    return lib


class _GroupInfo(ctypes.Structure):
    """H5G_info_t."""

    _fields_ = [("storage_type", ctypes.c_int), ("nlinks", ctypes.c_uint64), ("max_corder", ctypes.c_int64),
                ("mounted", ctypes.c_uint)]


def _members(lib, fid: int, group: str) -> list[str]:
    """Absolute names of the links in ``group`` of the open file ``fid`` (none if it is missing)."""
    parts = group.strip("/").split("/")
    if not all(lib.H5Lexists(fid, ("/" + "/".join(parts[: k + 1])).encode(), _H5P_DEFAULT) > 0
               for k in range(len(parts))):
        return []
    gid = lib.H5Gopen2(fid, group.encode(), _H5P_DEFAULT)
    if gid < 0:
        return []
    try:
        info = _GroupInfo()
        if lib.H5Gget_info(gid, ctypes.byref(info)) < 0:
            raise OutputError(f"HDF5 cannot read group {group}")
        names = []
        for k in range(info.nlinks):
            buffer = ctypes.create_string_buffer(1024)
            n = lib.H5Lget_name_by_idx(gid, b".", 0, 0, k, buffer, len(buffer), _H5P_DEFAULT)  # by name, ascending
            if n < 0 or n >= len(buffer):
                raise OutputError(f"HDF5 cannot read the names in group {group}")
            names.append(f"/{group.strip('/')}/{buffer.value.decode()}")
        return names
    finally:
        lib.H5Gclose(gid)


def delete_unlisted(path: str | pathlib.Path, groups: Iterable[str], keep: Iterable[str]) -> list[str]:
    """Delete from the HDF5 file ``path`` every object in ``groups`` that is not in ``keep``
    (absolute names); returns the names deleted. A run killed between writing a dataset and
    listing it in its XDMF file leaves such an object behind, and DOLFINx could not write it
    again. Serial, with the file closed everywhere."""
    lib = _library()
    lib.H5Eset_auto2(_H5E_DEFAULT, None, None)
    fid = lib.H5Fopen(str(path).encode(), _H5F_ACC_RDWR, _H5P_DEFAULT)
    if fid < 0:
        raise OutputError(f"HDF5 cannot open {path} for writing")
    keep = set(keep)
    try:
        unlisted = [name for group in sorted(set(groups)) for name in _members(lib, fid, group) if name not in keep]
    finally:
        lib.H5Fclose(fid)
    return delete(path, unlisted)


def delete(path: str | pathlib.Path, names: Iterable[str]) -> list[str]:
    """Delete the objects ``names`` (absolute paths such as ``/Function/u/0_5``) from the HDF5
    file ``path`` where they exist; returns the names deleted. Serial: call it on one process
    with the file closed everywhere. The space is not reclaimed (the file does not shrink)."""
    lib = _library()
    lib.H5Eset_auto2(_H5E_DEFAULT, None, None)  # missing objects are expected: no error stack print
    fid = lib.H5Fopen(str(path).encode(), _H5F_ACC_RDWR, _H5P_DEFAULT)
    if fid < 0:
        raise OutputError(f"HDF5 cannot open {path} for writing")
    deleted = []
    try:
        for name in names:
            parts = name.strip("/").split("/")
            # H5Lexists fails on a missing intermediate group: test the path from the root down.
            if all(lib.H5Lexists(fid, ("/" + "/".join(parts[: k + 1])).encode(), _H5P_DEFAULT) > 0
                   for k in range(len(parts))):
                if lib.H5Ldelete(fid, ("/" + "/".join(parts)).encode(), _H5P_DEFAULT) < 0:
                    raise OutputError(f"HDF5 cannot delete {name} from {path}")
                deleted.append(name)
    finally:
        lib.H5Fclose(fid)
    return deleted
