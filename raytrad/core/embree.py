"""Embree's packet queries: the library embreex ships, reached through ctypes.

embreex wraps Embree's single-ray queries (``rtcOccluded1``, ``rtcIntersect1``) in a
Python call per batch. Embree also traces *packets* of 8 rays at once
(``rtcOccluded8``, ``rtcIntersect8``), which answer the same queries on coherent rays
(a receiver's rays to one patch's samples leave one point for one region) about twice as
fast on this machine, with the same answers. embreex does not wrap them, so raytrad opens
the very library embreex was built with (:func:`library_path`: the wheel's bundled
``libembree4``) and builds its scenes through Embree's C API here; the compiled loops
that fill the packets and call Embree are in :mod:`raytrad.core._compiled_rays`, and
:class:`raytrad.core.visibility.Occluder` chooses between them and embreex.

Nothing here imports embreex (its package is found, not imported). Anything missing (a
build of embreex linked to an Embree found elsewhere, a library without the packet
functions, ``RAYTRAD_RAYS=embreex`` in the environment) leaves the queries to embreex.

References: Embree 4 API, ``rtcOccluded8``, ``rtcIntersect8``, ``rtcNewGeometry``
(https://github.com/RenderKit/embree/tree/master/doc/src/api).
"""

from __future__ import annotations

import ctypes
import functools
import importlib.util
import logging
import os
import threading
import weakref
from pathlib import Path
from typing import Any

import numpy as np

log = logging.getLogger(__name__)

#: Environment variable choosing how rays are traced: ``packets`` (the default, Embree's
#: 8-ray packets where the library is found) or ``embreex`` (its single-ray queries).
RAYS_VARIABLE = "RAYTRAD_RAYS"

#: Rays a packet holds (Embree's ``RTCRay8``).
PACKET = 8

# Embree 4's enums (rtcore_common.h, rtcore_buffer.h, rtcore_geometry.h, rtcore_scene.h)
_GEOMETRY_TRIANGLE = 0
_BUFFER_INDEX, _BUFFER_VERTEX = 0, 1
_FORMAT_UINT3, _FORMAT_FLOAT3 = 0x5003, 0x9003
_SCENE_FLAG_ROBUST = 1 << 2
_NO_ERROR = 0
_PROPERTY_VERSION_MAJOR = 1

_LOCK = threading.Lock()
_DEVICE: dict[int, int] = {}  # process id -> its one Embree device, made on first use


def wanted() -> bool:
    """Whether packets are asked for: :data:`RAYS_VARIABLE` is not ``embreex``."""
    return os.environ.get(RAYS_VARIABLE, "packets").strip().lower() != "embreex"


@functools.cache
def library_path() -> str | None:
    """The Embree 4 library embreex's wheel carries, or None when none is found.

    auditwheel (Linux) puts it in ``embreex.libs`` beside the package, delocate (macOS)
    in the package's ``.dylibs``, delvewheel (Windows) in ``embreex.libs`` too; a file
    named ``*embree4*`` there is the one embreex's modules load. Its packet functions
    must be exported (:func:`_library` checks when opening it).
    """
    spec = importlib.util.find_spec("embreex")
    if spec is None or not spec.submodule_search_locations:
        return None
    package = Path(next(iter(spec.submodule_search_locations)))
    folders = (package.parent / "embreex.libs", package / ".dylibs", package)
    for folder in folders:
        found = sorted(
            p for p in folder.glob("*embree4*") if p.suffix in (".so", ".4", ".dylib", ".dll")
        )
        if found:
            return str(found[0])
    return None


@functools.cache
def _library() -> Any:
    """The library opened by ctypes with the argument types of what raytrad calls."""
    path = library_path()
    if path is None:
        raise OSError("embreex's Embree library was not found")
    lib = ctypes.CDLL(path)
    pointer, size = ctypes.c_void_p, ctypes.c_size_t
    signatures: dict[str, tuple[list[Any], Any]] = {
        "rtcNewDevice": ([ctypes.c_char_p], pointer),
        "rtcGetDeviceError": ([pointer], ctypes.c_int),
        "rtcGetDeviceProperty": ([pointer, ctypes.c_int], ctypes.c_ssize_t),
        "rtcNewScene": ([pointer], pointer),
        "rtcSetSceneFlags": ([pointer, ctypes.c_int], None),
        "rtcNewGeometry": ([pointer, ctypes.c_int], pointer),
        "rtcSetNewGeometryBuffer": (
            [pointer, ctypes.c_int, ctypes.c_uint, ctypes.c_int, size, size],
            pointer,
        ),
        "rtcCommitGeometry": ([pointer], None),
        "rtcAttachGeometry": ([pointer, pointer], ctypes.c_uint),
        "rtcReleaseGeometry": ([pointer], None),
        "rtcCommitScene": ([pointer], None),
        "rtcReleaseScene": ([pointer], None),
    }
    for name, (arguments, result) in signatures.items():
        function = getattr(lib, name)
        function.argtypes, function.restype = arguments, result
    for name in ("rtcOccluded8", "rtcIntersect8"):  # called by the compiled loops
        getattr(lib, name)
    return lib


def available() -> bool:
    """Whether packet queries are to be used: asked for (:func:`wanted`) and
    :func:`usable`."""
    return wanted() and usable()


@functools.cache
def usable() -> bool:
    """Whether the library opens with every function raytrad calls and is Embree 4 (the
    packets' layout and the enums here are Embree 4's); whatever the environment asks."""
    try:
        major = _library().rtcGetDeviceProperty(_device(), _PROPERTY_VERSION_MAJOR)
    except (OSError, AttributeError) as error:
        log.debug("Embree packets unavailable (%s): rays go through embreex", error)
        return False
    if major != 4:
        log.debug("Embree %s found, not 4: rays go through embreex", major)
        return False
    return True


def _device() -> int:
    """The process's Embree device (made once; lives as long as the process). A process
    forked from one that had a device makes its own: the parent's thread pool is not
    there."""
    pid = os.getpid()
    with _LOCK:
        if pid not in _DEVICE:
            device = _library().rtcNewDevice(None)
            if not device:
                raise OSError("Embree could not make a device")
            _DEVICE.clear()
            _DEVICE[pid] = int(device)
        return _DEVICE[pid]


class PacketScene:
    """An Embree scene of one triangle mesh, for the compiled packet loops.

    Parameters
    ----------
    positions : (V, 3) float
        Vertex positions in the frame the rays use [m]; stored as float32, as embreex
        stores them.
    triangles : (T, 3) int
    robust : bool
        Embree's robust traversal (``RTC_SCENE_FLAG_ROBUST``).

    Attributes
    ----------
    pointer : int
        The ``RTCScene`` handle, passed to the compiled loops; released when this object
        is collected (never while a query may still hold it).

    Raises
    ------
    OSError
        Embree reported an error while building (then nothing is kept).
    """

    def __init__(self, positions: np.ndarray, triangles: np.ndarray, robust: bool = False):
        lib = _library()
        device = _device()
        vertices = np.ascontiguousarray(positions, dtype=np.float32)
        indices = np.ascontiguousarray(triangles, dtype=np.uint32)
        scene = lib.rtcNewScene(device)
        if not scene:
            raise OSError(f"Embree could not make a scene (error {lib.rtcGetDeviceError(device)})")
        self.pointer = int(scene)
        self._release = weakref.finalize(self, lib.rtcReleaseScene, scene)
        lib.rtcSetSceneFlags(scene, _SCENE_FLAG_ROBUST if robust else 0)
        geometry = lib.rtcNewGeometry(device, _GEOMETRY_TRIANGLE)
        for kind, form, data in (
            (_BUFFER_VERTEX, _FORMAT_FLOAT3, vertices),
            (_BUFFER_INDEX, _FORMAT_UINT3, indices),
        ):
            buffer = lib.rtcSetNewGeometryBuffer(geometry, kind, 0, form, 12, len(data))
            if buffer and data.nbytes:
                ctypes.memmove(buffer, data.ctypes.data, data.nbytes)
        lib.rtcCommitGeometry(geometry)
        lib.rtcAttachGeometry(scene, geometry)
        lib.rtcReleaseGeometry(geometry)
        lib.rtcCommitScene(scene)
        error = lib.rtcGetDeviceError(device)
        if error != _NO_ERROR:
            self._release()
            raise OSError(f"Embree failed to build the scene (error {error})")
