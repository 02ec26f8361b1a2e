"""Embree 4 through ctypes, from the shared library the ``embreex`` wheel ships.

We only need what the tracer uses: a device, triangle geometries grouped in one scene per
prototype mesh, instances of those scenes in a top-level scene, and the addresses of
``rtcIntersect1`` / ``rtcOccluded1`` so numba code can call them (``call3``) with a filter
function passed in the query arguments (``RTCIntersectArguments`` / ``RTCOccludedArguments``).

Structure layouts (Embree 4 headers, RTC_MAX_INSTANCE_LEVEL_COUNT = 1, the wheel's build):

* ``RTCRayHit``, 16-byte aligned: ray = org_x, org_y, org_z, tnear, dir_x, dir_y, dir_z, time,
  tfar (floats), mask, id, flags (uint32) -- 48 bytes; hit = Ng_x, Ng_y, Ng_z, u, v (floats),
  primID, geomID, instID[1] (uint32) and, in builds with instance arrays, instPrimID[1]. We give
  every ray/hit 128 bytes so either build fits (``RAYHIT_WORDS``).
* ``RTCIntersectArguments`` / ``RTCOccludedArguments``: flags (uint32), feature_mask (uint32),
  context pointer, filter pointer, intersect/occluded pointer (user geometry, unused): 32 bytes;
  we pass 64 zero-padded bytes.
* ``RTCRayQueryContext``: instID[1] (and instPrimID[1]): at most 8 bytes. The tracer's context is
  a larger block whose first ``CONTEXT_BYTES`` belong to Embree; a filter reads our data after it.
* ``RTCFilterFunctionNArguments``: int* valid, void* geometryUserPtr, context*, RTCRayN* ray,
  RTCHitN* hit, unsigned N. Rays and hits are structures of arrays: field f of ray i is word
  f * N + i (tfar: f = 8; hit u: 3, v: 4, primID: 5, geomID: 6, instID: 7).

Vertex and index data are copied into buffers Embree allocates (``rtcSetNewGeometryBuffer``),
which carry the padding Embree reads past the last vertex; the filter's machine code and the
tracer's tables are kept alive by the objects that use them.
"""

from __future__ import annotations

import ctypes
import glob
import importlib.util
import os

import numpy as np
from llvmlite import ir
from numba import types
from numba.core.extending import intrinsic

from ..errors import InputError

MIN_VERSION = 40300  # 4.3: RTCRayQueryContext and the argument-structure API we use
MAX_VERSION = 50000

RTC_DEVICE_PROPERTY_VERSION = 0
RTC_DEVICE_PROPERTY_BACKFACE_CULLING_ENABLED = 65
RTC_DEVICE_PROPERTY_FILTER_FUNCTION_SUPPORTED = 66
RTC_DEVICE_PROPERTY_TRIANGLE_GEOMETRY_SUPPORTED = 96
RTC_GEOMETRY_TYPE_TRIANGLE = 0
RTC_GEOMETRY_TYPE_INSTANCE = 121
RTC_BUFFER_TYPE_INDEX = 0
RTC_BUFFER_TYPE_VERTEX = 1
RTC_FORMAT_UINT3 = 0x5003
RTC_FORMAT_FLOAT3 = 0x9003
RTC_FORMAT_FLOAT3X4_COLUMN_MAJOR = 0x9234
RTC_SCENE_FLAG_FILTER_FUNCTION_IN_ARGUMENTS = 1 << 3
RTC_BUILD_QUALITY_MEDIUM = 1
RTC_FEATURE_FLAG_ALL = 0xFFFFFFFF
RTC_INVALID_GEOMETRY_ID = 0xFFFFFFFF

RAYHIT_WORDS = 32  # 128 bytes per ray/hit record
CONTEXT_BYTES = 64  # room for Embree's RTCRayQueryContext at the start of a query context
ARGS_WORDS = 8  # 64 bytes of query arguments (int64 words)

# words of an RTCRayHit record (uint32/float32 view)
W_ORG, W_TNEAR, W_DIR, W_TIME, W_TFAR, W_MASK, W_ID, W_FLAGS = 0, 3, 4, 7, 8, 9, 10, 11
W_NG, W_U, W_V, W_PRIM, W_GEOM, W_INST = 12, 15, 16, 17, 18, 19

GEOM_OPAQUE = 0  # geometry ids inside a prototype scene
GEOM_ALPHA = 1


def library_path() -> str:
    """The Embree 4 shared library of the installed ``embreex`` wheel (or $OMAPS_EMBREE_LIB)."""
    env = os.environ.get("OMAPS_EMBREE_LIB")
    if env:
        if not os.path.isfile(env):
            raise InputError("OMAPS_EMBREE_LIB does not name a file", env)
        return env
    spec = importlib.util.find_spec("embreex")
    if spec is None or not spec.submodule_search_locations:
        raise InputError("the embreex package is not installed (pip install 'embreex>=4.4,<5')")
    pkg = list(spec.submodule_search_locations)[0]
    site = os.path.dirname(pkg)
    patterns = [os.path.join(site, "embreex.libs", "libembree4*"), os.path.join(pkg, ".dylibs", "libembree4*"),
                os.path.join(site, "embreex.libs", "embree4*.dll"), os.path.join(pkg, "libembree4*")]
    for pat in patterns:
        found = sorted(glob.glob(pat))
        if found:
            return found[0]
    raise InputError("no Embree 4 library found in the embreex installation", site)


class _Lib:
    """The loaded library with argument types set (one per process)."""

    def __init__(self, path: str):
        lib = ctypes.CDLL(path)
        vp, u32, sz = ctypes.c_void_p, ctypes.c_uint32, ctypes.c_size_t
        sig = {
            "rtcNewDevice": (vp, [ctypes.c_char_p]),
            "rtcGetDeviceProperty": (ctypes.c_ssize_t, [vp, ctypes.c_int]),
            "rtcGetDeviceError": (ctypes.c_int, [vp]),
            "rtcReleaseDevice": (None, [vp]),
            "rtcNewScene": (vp, [vp]),
            "rtcSetSceneFlags": (None, [vp, ctypes.c_int]),
            "rtcSetSceneBuildQuality": (None, [vp, ctypes.c_int]),
            "rtcCommitScene": (None, [vp]),
            "rtcReleaseScene": (None, [vp]),
            "rtcNewGeometry": (vp, [vp, ctypes.c_int]),
            "rtcSetNewGeometryBuffer": (vp, [vp, ctypes.c_int, u32, ctypes.c_int, sz, sz]),
            "rtcSetGeometryEnableFilterFunctionFromArguments": (None, [vp, ctypes.c_bool]),
            "rtcSetGeometryInstancedScene": (None, [vp, vp]),
            "rtcSetGeometryTransform": (None, [vp, u32, ctypes.c_int, vp]),
            "rtcCommitGeometry": (None, [vp]),
            "rtcAttachGeometryByID": (None, [vp, vp, u32]),
            "rtcReleaseGeometry": (None, [vp]),
        }
        for name, (res, args) in sig.items():
            f = getattr(lib, name)
            f.restype = res
            f.argtypes = args
        self.lib = lib
        self.path = path
        self.intersect1 = ctypes.cast(lib.rtcIntersect1, ctypes.c_void_p).value
        self.occluded1 = ctypes.cast(lib.rtcOccluded1, ctypes.c_void_p).value


_LIB: _Lib | None = None


def lib() -> _Lib:
    global _LIB
    if _LIB is None:
        _LIB = _Lib(library_path())
    return _LIB


class Device:
    """An Embree device, checked at start-up: version in [4.3, 5), filter functions supported,
    triangles supported, back-face culling off (the scenes' alpha cards are double-sided)."""

    def __init__(self, config: str = ""):
        self.l = lib()
        L = self.l.lib
        self.handle = L.rtcNewDevice(config.encode() if config else None)
        if not self.handle:
            raise RuntimeError(f"rtcNewDevice failed ({self.l.path})")
        self.version = int(L.rtcGetDeviceProperty(self.handle, RTC_DEVICE_PROPERTY_VERSION))
        if not MIN_VERSION <= self.version < MAX_VERSION:
            raise RuntimeError(f"Embree {self.version_text} at {self.l.path}: need >= 4.3 and < 5")
        needs = {RTC_DEVICE_PROPERTY_FILTER_FUNCTION_SUPPORTED: "filter functions",
                 RTC_DEVICE_PROPERTY_TRIANGLE_GEOMETRY_SUPPORTED: "triangle geometry"}
        for prop, what in needs.items():
            if L.rtcGetDeviceProperty(self.handle, prop) != 1:
                raise RuntimeError(f"Embree at {self.l.path} was built without {what}")
        if L.rtcGetDeviceProperty(self.handle, RTC_DEVICE_PROPERTY_BACKFACE_CULLING_ENABLED):
            raise RuntimeError(f"Embree at {self.l.path} culls back faces; double-sided cards need it off")

    @property
    def version_text(self) -> str:
        v = self.version
        return f"{v // 10000}.{v // 100 % 100}.{v % 100}"

    def check(self, what: str) -> None:
        err = self.l.lib.rtcGetDeviceError(self.handle)
        if err:
            raise RuntimeError(f"Embree error {err} in {what}")

    def __del__(self):
        if getattr(self, "handle", None):
            self.l.lib.rtcReleaseDevice(self.handle)
            self.handle = None


class InstancedScene:
    """Prototype scenes (geometry 0: opaque triangles, 1: alpha-tested triangles, whose filter
    comes from the query arguments) instanced by a top-level scene (instance i = geometry i).
    A hit's instID is the instance, its geomID says opaque or alpha, its primID indexes the
    triangles of that geometry in the order given."""

    def __init__(self, device: Device, prototypes, instances, quality: int = RTC_BUILD_QUALITY_MEDIUM):
        """prototypes: list of (positions (V, 3), opaque triangles (To, 3), alpha triangles
        (Ta, 3)); instances: list of (prototype index, 4x4 transform)."""
        self.device = device
        L = device.l.lib
        self.protos = []
        for pos, opaque, alpha in prototypes:
            sc = L.rtcNewScene(device.handle)
            L.rtcSetSceneFlags(sc, RTC_SCENE_FLAG_FILTER_FUNCTION_IN_ARGUMENTS)
            L.rtcSetSceneBuildQuality(sc, quality)
            for gid, tris in ((GEOM_OPAQUE, opaque), (GEOM_ALPHA, alpha)):
                if len(tris):
                    self._triangles(sc, gid, pos, tris, filtered=gid == GEOM_ALPHA)
            L.rtcCommitScene(sc)
            device.check("prototype scene commit")
            self.protos.append(sc)
        self.top = L.rtcNewScene(device.handle)
        L.rtcSetSceneFlags(self.top, RTC_SCENE_FLAG_FILTER_FUNCTION_IN_ARGUMENTS)
        L.rtcSetSceneBuildQuality(self.top, quality)
        for i, (p, m) in enumerate(instances):
            g = L.rtcNewGeometry(device.handle, RTC_GEOMETRY_TYPE_INSTANCE)
            L.rtcSetGeometryInstancedScene(g, self.protos[p])
            xf = np.ascontiguousarray(np.asarray(m, dtype=np.float64)[:3, :4].T, dtype=np.float32)  # 3x4 col-major
            L.rtcSetGeometryTransform(g, 0, RTC_FORMAT_FLOAT3X4_COLUMN_MAJOR, xf.ctypes.data)
            L.rtcCommitGeometry(g)
            L.rtcAttachGeometryByID(self.top, g, i)
            L.rtcReleaseGeometry(g)
        L.rtcCommitScene(self.top)
        device.check("top-level scene commit")

    def _triangles(self, scene, gid, positions, tris, filtered):
        L = self.device.l.lib
        g = L.rtcNewGeometry(self.device.handle, RTC_GEOMETRY_TYPE_TRIANGLE)
        pos = np.ascontiguousarray(positions, dtype=np.float32)
        idx = np.ascontiguousarray(tris, dtype=np.uint32)
        vb = L.rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 12, len(pos))
        ib = L.rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 12, len(idx))
        if not vb or not ib:
            raise RuntimeError("Embree could not allocate a geometry buffer")
        ctypes.memmove(vb, pos.ctypes.data, pos.nbytes)
        ctypes.memmove(ib, idx.ctypes.data, idx.nbytes)
        if filtered:
            L.rtcSetGeometryEnableFilterFunctionFromArguments(g, True)
        L.rtcCommitGeometry(g)
        L.rtcAttachGeometryByID(scene, g, gid)
        L.rtcReleaseGeometry(g)

    @property
    def handle(self) -> int:
        return int(self.top)

    def __del__(self):
        L = self.device.l.lib
        if getattr(self, "top", None):
            L.rtcReleaseScene(self.top)
            self.top = None
        for sc in getattr(self, "protos", []):
            L.rtcReleaseScene(sc)
        self.protos = []


# --------------------------------------------------------------------------------------------
# numba helpers: raw pointers and calls through addresses

def _ptr_intrinsic(elem):
    @intrinsic
    def as_ptr(typingctx, addr):
        sig = types.CPointer(elem)(types.int64)

        def codegen(context, builder, signature, args):
            return builder.inttoptr(args[0], context.get_value_type(types.CPointer(elem)))
        return sig, codegen
    return as_ptr


i64_ptr = _ptr_intrinsic(types.int64)
i32_ptr = _ptr_intrinsic(types.int32)
u32_ptr = _ptr_intrinsic(types.uint32)
f32_ptr = _ptr_intrinsic(types.float32)
f64_ptr = _ptr_intrinsic(types.float64)
u8_ptr = _ptr_intrinsic(types.uint8)
i8_ptr = _ptr_intrinsic(types.int8)
u16_ptr = _ptr_intrinsic(types.uint16)


@intrinsic
def call3(typingctx, fn, a, b, c):
    """Call the C function at address ``fn`` as void f(void*, void*, void*) with three
    addresses (rtcIntersect1 / rtcOccluded1: scene, ray, arguments)."""
    sig = types.void(types.int64, types.int64, types.int64, types.int64)

    def codegen(context, builder, signature, args):
        i8p = ir.IntType(8).as_pointer()
        fnty = ir.FunctionType(ir.VoidType(), [i8p, i8p, i8p])
        f = builder.inttoptr(args[0], fnty.as_pointer())
        builder.call(f, [builder.inttoptr(x, i8p) for x in args[1:]])
        return context.get_dummy_value()
    return sig, codegen
