"""Reading OpenUSD stages (.usd, .usda, .usdc, .usdz) into the scene model: the only module that
imports ``pxr`` (usd-core, the optional extra ``omaps[usd]``), and only when a stage is read.

The rules mirror the glTF reader's (``scene.gltf``) wherever the formats say the same thing:

* without usd-core, a stage is an ``InputError`` naming the file and ``pip install 'omaps[usd]'``;
  a stage USD cannot open (a malformed .usda, a broken crate file) an ``InputError`` naming it;
* every layer the stage composes (sublayers, references, payloads) and every texture file is
  resolved by the stage's resolver and then held to the glTF URIs' policy
  (``container.AssetPolicy``): under the stage's folder or ``root`` (files inside a .usdz under
  it), never a URI with a scheme (omaps never fetches), each file at most ``max_bytes``. A layer
  refused or missing is an ``InputError`` before it is opened; a texture file refused is an
  ``InputError`` too (with ``allow_outside``, a scheme URI is a warning and the image missing);
* the stage is read at its first time sample (the default value where there is none);
  ``metersPerUnit`` scales it to metres and a Z-up stage is turned Y-up ((x, y, z) to
  (x, z, -y)), the axes of the scene model (glTF's); cameras turn with it;
* a ``UsdGeomMesh`` (prims not active, ``invisible``, or of purpose guide or proxy are left out,
  with what they hold) is a mesh: each polygon a fan (v0, vk, vk+1) as glTF's fans, faces of
  fewer than 3 vertices and ``holeIndices`` left out, ``orientation = leftHanded`` flipping each
  triangle's winding, a subdivision surface read as its control cage. Its faces bound to one
  material (``MaterialBindingAPI.ComputeBoundMaterial``, full purpose, per ``GeomSubset`` of the
  materialBind family) are one primitive; each primitive keeps its prim path (``source``) and
  each triangle its face (``faces``): an engine attaches a baked micromap by them. Other gprims
  (cubes, spheres, curves, points) are left out and listed in ``Scene.skipped``;
* texture coordinates are the primvar the texture's ``UsdPrimvarReader_float2`` names
  (``varname``, through connections), of any interpolation, indexed or not: vertex and varying
  ones keep the mesh's points, faceVarying and uniform ones give each face corner a vertex of its
  own, constant ones one value. ``UsdTransform2d`` between reader and texture (scale, rotation
  in degrees counter-clockwise, translation) is applied, then t turned to glTF's v (1 - t, the
  image's first row at the top). A primvar that is missing, NaN, infinite or huge: as glTF's
  TEXCOORD rules (a warning; those triangles unknown, at UV (0, 0));
* ``UsdPreviewSurface``: ``opacityThreshold`` > 0 is alpha-tested at that threshold (glTF's MASK
  with that cutoff); = 0 with an opacity below 1 or from a texture is blended (glTF's BLEND); no
  opacity connection and opacity 1 is opaque. Opacity is a constant ``inputs:opacity`` or one
  channel (r, g, b or a) of a ``UsdUVTexture``: its image decoded by Pillow as glTF images are,
  ``inputs:scale`` of that channel a factor (as glTF's base colour factor), a non-zero
  ``inputs:bias`` refused (an ``InputError`` naming the shader). ``wrapS`` / ``wrapT``: repeat,
  clamp, mirror; black (and ``useMetadata``, which is black for the images Pillow reads) is
  the image with a border of alpha 0 sampled clamped, its coordinates moved into it. Filtering
  is linear. A surface that is not a ``UsdPreviewSurface``, or an opacity fed by another node,
  is a warning: the material's maps are unknown (all C) and the tracer's shader sees alpha 1,
  as for an image that cannot be read (missing, undecodable: the same warning as glTF's);
* instanceable prims: the meshes of a prototype are read once (one mesh per prototype mesh and
  material binding) with an instance per placement; a ``UsdGeomPointInstancer``'s prototypes
  likewise, placed by ``ComputeInstanceTransformsAtTime`` (positions, orientations, scales,
  protoIndices, its mask), and never drawn by themselves;
* a ``UsdGeomCamera`` is a ``SceneCamera`` (in stage traversal order): perspective vertical field
  of view from its apertures and focal length, looking down its -Z with +Y up, as glTF's;
* ``doubleSided`` is kept with the material (``Material.double_sided``).
"""

from __future__ import annotations

import io
import math
import os
import warnings
import zipfile

import numpy as np

from ..errors import InputError
from .container import MAX_BYTES_ENV, URI_SCHEME, AssetPolicy, inside_root, max_asset_bytes
from .files import USD_SUFFIXES, is_usd_file
from .gltf import MAX_TEXEL_COORDINATE
from .model import Material, Mesh, Primitive, Scene, SceneCamera, SceneWarning, Texture, own_vertices

__all__ = ["load_scene", "INSTALL_HINT"]

INSTALL_HINT = "pip install 'omaps[usd]'"
UNCHECKED = "malformed USD"
_WRAPS = {"repeat": "wrap", "clamp": "clamp", "mirror": "mirror", "black": "black", "useMetadata": "black"}
_CHANNELS = {"r": 0, "g": 1, "b": 2, "a": 3}


def _pxr(path: str):
    """usd-core's modules, or the InputError that says how to install them."""
    try:
        from pxr import Ar, Gf, Sdf, Tf, Usd, UsdGeom, UsdShade
    except ImportError:
        raise InputError(f"is an OpenUSD stage: reading it needs usd-core ({INSTALL_HINT})", path) from None
    return Ar, Gf, Sdf, Tf, Usd, UsdGeom, UsdShade


def _tf_message(exc) -> str:
    """The first problem a ``Tf.ErrorException`` reports (its errors' commentary), without USD's
    source locations."""
    notes = []
    for a in exc.args:
        try:
            notes.append(str(getattr(a, "commentary", "") or "").strip())
        except (UnicodeDecodeError, ValueError):  # (a message quoting the file's bytes)
            notes.append("a message that is not UTF-8")
    first = next((n for n in notes if n), "") or type(exc).__name__
    first = " ".join(first.split())
    return first if len(first) <= 300 else first[:300] + "..."


def load_scene(path, *, root=None, allow_outside: bool = False, max_bytes: int | None = None) -> Scene:
    """Load a .usd, .usda, .usdc or .usdz stage into the scene model (``omaps.scene.model``);
    the keywords are ``omaps.scene.load_scene``'s (the module docstring lists the rules).

    Raises
    ------
    InputError
        Naming the file; recoverable problems are ``SceneWarning``s (also in ``Scene.warnings``).
    """
    from ..checks import path as checked_path

    path = checked_path(path, "path")
    if not is_usd_file(path):
        raise InputError(f"not an OpenUSD stage: it must end in {', '.join(USD_SUFFIXES)}", path)
    if not os.path.exists(path):
        raise InputError("no such file", path)
    if os.path.isdir(path):
        raise InputError("is a folder, not a USD stage", path)
    pxr = _pxr(path)
    policy = AssetPolicy.of(root, allow_outside, max_bytes)
    reader = _Reader(path, policy, pxr)
    try:
        return reader.scene()
    except InputError:
        raise
    except pxr[3].ErrorException as exc:
        raise InputError(f"cannot read USD ({_tf_message(exc)})", path) from None
    except (IndexError, TypeError, KeyError, ValueError, AttributeError, RuntimeError, OverflowError,
            ZeroDivisionError) as exc:  # a case no check names
        raise InputError(f"{UNCHECKED} ({type(exc).__name__}: {exc})", path) from None


class _Reader:
    def __init__(self, path: str, policy: AssetPolicy, pxr):
        self.Ar, self.Gf, self.Sdf, self.Tf, self.Usd, self.UsdGeom, self.UsdShade = pxr
        self.path = path
        self.policy = policy
        self.max_bytes = max_asset_bytes(policy.max_bytes)
        folder = os.path.dirname(os.path.abspath(path))
        self.root = os.path.realpath(policy.root if policy.root is not None else folder)
        self.root_label = "the {root} folder" if policy.root is not None else "the stage's folder"
        self.warnings: list[str] = []
        self.skipped: list[dict] = []
        self.materials: list[Material] = []
        self.textures: list[Texture] = []
        self._material_keys: dict = {}
        self._looks: dict = {}
        self._texture_keys: dict = {}
        self._mesh_keys: dict = {}
        self._prim_mesh: dict = {}
        self._uv: dict = {}  # per model material: its look (``look``: primvar, st transform, border)
        self.meshes: list[Mesh] = []
        self.instances: list[tuple[int, np.ndarray]] = []

    def warn(self, message: str) -> None:
        if message in self.warnings:
            return
        self.warnings.append(message)
        warnings.warn(f"{self.path}: {message}", SceneWarning, stacklevel=3)

    # -- files: the policy of glTF URIs ------------------------------------------------------
    def _outer(self, resolved: str) -> str:
        """A resolved path's file on disk: the outermost package of a package-relative path."""
        while resolved.endswith("]") and "[" in resolved:
            resolved = self.Ar.SplitPackageRelativePathOuter(resolved)[0]
        return resolved

    def _scheme(self, authored: str) -> str | None:
        m = URI_SCHEME.match(authored)
        if m and len(m.group(1)) > 1 and m.group(1).lower() != "file":  # (a one-letter scheme: a drive)
            return m.group(1).lower()
        return None

    def _allowed(self, authored: str, resolved: str, what: str) -> str:
        """The real path of the file a resolved asset path leads to (its package for a path
        inside a .usdz), under the policy; an ``InputError`` naming ``what`` when it is refused."""
        real = os.path.realpath(self._outer(resolved))
        if not self.policy.allow_outside and not inside_root(real, self.root):
            raise InputError(f"{what}: asset path {authored!r} leads to {real}, outside {self.root} "
                             f"({self.root_label}): omaps reads only files under it ({{root}}: a folder holding "
                             "both; {allow_outside}: if you trust this stage)", self.path,
                             param=("root", "allow_outside"))
        return real

    def _size(self, real: str, what: str) -> None:
        try:
            size = os.path.getsize(real)
        except OSError:
            return
        if size > self.max_bytes:
            raise InputError(f"{what}: file {real} holds {size} bytes, over the size cap of {self.max_bytes} "
                             f"({MAX_BYTES_ENV})", self.path)

    def check_layers(self):
        """Open the root layer and every layer it composes, depth first, each checked under the
        policy before it is opened; returns the root layer."""
        Sdf = self.Sdf
        self._size(self.path, "the stage")
        root = Sdf.Layer.FindOrOpen(self.path)
        if root is None:
            raise InputError("cannot read USD (not a layer USD can open)", self.path)
        seen, todo = {root.identifier}, [root]
        while todo:
            layer = todo.pop()
            for dep in sorted(d for d in layer.GetCompositionAssetDependencies() if d):  # ('': an internal one)
                what = f"layer {dep!r} (named by {os.path.basename(layer.realPath or layer.identifier)})"
                scheme = self._scheme(dep)
                if scheme:
                    raise InputError(f"{what} is a {scheme}: URI; omaps never fetches URIs (no network access)",
                                     self.path)
                resolved = str(self.Ar.GetResolver().Resolve(layer.ComputeAbsolutePath(dep)))
                if not resolved:
                    raise InputError(f"{what} is missing", self.path)
                self._allowed(dep, resolved, what)
                self._size(self._outer(resolved), what)
                sub = Sdf.Layer.FindOrOpen(resolved)
                if sub is None:
                    raise InputError(f"{what} cannot be opened", self.path)
                if sub.identifier not in seen:
                    seen.add(sub.identifier)
                    todo.append(sub)
        return root

    def file_bytes(self, authored: str, resolved: str, what: str):
        """The bytes of a texture file (None: missing or unreadable, the problem said); an
        ``InputError`` when the policy refuses it."""
        scheme = self._scheme(authored)
        if scheme:
            problem = (f"{what}: asset path {authored!r} is a {scheme}: URI; omaps never fetches URIs (no network "
                       "access)")
            if not self.policy.allow_outside:
                raise InputError(problem + " ({allow_outside}: go on without it)", self.path, param="allow_outside")
            return None, problem + "; it is not read"
        if not resolved:
            return None, f"image file {authored!r} is missing"
        real = self._allowed(authored, resolved, what)
        self._size(real, what)
        try:
            if resolved.endswith("]") and "[" in resolved:  # a file inside a .usdz (a zip, stored)
                return self._packaged(resolved, what), None
            with open(real, "rb") as f:
                return f.read(), None
        except (OSError, KeyError, zipfile.BadZipFile, ValueError):
            return None, f"image file {authored!r} is missing or unreadable"

    def _packaged(self, resolved: str, what: str) -> bytes:
        outer, inner = self.Ar.SplitPackageRelativePathInner(resolved)  # (a package inside a package: outer's)
        source = io.BytesIO(self._packaged(outer, what)) if outer.endswith("]") else os.path.realpath(outer)
        with zipfile.ZipFile(source) as z:
            info = z.getinfo(inner)
            if info.file_size > self.max_bytes:
                raise InputError(f"{what}: {inner} holds {info.file_size} bytes, over the size cap of "
                                 f"{self.max_bytes} ({MAX_BYTES_ENV})", self.path)
            return z.read(inner)

    # -- the stage ----------------------------------------------------------------------------
    def scene(self) -> Scene:
        Usd, UsdGeom = self.Usd, self.UsdGeom
        self.check_layers()
        stage = Usd.Stage.Open(self.path, Usd.Stage.LoadAll)
        if stage is None:
            raise InputError("cannot read USD (the stage cannot be opened)", self.path)
        self.stage = stage
        self.time = Usd.TimeCode.EarliestTime()
        self.xf = UsdGeom.XformCache(self.time)
        mpu = float(UsdGeom.GetStageMetersPerUnit(stage))
        if not (math.isfinite(mpu) and mpu > 0):
            raise InputError(f"metersPerUnit is {mpu}, not a positive number", self.path)
        axis = str(UsdGeom.GetStageUpAxis(stage))
        self.to_model = np.eye(4) * mpu
        self.to_model[3, 3] = 1.0
        if axis == "Z":  # (x, y, z) -> (x, z, -y): Y up
            self.to_model = self.to_model @ np.array([[1.0, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0], [0, 0, 0, 1]])
        self.cameras: list[SceneCamera] = []
        for prim, world in self.collect(stage.GetPseudoRoot(), None):
            self.mesh_instance(prim, world)
        return Scene(self.path, self.meshes, self.instances, self.materials, self.textures, self.warnings,
                     self.skipped, self.cameras, None)

    def _matrix(self, gf) -> np.ndarray:
        """A Gf matrix (row vectors) as the model's column-vector 4x4."""
        m = np.array(gf, dtype=np.float64).reshape(4, 4).T
        if not np.all(np.isfinite(m)):
            raise InputError("a transform holds a NaN or an infinity", self.path)
        return m

    def _relative(self, prim, anchor) -> np.ndarray:
        """``prim``'s transform to world (``anchor`` None) or to ``anchor``'s space (a prototype
        root: its own transform is the instancer's to apply)."""
        if anchor is None:
            return self._matrix(self.xf.GetLocalToWorldTransform(prim))
        if prim == anchor:
            return np.eye(4)
        return self._matrix(self.xf.ComputeRelativeTransform(prim, anchor)[0])

    def collect(self, start, anchor, depth: int = 0) -> list:
        """(mesh prim, its transform relative to ``anchor``, None: the world) of every mesh drawn
        under ``start`` (inclusive), point instancers' prototypes once per placement; cameras
        are read on the stage's own walk (``anchor`` None)."""
        Usd, UsdGeom = self.Usd, self.UsdGeom
        out = []
        it = iter(Usd.PrimRange(start, Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)))
        for prim in it:
            if prim.IsPseudoRoot():
                continue
            if prim.IsA(UsdGeom.Imageable):
                img = UsdGeom.Imageable(prim)
                vis = img.GetVisibilityAttr().Get(self.time)
                purpose = img.GetPurposeAttr().Get(self.time)
                if vis == UsdGeom.Tokens.invisible or purpose in (UsdGeom.Tokens.guide, UsdGeom.Tokens.proxy):
                    it.PruneChildren()
                    continue
            if prim.IsA(UsdGeom.PointInstancer):
                it.PruneChildren()
                out += self.point_instancer(prim, anchor, depth)
            elif prim.IsA(UsdGeom.Mesh):
                out.append((prim, self._relative(prim, anchor)))
            elif prim.IsA(UsdGeom.Gprim):
                self.skipped.append({"mesh": -1, "primitive": -1, "name": str(prim.GetPath()),
                                     "reason": f"a {prim.GetTypeName()}, not a Mesh"})
            elif anchor is None and prim.IsA(UsdGeom.Camera):
                self.camera(prim)
        return out

    def point_instancer(self, prim, anchor, depth: int) -> list:
        """The meshes of a point instancer's prototypes, once per placement, in instance order."""
        UsdGeom = self.UsdGeom
        pi = UsdGeom.PointInstancer(prim)
        what = f"point instancer {prim.GetPath()}"
        if depth >= 8:
            raise InputError(f"{what}: point instancers nest more than 8 deep", self.path)
        protos = pi.GetPrototypesRel().GetForwardedTargets()
        indices = pi.GetProtoIndicesAttr().Get(self.time)
        indices = np.zeros(0, np.int64) if indices is None else np.asarray(indices, np.int64)
        if indices.size and (indices.min() < 0 or indices.max() >= len(protos)):
            bad = int(indices.max() if indices.max() >= len(protos) else indices.min())
            raise InputError(f"{what}: protoIndices name prototype {bad} of {len(protos)}", self.path)
        xforms = pi.ComputeInstanceTransformsAtTime(self.time, self.time)
        mask = pi.ComputeMaskAtTime(self.time)
        keep = np.ones(len(indices), bool) if not mask else np.asarray(mask, bool)
        if len(xforms) != int(keep.sum()) or len(keep) != len(indices):
            raise InputError(f"{what}: its positions, orientations and scales do not give one transform per "
                             f"protoIndices element ({len(xforms)} for {len(indices)})", self.path)
        indices = indices[keep]
        here = self._relative(prim, anchor)
        parts = {}
        for k in np.unique(indices):
            root = self.stage.GetPrimAtPath(protos[k])
            if not root or not root.IsValid():
                raise InputError(f"{what}: prototype {protos[k]} does not exist", self.path)
            parts[int(k)] = self.collect(root, root, depth + 1)
        out = []
        for k, m in zip(indices, xforms):
            placed = here @ self._matrix(m)
            out += [(mesh, placed @ rel) for mesh, rel in parts[int(k)]]
        return out

    def mesh_instance(self, prim, world: np.ndarray) -> None:
        """An instance of the mesh prim: its prototype's mesh when it is an instance proxy (one
        mesh per prototype mesh and material binding)."""
        path = str(prim.GetPath())
        if path not in self._prim_mesh:
            shared = prim.GetPrimInPrototype() if prim.IsInstanceProxy() else prim
            groups = self.bindings(prim)
            key = (str(shared.GetPath()), tuple((m, None if f is None else tuple(f)) for m, f in groups))
            if key not in self._mesh_keys:
                self._mesh_keys[key] = len(self.meshes)
                self.meshes.append(self.mesh(prim, len(self.meshes), groups))
            self._prim_mesh[path] = self._mesh_keys[key]
        self.instances.append((self._prim_mesh[path], self.to_model @ world))

    # -- materials -----------------------------------------------------------------------------
    def bindings(self, prim) -> list[tuple[int, np.ndarray | None]]:
        """(model material, its faces: None for every face not in a subset) per material bound."""
        UsdShade, UsdGeom = self.UsdShade, self.UsdGeom
        api = UsdShade.MaterialBindingAPI(prim)
        double = bool(UsdGeom.Mesh(prim).GetDoubleSidedAttr().Get(self.time))
        out = []
        for subset in api.GetMaterialBindSubsets():
            faces = subset.GetIndicesAttr().Get(self.time)
            faces = np.zeros(0, np.int64) if faces is None else np.asarray(faces, np.int64)
            mat = UsdShade.MaterialBindingAPI(subset.GetPrim()).ComputeBoundMaterial(UsdShade.Tokens.full)[0]
            out.append((self.material(mat, double), faces))
        mat = api.ComputeBoundMaterial(UsdShade.Tokens.full)[0]
        out.append((self.material(mat, double), None))
        return out

    def material(self, mat, double: bool) -> int:
        if not mat:
            return self._plain(double)
        path = str(mat.GetPath())
        key = (path, double)
        if key not in self._material_keys:
            look = self.look(mat)
            self._material_keys[key] = len(self.materials)
            self.materials.append(Material(len(self.materials), look["name"], look["mode"], look["cutoff"],
                                           (1.0, 1.0, 1.0, look["factor"]), look["texture"], "linear", look["wrap"][0],
                                           look["wrap"][1], 0, double))
            self._uv[len(self.materials) - 1] = look
        return self._material_keys[key]

    def _plain(self, double: bool) -> int:
        key = ("plain", double)
        if key not in self._material_keys:
            self._material_keys[key] = len(self.materials)
            self.materials.append(Material(len(self.materials), "default", "OPAQUE", 0.5, (1, 1, 1, 1), -1, "linear",
                                           "wrap", "wrap", 0, double))
        return self._material_keys[key]

    def _produced(self, inp):
        """What feeds a shader input: ("output", shader prim, output name), ("value", value) or
        None (nothing authored)."""
        UsdShade = self.UsdShade
        if not inp:
            return None
        attrs = inp.GetValueProducingAttributes(False)
        if attrs:
            a = attrs[0]
            if UsdShade.Output.IsOutput(a):
                return ("output", a.GetPrim(), UsdShade.Output(a).GetBaseName())
            return ("value", a.Get(self.time))
        return None

    def _value(self, shader, name, default):
        got = self._produced(shader.GetInput(name))
        if got is None or got[0] != "value" or got[1] is None:
            return default
        return got[1]

    def _number(self, value, what: str) -> float:
        try:
            x = float(value)
        except (TypeError, ValueError):
            raise InputError(f"{what} is {value!r}, not a number", self.path) from None
        if not math.isfinite(x):
            raise InputError(f"{what} is {x}, not a finite number", self.path)
        return x

    def look(self, mat) -> dict:
        """What the alpha test needs of a material (its UsdPreviewSurface)."""
        UsdShade = self.UsdShade
        path = str(mat.GetPath())
        look = {"name": path, "mode": "OPAQUE", "cutoff": 0.5, "factor": 1.0, "texture": -1, "wrap": ("wrap", "wrap"),
                "varname": None, "st": np.eye(2, 3), "fallback_st": (0.0, 0.0)}
        shader = mat.ComputeSurfaceSource()[0]
        if not shader:
            others = [o.GetFullName() for o in mat.GetSurfaceOutputs() if o.HasConnectedSource()]
            if others:
                return self._unknown(look, f"material {path} has no universal surface (only {', '.join(others)})",
                                     f"material {path}")
            return look
        sid = shader.GetIdAttr().Get()
        if sid != "UsdPreviewSurface":
            problem = f"material {path}: its surface is {sid or shader.GetPath()}, not a UsdPreviewSurface"
            return self._unknown(look, problem, f"material {path}")
        what = f"material {path}: {shader.GetPath()}"
        threshold = self._number(self._value(shader, "opacityThreshold", 0.0), f"{what}: inputs:opacityThreshold")
        got = self._produced(shader.GetInput("opacity"))
        textured = got is not None and got[0] == "output"
        opacity = 1.0 if textured or got is None or got[1] is None else self._number(got[1], f"{what}: inputs:opacity")
        if threshold > 0:
            look.update(mode="MASK", cutoff=threshold)
        elif textured or opacity < 1:
            look["mode"] = "BLEND"
        look["factor"] = opacity
        if not textured:  # the diffuse colour's texture gives the coordinates (and the pictures' colours)
            diffuse = self._produced(shader.GetInput("diffuseColor"))
            if diffuse is not None and diffuse[0] == "output" and \
                    UsdShade.Shader(diffuse[1]).GetIdAttr().Get() == "UsdUVTexture":
                return self.texture(look, UsdShade.Shader(diffuse[1]), "a", what, opacity=False)
            return look
        tex = UsdShade.Shader(got[1])
        channel = got[2]
        if tex.GetIdAttr().Get() != "UsdUVTexture" or channel not in _CHANNELS:
            return self._unknown(look, f"material {path}: its opacity comes from {got[1].GetPath()}.outputs:{channel}"
                                 ", not from a UsdUVTexture's r, g, b or a", f"material {path}")
        return self.texture(look, tex, channel, what)

    def _unknown(self, look, problem, label) -> dict:
        key = ("unknown", problem)
        if key not in self._texture_keys:
            self._texture_keys[key] = len(self.textures)
            self.textures.append(Texture(label, None, 255, None, problem))
            self.warn(f"{problem}: its maps are unknown (all C) and the tracer's shader sees alpha 1")
        if look["mode"] == "OPAQUE":
            look["mode"] = "BLEND"  # an unread opacity: not known to be opaque
        look["texture"] = self._texture_keys[key]
        return look

    def texture(self, look, tex, channel: str, what: str, opacity: bool = True) -> dict:
        """The texture a material's opacity reads (``opacity`` False: its diffuse colour's, for
        the coordinates and the pictures' colours of an opaque material)."""
        twhat = f"{what}: texture {tex.GetPath()}"
        k = _CHANNELS[channel]
        for name, default in (("scale", (1.0, 1.0, 1.0, 1.0)), ("bias", (0.0, 0.0, 0.0, 0.0)))[:2 if opacity else 0]:
            v = self._value(tex, name, default)
            try:
                v = [float(x) for x in v]
            except TypeError:
                raise InputError(f"{twhat}: inputs:{name} is {v!r}, not four numbers", self.path) from None
            if len(v) != 4 or not all(math.isfinite(x) for x in v):
                raise InputError(f"{twhat}: inputs:{name} is {v!r}, not four finite numbers", self.path)
            if name == "scale":
                if v[k] < 0:
                    raise InputError(f"{twhat}: inputs:scale of channel {channel} is {v[k]}: a negative scale "
                                     "inverts the opacity, which omaps cannot sample", self.path)
                look["factor"] = v[k]
            elif v[k] != 0:
                raise InputError(f"{twhat}: inputs:bias of channel {channel} is {v[k]}: omaps samples opacity as "
                                 "the texture times a factor, with no bias; author bias 0 for it", self.path)
        wraps = []
        for name in ("wrapS", "wrapT"):
            v = str(self._value(tex, name, "useMetadata"))
            if v not in _WRAPS:
                raise InputError(f"{twhat}: inputs:{name} is {v!r}, not repeat, clamp, mirror, black or useMetadata",
                                 self.path)
            wraps.append(_WRAPS[v])
        look["wrap"] = tuple("clamp" if w == "black" else w for w in wraps)
        look["varname"], look["st"], look["fallback_st"] = self.coordinates(tex, twhat)
        asset = self._value(tex, "file", None)
        authored = getattr(asset, "path", "") or ""
        resolved = getattr(asset, "resolvedPath", "") or ""
        if not authored:
            return self._unknown(look, f"{twhat} names no file", twhat)
        pad = (wraps[0] == "black", wraps[1] == "black")
        key = (resolved or authored, channel, pad)
        if key not in self._texture_keys:
            self._texture_keys[key] = len(self.textures)
            t = self.image(authored, resolved, channel, pad, twhat)
            self.textures.append(t)
            if t.problem is not None:
                self.warn(f"{t.problem}: the maps of materials using it are unknown (all C) and the tracer's shader "
                          "sees alpha 1")
        look["texture"] = self._texture_keys[key]
        t = self.textures[look["texture"]]
        look["size"] = t.alpha.shape if t.alpha is not None else None
        look["pad"] = pad
        if t.problem is None and not t.has_alpha and look["mode"] != "OPAQUE":
            self.warn(f"{what}: its opacity is channel a of {t.name!r}, which has no alpha channel: alpha is 1 "
                      "everywhere")
        return look

    def image(self, authored: str, resolved: str, channel: str, pad, what: str) -> Texture:
        from PIL import Image

        from ..texture import open_image

        label = authored
        data, problem = self.file_bytes(authored, resolved, what)
        if data is None:
            return Texture(label, None, 255, None, problem)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("error", Image.DecompressionBombWarning)
                with open_image(io.BytesIO(data), label) as pil:
                    sixteen = pil.mode in ("I;16", "I;16B", "I;16L", "I")
                    t = Texture.from_image(label, pil)
        except InputError as exc:
            if "DecompressionBomb" in exc.problem:
                raise InputError(f"{what}: image {label!r} is over Pillow's decompression-bomb limit of "
                                 f"{Image.MAX_IMAGE_PIXELS} pixels ({exc.problem}): not decoded", self.path) from None
            return Texture(label, None, 255, None, f"image {label!r} cannot be decoded ({exc.problem})")
        alpha, maxval, has_alpha = t.alpha, t.maxval, t.has_alpha
        if channel == "a" and sixteen:  # a one-channel image: its a is 1
            alpha, has_alpha = np.full_like(alpha, maxval), False
        elif channel != "a" and not sixteen:
            alpha, has_alpha = np.ascontiguousarray(t.rgb[..., _CHANNELS[channel]]), True
        elif channel != "a":
            has_alpha = True
        rgb = t.rgb
        if pad[0] or pad[1]:  # black: a border of zeros, sampled clamped
            w = ((1, 1) if pad[1] else (0, 0), (1, 1) if pad[0] else (0, 0))
            alpha = np.pad(alpha, w)
            rgb = np.pad(rgb, w + ((0, 0),)) if rgb is not None else None
        name = label if channel == "a" else f"{label} ({channel})"
        return Texture(name, np.ascontiguousarray(alpha), maxval, rgb, None, has_alpha)

    def coordinates(self, tex, what: str):
        """(primvar name or None, 2x3 st transform, st when no primvar is read) of a texture."""
        got = self._produced(tex.GetInput("st"))
        xf = np.eye(2, 3)
        for _ in range(16):
            if got is None:
                return None, xf, (0.0, 0.0)
            if got[0] == "value":
                v = got[1]
                st = (0.0, 0.0) if v is None else (self._number(v[0], f"{what}: inputs:st"),
                                                   self._number(v[1], f"{what}: inputs:st"))
                return None, xf, st
            node = self.UsdShade.Shader(got[1])
            sid = node.GetIdAttr().Get()
            if sid == "UsdTransform2d":
                xf = _compose(xf, self._transform2d(node, what))
                got = self._produced(node.GetInput("in"))
                continue
            if isinstance(sid, str) and sid.startswith("UsdPrimvarReader_float2"):
                name = self._value(node, "varname", "")
                name = str(name) if name is not None else ""
                if not name:
                    raise InputError(f"{what}: its st reader {node.GetPath()} names no primvar (inputs:varname)",
                                     self.path)
                return name, xf, (0.0, 0.0)
            raise InputError(f"{what}: its st comes from {node.GetPath()} ({sid}), not from a "
                             "UsdPrimvarReader_float2 or a UsdTransform2d", self.path)
        raise InputError(f"{what}: its st passes through more than 16 UsdTransform2d nodes", self.path)

    def _transform2d(self, node, what: str) -> np.ndarray:
        w = f"{what}: {node.GetPath()}"
        sx, sy = (self._number(x, f"{w}: inputs:scale") for x in self._value(node, "scale", (1.0, 1.0)))
        r = math.radians(self._number(self._value(node, "rotation", 0.0), f"{w}: inputs:rotation"))
        tx, ty = (self._number(x, f"{w}: inputs:translation") for x in self._value(node, "translation", (0.0, 0.0)))
        c, s = math.cos(r), math.sin(r)
        return np.array([[c * sx, -s * sy, tx], [s * sx, c * sy, ty]])  # T * R(ccw) * S

    # -- geometry ------------------------------------------------------------------------------
    def mesh(self, prim, index: int, groups) -> Mesh:
        UsdGeom = self.UsdGeom
        m = UsdGeom.Mesh(prim)
        label = f"mesh {prim.GetPath()}"
        t = self.time
        points = m.GetPointsAttr().Get(t)
        points = np.zeros((0, 3)) if points is None else np.asarray(points, np.float64).reshape(-1, 3)
        counts = m.GetFaceVertexCountsAttr().Get(t)
        counts = np.zeros(0, np.int64) if counts is None else np.asarray(counts, np.int64)
        fvi = m.GetFaceVertexIndicesAttr().Get(t)
        fvi = np.zeros(0, np.int64) if fvi is None else np.asarray(fvi, np.int64)
        if counts.size and counts.min() < 0:
            raise InputError(f"{label}: faceVertexCounts holds a negative count", self.path)
        if int(counts.sum()) != len(fvi):
            raise InputError(f"{label}: faceVertexCounts add up to {int(counts.sum())}, faceVertexIndices holds "
                             f"{len(fvi)}", self.path)
        if fvi.size and (fvi.min() < 0 or fvi.max() >= len(points)):
            bad = int(fvi.max() if fvi.max() >= len(points) else fvi.min())
            raise InputError(f"{label}: faceVertexIndices name point {bad} of {len(points)}", self.path)
        if not np.all(np.isfinite(points)):
            raise InputError(f"{label}: its points hold a NaN or an infinity", self.path)
        left = m.GetOrientationAttr().Get(t) == UsdGeom.Tokens.leftHanded
        holes = m.GetHoleIndicesAttr().Get(t)
        start = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64) if counts.size else counts
        nf = len(counts)
        owner = np.full(nf, -1, np.int64)
        for gi, (mat, faces) in enumerate(groups):
            if faces is None:
                owner[owner < 0] = gi
                continue
            if faces.size and (faces.min() < 0 or faces.max() >= nf):
                bad = int(faces.max() if faces.max() >= nf else faces.min())
                raise InputError(f"{label}: a GeomSubset names face {bad} of {nf}", self.path)
            free = faces[owner[faces] < 0]
            owner[free] = gi
        if holes is not None and len(holes):
            h = np.asarray(holes, np.int64)
            owner[h[(h >= 0) & (h < nf)]] = -1
        prims = []
        for gi, (mat, _) in enumerate(groups):
            faces = np.flatnonzero((owner == gi) & (counts >= 3))
            if not len(faces):
                continue
            prims.append(self.primitive(prim, m, index, len(prims), mat, faces, counts, start, fvi, points, left,
                                        label))
        return Mesh(index, str(prim.GetPath()), prims)

    def primitive(self, prim, m, index, pi, mat, faces, counts, start, fvi, points, left, label) -> Primitive:
        n = counts[faces]
        first = np.cumsum(n) - n  # each face's first corner in ``corners``
        corners = np.repeat(start[faces] - first, n) + np.arange(int(n.sum()))  # into faceVertexIndices
        ntri = n - 2  # the fan of each face over its corners: (c0, ck, ck+1)
        f_of_t = np.repeat(np.arange(len(faces)), ntri)
        k = np.arange(int(ntri.sum())) - np.repeat(np.cumsum(ntri) - ntri, ntri)
        tri = np.stack([first[f_of_t], first[f_of_t] + k + 1, first[f_of_t] + k + 2], axis=1)
        if left:
            tri = tri[:, [0, 2, 1]]
        face_ids = faces[f_of_t]
        look = self._uv.get(mat)
        material = self.materials[mat]
        unknown = np.zeros(len(tri), bool)
        uv_corner = None  # per corner
        uv_point = None  # per point
        name = look["varname"] if look is not None else None
        if look is not None and name is None and material.texture >= 0:
            uv_point = np.tile(np.asarray(look["fallback_st"], np.float64), (len(points), 1))
        elif name is not None:
            pv = self.UsdGeom.PrimvarsAPI(prim).GetPrimvar(name)
            values = pv.Get(self.time) if pv and pv.HasValue() else None
            if values is not None and pv.IsIndexed():  # indices checked here (USD's flattening only warns)
                idx = np.asarray(pv.GetIndices(self.time), np.int64)
                if idx.size and (idx.min() < 0 or idx.max() >= len(values)):
                    bad = int(idx.max() if idx.max() >= len(values) else idx.min())
                    raise InputError(f"{label}: primvar {name!r}: its indices name value {bad} of {len(values)}",
                                     self.path)
                values = np.asarray(values, np.float64).reshape(len(values), -1)[idx] if len(values) else None
            if values is None:
                if material.alpha_mode != "OPAQUE":
                    self.warn(f"{label}: its material's texture reads primvar {name!r}, which the mesh lacks: its "
                              f"{len(tri)} triangles are unknown")
                    unknown[:] = True
            else:
                try:
                    st = np.asarray(values, np.float64).reshape(len(values), -1)
                except (TypeError, ValueError):
                    raise InputError(f"{label}: primvar {name!r} is not an array of 2-vectors", self.path) from None
                if st.shape[1] != 2:
                    raise InputError(f"{label}: primvar {name!r} has {st.shape[1]} components, 2 expected", self.path)
                interp = pv.GetInterpolation()
                need = {"vertex": len(points), "varying": len(points), "faceVarying": len(fvi),
                        "uniform": len(counts), "constant": 1}.get(interp)
                if need is None:
                    raise InputError(f"{label}: primvar {name!r} has interpolation {interp!r}", self.path)
                if len(st) != need:
                    raise InputError(f"{label}: primvar {name!r} ({interp}) has {len(st)} values, the mesh needs "
                                     f"{need}", self.path)
                if interp in ("vertex", "varying"):
                    uv_point = st
                elif interp == "constant":
                    uv_point = np.repeat(st, len(points), axis=0)
                elif interp == "faceVarying":
                    uv_corner = st[corners]
                else:
                    uv_corner = st[np.repeat(faces, n)]
        if uv_corner is not None:  # a vertex per face corner
            pos = points[fvi[corners]]
            uv = uv_corner
            tris = tri
        else:  # the points the faces use, in order
            used, inverse = np.unique(fvi[corners], return_inverse=True)
            pos = points[used]
            uv = uv_point[used] if uv_point is not None else np.zeros((len(used), 2))
            tris = inverse.reshape(-1)[tri]
        if look is not None and (uv_point is not None or uv_corner is not None):
            uv = self.to_uv(uv, look)
            size = max(look["size"]) if look.get("size") else 1
            with np.errstate(invalid="ignore"):
                bad_v = ~(np.abs(uv) * size <= MAX_TEXEL_COORDINATE).all(axis=1)
            if bad_v.any():
                bad_t = bad_v[tris].any(axis=1)
                uv = np.where(bad_v[:, None], 0.0, uv)
                unknown |= bad_t
                if material.alpha_mode != "OPAQUE":
                    self.warn(f"{label}: {int(bad_t.sum())} triangles have NaN, infinite or huge (beyond 2^30 texels) "
                              "texture coordinates: they are unknown (all C), read as UV (0, 0) at every vertex")
                pos, uv, tris, _ = own_vertices(pos, uv, tris, None, bad_t)
        return Primitive(index, pi, pos, uv, tris.astype(np.int64), mat, None, unknown, str(prim.GetPath()),
                         face_ids.astype(np.int64))

    def to_uv(self, st: np.ndarray, look) -> np.ndarray:
        """USD st (t up) through the material's UsdTransform2d, as the model's uv (v down), moved
        into the black border's image where a wrap is black."""
        xf = look["st"]
        if not np.array_equal(xf, np.eye(2, 3)):
            st = st @ xf[:, :2].T + xf[:, 2]
        uv = np.stack([st[:, 0], 1.0 - st[:, 1]], axis=1)
        pad = look.get("pad", (False, False))
        size = look.get("size")
        if size is not None:
            h, w = size
            if pad[0]:
                uv[:, 0] = (uv[:, 0] * (w - 2) + 1) / w
            if pad[1]:
                uv[:, 1] = (uv[:, 1] * (h - 2) + 1) / h
        return uv

    # -- cameras -------------------------------------------------------------------------------
    def camera(self, prim) -> None:
        Gf = self.Gf
        ci = len(self.cameras)
        name = str(prim.GetPath())
        cam = self.UsdGeom.Camera(prim).GetCamera(self.time)
        kind = "orthographic" if cam.projection == Gf.Camera.Orthographic else "perspective"
        problem = None
        yfov = aspect = None
        try:
            yfov = math.radians(cam.GetFieldOfView(Gf.Camera.FOVVertical))
            aspect = cam.aspectRatio
        except (ValueError, ZeroDivisionError, RuntimeError):
            pass
        if kind != "perspective":
            problem = f"camera {ci} ({name}) is {kind}; omaps trace renders perspective views only"
        elif yfov is None or not 0 < yfov < math.pi:
            problem = f"camera {ci} ({name}) has no valid perspective field of view (got {yfov})"
        world = self.to_model @ self._relative(prim, None)
        eye = world[:3, 3].copy()
        f = world[:3, :3] @ np.array([0.0, 0.0, -1.0])
        u = world[:3, :3] @ np.array([0.0, 1.0, 0.0])
        fn = float(np.linalg.norm(f))
        forward = up = None
        if fn > 0:
            forward = f / fn
            u = u - (u @ forward) * forward
            un = float(np.linalg.norm(u))
            up = u / un if un > 0 else None
        if forward is None or up is None:
            problem = problem or f"camera {ci} ({name}): its transform is degenerate"
        self.cameras.append(SceneCamera(ci, name, kind, yfov, aspect, None, eye, forward, up, problem))


def _compose(outer: np.ndarray, inner: np.ndarray) -> np.ndarray:
    """The 2x3 affine map ``outer`` after ``inner``."""
    a = np.vstack([outer, [0, 0, 1]])
    b = np.vstack([inner, [0, 0, 1]])
    return (a @ b)[:2]
