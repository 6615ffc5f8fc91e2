"""What a render reads of a composed stage (spec/renderer.md#scene-input, #traversal, #image-size, #render-settings,
#materials): the render time, the scene's own payloads, the render settings prim and what it chooses (camera, image
size, prim purposes, material binding purpose, custom nasset: settings), visibility, the bound material, its surface
shader and where a shader input's value comes from, composition errors and the units of a placed asset. Both renderers
call these, so each rule lives in one place; how the prims are shaded is each renderer's own.

``warn(message, prim)`` receives what a renderer says about a feature it reads otherwise than authored (``prim``: a
path, or None when the message names its prim itself)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .errors import SceneError

Warn = Callable[[str, "str | None"], None]

#: largest side of a render settings' ``resolution`` (spec/renderer.md#image-size)
MAX_SETTINGS_SIDE = 16384
#: pixel filters of ``nasset:pixelFilter`` (spec/renderer.md#render-settings) and the largest ``nasset:pixelFilterStddev``
PIXEL_FILTERS = ("box", "gaussian")
MAX_FILTER_STDDEV = 8.0


@dataclass(frozen=True)
class Purposes:
    included: frozenset  # prim purposes rendered (UsdRender includedPurposes)
    material: str  # the binding purpose resolved, "" for all-purpose only (UsdRender materialBindingPurposes)


def render_time(stage, time=None):
    """The ``Usd.TimeCode`` a scene renders at (spec/renderer.md#traversal): ``time`` (a number) when given, else the
    stage's ``startTimeCode`` when it authors a time code range, else the earliest time: an attribute's default
    value, or its first time sample where it has samples (an animation cache without defaults still renders)."""
    import math

    from pxr import Usd

    if time is not None:
        if isinstance(time, Usd.TimeCode):
            return time
        if not math.isfinite(float(time)):
            raise SceneError("SCENE_INVALID", f"render time {time!r} is not finite")
        return Usd.TimeCode(float(time))
    if stage.HasAuthoredTimeCodeRange():
        return Usd.TimeCode(stage.GetStartTimeCode())
    return Usd.TimeCode.EarliestTime()


def load_scene_payloads(stage) -> None:
    """Load the scene's own payloads (a prim placed with a payload, spec/renderer.md#traversal), each
    without descendants, never inside a NeuralAsset: its components are loaded later by the render plan."""
    from pxr import Usd

    from .references import asset_source

    pred = Usd.TraverseInstanceProxies(Usd.PrimIsActive & Usd.PrimIsDefined & ~Usd.PrimIsAbstract)
    for _ in range(32):  # payloads may bring further payloads; bounded against cycles
        todo = []
        it = iter(Usd.PrimRange(stage.GetPseudoRoot(), pred))
        for prim in it:
            if prim.GetTypeName() == "NeuralAsset" or asset_source(prim) is not None:
                it.PruneChildren()
            elif prim.HasAuthoredPayloads() and not prim.IsLoaded():
                todo.append(prim.GetPath())
                it.PruneChildren()
        if not todo:
            return
        for path in todo:
            stage.Load(path, Usd.LoadWithoutDescendants)


def settings_prim(stage, warn: Warn):
    """The stage's render settings: the prim the stage's ``renderSettingsPrimPath`` names, else the first active
    UsdRender.Settings prim in traversal order (instance proxies included); None."""
    from pxr import Usd, UsdRender

    named = stage.GetMetadata("renderSettingsPrimPath")
    if named:
        prim = stage.GetPrimAtPath(named)
        if prim and prim.IsActive() and prim.IsA(UsdRender.Settings):
            return prim
        warn(f"renderSettingsPrimPath {named} is not an active UsdRender.Settings prim: the first one is used", None)
    return next((p for p in stage.Traverse(Usd.TraverseInstanceProxies()) if p.IsA(UsdRender.Settings)), None)


def render_products(stage, settings) -> list:
    """The UsdRender.Product prims of the render settings' ``products``, in order."""
    from pxr import UsdRender

    targets = UsdRender.Settings(settings).GetProductsRel().GetForwardedTargets()
    return [p for p in map(stage.GetPrimAtPath, targets) if p and p.IsA(UsdRender.Product)]


def stage_cameras(stage) -> list:
    """Every UsdGeom.Camera prim in traversal order (instance proxies included), whatever its visibility and purpose
    (they hide a camera's gizmo in a viewport, not the view through it)."""
    from pxr import Usd, UsdGeom

    return [p for p in Usd.PrimRange.Stage(stage, Usd.TraverseInstanceProxies()) if p.IsA(UsdGeom.Camera)]


def settings_camera(stage, settings, file: str):
    """The camera the render settings name (the ``camera`` of their first product that authors one, else their own),
    None when they name none; ``SCENE_INVALID`` when the target is not a UsdGeom.Camera."""
    from pxr import UsdGeom, UsdRender

    if settings is None:
        return None
    for owner in render_products(stage, settings) + [settings]:
        targets = UsdRender.SettingsBase(owner).GetCameraRel().GetForwardedTargets()
        if targets:
            prim = stage.GetPrimAtPath(targets[0])
            if not (prim and prim.IsA(UsdGeom.Camera)):
                raise SceneError("SCENE_INVALID", f"camera {targets[0]} is not a UsdGeom.Camera", file=file,
                                 prim=str(owner.GetPath()), attribute="camera")
            return prim
    return None


def render_camera(stage, settings, file: str, warn: Warn, cameras: list | None = None):
    """The camera rendered through: the settings' (:func:`settings_camera`), else the first of :func:`stage_cameras`
    (several are warned about); ``SCENE_INVALID`` when the stage has none."""
    chosen = settings_camera(stage, settings, file)
    if chosen is not None:
        return chosen
    cameras = stage_cameras(stage) if cameras is None else cameras
    if not cameras:
        raise SceneError("SCENE_INVALID", "the scene has no UsdGeom.Camera", file=file)
    if len(cameras) > 1:
        warn(f"{len(cameras)} cameras; rendering through the first, {cameras[0].GetPath()}", None)
    return cameras[0]


def settings_resolution(stage, settings, time, warn: Warn, max_pixels: int) -> tuple[int, int] | None:
    """Resolution of the render settings (their first product's when it authors one; None when absent or invalid).
    A ``pixelAspectRatio`` other than 1 and a ``dataWindowNDC`` other than the whole image are warned about."""
    from pxr import Gf, UsdRender

    if settings is None:
        return None
    owner = next((p for p in render_products(stage, settings)
                  if UsdRender.SettingsBase(p).GetResolutionAttr().HasAuthoredValue()), settings)
    base = UsdRender.SettingsBase(owner)
    res = base.GetResolutionAttr().Get(time)
    pixel_aspect = base.GetPixelAspectRatioAttr().Get(time)
    if pixel_aspect is not None and pixel_aspect != 1.0:
        warn(f"pixelAspectRatio {pixel_aspect:g} is ignored (square pixels)", str(owner.GetPath()))
    window = base.GetDataWindowNDCAttr().Get(time)
    if window is not None and Gf.Vec4f(window) != Gf.Vec4f(0, 0, 1, 1):
        warn(f"dataWindowNDC {tuple(window)} is ignored (the whole image is rendered)", str(owner.GetPath()))
    if res is not None and 0 < res[0] <= MAX_SETTINGS_SIDE and 0 < res[1] <= MAX_SETTINGS_SIDE and res[0] * res[1] <= max_pixels:
        return int(res[0]), int(res[1])
    warn(f"{owner.GetPath()}: resolution {res} ignored", None)
    return None


def conform_warning(settings, time, resolution, h_aperture: float, v_aperture: float, warn: Warn) -> None:
    """A warning when the settings' ``aspectRatioConformPolicy`` (USD's fallback ``expandAperture``) would frame the
    settings' ``resolution`` otherwise than the spec's horizontal fit."""
    from pxr import UsdRender

    if settings is None or resolution is None:
        return
    policy = str(UsdRender.SettingsBase(settings).GetAspectRatioConformPolicyAttr().Get(time) or "expandAperture")
    wider = resolution[0] * v_aperture - resolution[1] * h_aperture
    if policy == "adjustApertureHeight" or abs(wider) <= 1e-6 * resolution[1] * h_aperture:
        return
    if (policy == "expandAperture" and wider < 0) or (policy == "cropAperture" and wider > 0):
        return
    warn(f"aspectRatioConformPolicy {policy!r} is not applied: the horizontal aperture is kept and the vertical "
         f"extent follows the {resolution[0]}x{resolution[1]} image", str(settings.GetPath()))


def nasset_settings(settings, time, warn: Warn) -> dict:
    """The custom attributes of the render settings (spec/renderer.md#render-settings): ``max_depth`` (int
    ``nasset:maxDepth``, -1 unbounded), ``pixel_filter`` (``nasset:pixelFilter``: box | gaussian) and
    ``pixel_filter_stddev`` (float ``nasset:pixelFilterStddev``, pixels), each only where authored and valid; invalid
    values are warned about and dropped."""
    out: dict = {}
    for prim in [settings] if settings is not None else []:
        for name, key, ok in (("nasset:maxDepth", "max_depth", lambda v: isinstance(v, int) and v >= -1),
                              ("nasset:pixelFilter", "pixel_filter", lambda v: str(v) in PIXEL_FILTERS),
                              ("nasset:pixelFilterStddev", "pixel_filter_stddev",
                               lambda v: isinstance(v, float) and 0.0 < v <= MAX_FILTER_STDDEV)):
            attr = prim.GetAttribute(name)
            v = attr.Get(time) if attr and attr.HasAuthoredValue() else None
            if v is None:
                continue
            if ok(v):
                out[key] = str(v) if key == "pixel_filter" else v
            else:
                warn(f"{name} = {v!r} ignored", str(prim.GetPath()))
    return out


def settings_purposes(settings, time, warn: Warn) -> Purposes:
    """What the render settings render: ``included`` prim purposes (``includedPurposes``, fallback default and
    render) and the ``material`` binding purpose to resolve (the first specific one of ``materialBindingPurposes``,
    fallback full; ``ComputeBoundMaterial`` falls back to the all-purpose binding)."""
    from pxr import UsdGeom, UsdRender, UsdShade

    included, purposes = [UsdGeom.Tokens.default_, UsdGeom.Tokens.render], [UsdShade.Tokens.full, ""]
    if settings is not None:
        api = UsdRender.Settings(settings)
        included = list(api.GetIncludedPurposesAttr().Get(time) or included)
        purposes = list(api.GetMaterialBindingPurposesAttr().Get(time) or purposes)
    specific = [str(p) for p in purposes if p]
    if len(specific) > 1:
        warn(f"materialBindingPurposes {purposes}: bindings of {specific[0]!r}, else all-purpose ones, are read",
             str(settings.GetPath()))
    return Purposes(frozenset(str(p) for p in included), specific[0] if specific else str(UsdShade.Tokens.allPurpose))


def is_hidden(prim, time, purposes: Purposes) -> bool:
    """:meth:`Hiding.is_hidden` of one prim on its own (spec/implementers.md lets implementations call this module):
    USD's per-prim ``ComputeVisibility`` / ``ComputePurpose``, O(depth) per call; a traversal uses :class:`Hiding`."""
    from pxr import UsdGeom

    if not prim.IsA(UsdGeom.Imageable):
        return False
    img = UsdGeom.Imageable(prim)
    return img.ComputeVisibility(time) == UsdGeom.Tokens.invisible or img.ComputePurpose() not in purposes.included


class Hiding:
    """Which prims a render skips (:meth:`is_hidden`), each prim's computed visibility and purpose found from its
    parent's, remembered by path: a traversal costs O(prims), where USD's ``ComputeVisibility`` and
    ``ComputePurpose`` walk every ancestor of every prim (O(prims x depth): a chain of 3 000 nested Xforms took
    seconds). The rules are USD's: an imageable prim authoring visibility ``invisible`` hides its subtree; a prim's
    purpose is its own authored one, else its nearest imageable ancestor's authored one, else ``default``;
    non-imageable prims author neither (their attributes are ignored) and pass their parent's down."""

    def __init__(self, time, purposes: Purposes):
        self.time = time
        self.purposes = purposes
        self._state: dict = {}  # prim path -> (invisible, UsdGeom.Imageable.PurposeInfo)

    def is_hidden(self, prim) -> bool:
        """True for an imageable prim whose computed visibility is ``invisible`` or whose computed purpose the settings
        do not include: the prim is skipped with its subtree (cameras are found by :func:`stage_cameras`
        regardless)."""
        from pxr import UsdGeom

        if not prim.IsA(UsdGeom.Imageable):
            return False
        invisible, info = self._computed(prim)
        return invisible or str(info.purpose) not in self.purposes.included

    def _computed(self, prim) -> tuple:
        """(invisible, PurposeInfo) of ``prim``, from the nearest remembered ancestor down (in traversal order the
        parent is always remembered, so each prim costs O(1))."""
        from pxr import UsdGeom

        chain = []
        while prim and not prim.IsPseudoRoot() and prim.GetPath() not in self._state:
            chain.append(prim)
            prim = prim.GetParent()
        state = self._state.get(prim.GetPath()) if prim else None
        state = state or (False, UsdGeom.Imageable.PurposeInfo())  # at the root: nothing inherited
        for p in reversed(chain):
            invisible, info = state
            if p.IsA(UsdGeom.Imageable):
                img = UsdGeom.Imageable(p)
                invisible = invisible or img.GetVisibilityAttr().Get(self.time) == UsdGeom.Tokens.invisible
                info = img.ComputePurposeInfo(info)
            state = (invisible, info)
            self._state[p.GetPath()] = state
        return state


class InheritedPrimvars:
    """``UsdGeom.PrimvarsAPI.FindPrimvarWithInheritance`` with what each prim passes down of a name remembered by
    (prim, name): a mesh N deep costs O(1) per name asked, where USD's walks its N ancestors (a chain of meshes N
    deep cost O(N^2)). USD's rule: a prim's own primvar with an authored value, else the nearest ancestor's that
    authors a value, when that one is constant (a non-constant one blocks inheritance)."""

    def __init__(self):
        self._state: dict = {}  # (prim, name) -> the primvar its children inherit, or None (prims of any stage)

    def find(self, prim, name: str):
        """The primvar ``name`` that ``prim`` reads, with an authored value (its own or inherited); None."""
        from pxr import UsdGeom

        own = UsdGeom.PrimvarsAPI(prim).GetPrimvar(name)
        if own and own.HasAuthoredValue():
            return own
        return self._inherited(prim.GetParent(), name)

    def _inherited(self, prim, name: str):
        """The primvar ``name`` that ``prim``'s children inherit (None), from the nearest remembered ancestor down."""
        from pxr import UsdGeom

        chain = []
        while prim and not prim.IsPseudoRoot() and (prim, name) not in self._state:
            chain.append(prim)
            prim = prim.GetParent()
        inherited = self._state.get((prim, name)) if prim else None
        for p in reversed(chain):
            pv = UsdGeom.PrimvarsAPI(p).GetPrimvar(name)
            if pv and pv.HasAuthoredValue():
                inherited = pv if pv.GetInterpolation() == UsdGeom.Tokens.constant else None
            self._state[(p, name)] = inherited
        return inherited


class MaterialBindings:
    """``UsdShade.MaterialBindingAPI.ComputeBoundMaterial`` with what each prim passes down remembered by (prim,
    purpose): a mesh N deep costs O(1), where USD's walks its N ancestors (a chain of meshes N deep cost O(N^2)).
    USD's rule, each prim's own binding read by USD's calls: the specific purpose's bindings first, then the
    all-purpose ones; of the direct bindings to a Material on the prim and its ancestors, the nearest wins, unless
    an ancestor's is ``strongerThanDescendants`` (the one nearest the root of those). Below a collection-based
    binding (membership depends on the prim asked about) USD's own walk answers."""

    def __init__(self):
        self._state: dict = {}  # (prim, purpose) -> (nearest bound path, root-most stronger one, collections above)

    def compute(self, prim, purpose: str):
        """The Material bound to ``prim`` for ``purpose``, else its all-purpose one (an invalid Material: none)."""
        from pxr import UsdShade

        for each in dict.fromkeys((purpose, str(UsdShade.Tokens.allPurpose))):
            nearest, stronger, collections = self._computed(prim, each)
            if collections:
                return UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial(purpose)[0]
            if stronger or nearest:  # a binding to what is not a Material binds nothing, and ends the search
                return UsdShade.Material(prim.GetStage().GetPrimAtPath(stronger or nearest))
        return UsdShade.Material()

    def _computed(self, prim, purpose: str) -> tuple:
        from pxr import UsdShade

        chain = []
        while prim and not prim.IsPseudoRoot() and (prim, purpose) not in self._state:
            chain.append(prim)
            prim = prim.GetParent()
        state = self._state.get((prim, purpose)) if prim else None
        state = state or (None, None, False)
        for p in reversed(chain):
            nearest, stronger, collections = state
            names = [n for n in p.GetAuthoredPropertyNames() if n.startswith("material:binding")]
            if names:
                binding = UsdShade.MaterialBindingAPI(p).GetDirectBinding(purpose)
                target = binding.GetMaterialPath()
                if not target.isEmpty:
                    nearest = target
                    if stronger is None and UsdShade.MaterialBindingAPI.GetMaterialBindingStrength(
                            binding.GetBindingRel()) == UsdShade.Tokens.strongerThanDescendants:
                        stronger = target
                collections = collections or any(n.startswith("material:binding:collection") for n in names)
            state = (nearest, stronger, collections)
            self._state[(p, purpose)] = state
        return state


def bound_material(prim, purposes: Purposes, warn: Warn, bindings: MaterialBindings | None = None):
    """The material bound to ``prim`` for the settings' binding purpose (else its all-purpose binding; an invalid
    ``UsdShade.Material`` when unbound); a prim bound only for ``preview`` while the settings do not read it is
    unbound, with a warning naming the prim and the material. ``bindings``: what a traversal remembers of the
    ancestors' bindings (:class:`MaterialBindings`)."""
    from pxr import UsdShade

    bindings = bindings or MaterialBindings()
    mat = bindings.compute(prim, purposes.material)
    if not mat and purposes.material != UsdShade.Tokens.preview:
        preview = bindings.compute(prim, str(UsdShade.Tokens.preview))
        if preview:
            warn(f"bound to {preview.GetPath()} only for purpose preview (a viewport's binding; a final render "
                 "reads full, else all-purpose bindings): rendered unbound", str(prim.GetPath()))
    return mat


#: |IOR - 1| below which a solid glass is index-matched and read as thin-walled (spec/renderer.md#transmission)
INDEX_MATCHED = 1e-4
#: surface shader ids read with UsdPreviewSurface's inputs
PREVIEW_SURFACES = ("UsdPreviewSurface", "ND_UsdPreviewSurface_surfaceshader")


def surface_shader(mat):
    """The surface shader of a UsdShade.Material (spec/renderer.md#materials, surface shaders): MaterialX's
    ``outputs:mtlx:surface`` when its shader is one the renderers read (the render context a MaterialX renderer
    asks for first), else the universal ``outputs:surface``, else the MaterialX one; None when neither has one."""
    found = []
    for context in ("mtlx", ""):  # ComputeSurfaceSource("mtlx") falls back to the universal output
        src = mat.ComputeSurfaceSource(context)
        if src and src[0]:
            found.append(src[0])
    readable = [sh for sh in found if sh.GetIdAttr().Get() in PREVIEW_SURFACES + tuple(MTLX_SURFACES)]
    return (readable or found or [None])[0]


def input_source(inp, time) -> tuple:
    """(producer, value) of a shader input, followed through its connections (spec/renderer.md#materials: node graph
    boundaries, a material's interface inputs, as in USD's own UsdPreviewSurface example): producer is the (shader,
    output name) whose output feeds it, or None when a value does; value is that value, or the input's own when a
    shader output feeds it (None when unset)."""
    from pxr import UsdShade

    if not inp:
        return None, None
    attrs = inp.GetValueProducingAttributes() if inp.HasConnectedSource() else [inp.GetAttr()]
    if attrs and UsdShade.Utils.GetType(attrs[0].GetName()) == UsdShade.AttributeType.Output:
        return (UsdShade.Shader(attrs[0].GetPrim()), UsdShade.Utils.GetBaseNameAndType(attrs[0].GetName())[0]), \
            inp.Get(time)
    return None, (attrs[0].Get(time) if attrs else None)


def units_warning(stage, asset_meters_per_unit: float, M, prim: str, warn: Warn) -> None:
    """A warning when a stage that authors ``metersPerUnit`` places an asset of other units (the asset layer's
    ``metersPerUnit``) without the scale that converts them (``cbrt |det M3|`` within 1 % of their ratio; USD converts
    nothing: spec/format.md#coordinates, spec/renderer.md#traversal); the asset then renders at another size."""
    from pxr import UsdGeom

    if not stage.HasAuthoredMetadata("metersPerUnit"):
        return
    ratio = float(asset_meters_per_unit) / UsdGeom.GetStageMetersPerUnit(stage)
    scale = float(np.cbrt(abs(np.linalg.det(np.asarray(M, np.float64)[:3, :3]))))
    if not np.isclose(ratio, 1.0, rtol=1e-6) and not np.isclose(scale, ratio, rtol=0.01):
        warn(f"the asset's metersPerUnit is {ratio:.4g} x the stage's and USD converts no units: its placement "
             f"scales it by {scale:.4g}, not {ratio:.4g}, so it renders {scale / ratio:.4g} x its size", prim)


def composition_errors(stage) -> list:
    """USD's composition errors (a reference, payload or sublayer that cannot be opened, an unresolved prim path):
    [(prim path, USD's message)] in USD's order. USD composes the stage without what failed; a renderer warns about
    each, naming the prim."""
    return [(str(f.rootSite.path), str(f).strip()) for f in stage.GetCompositionErrors()]


#: UsdLux light inputs no renderer here honours, with the value that means "no effect" (spec/renderer.md#lights)
UNRENDERED_LIGHT_INPUTS = (("inputs:diffuse", 1.0), ("inputs:specular", 1.0), ("inputs:shadow:enable", True))


def unrendered_light_inputs(prim, time) -> str:
    """The authored light inputs of ``prim`` that would change its light and are not rendered, as "name = value, ..."
    ("" when none): a diffuse or specular multiplier other than 1, shadows turned off (UsdLux.ShadowAPI)."""
    said = []
    for name, neutral in UNRENDERED_LIGHT_INPUTS:
        attr = prim.GetAttribute(name)
        value = attr.Get(time) if attr and attr.HasAuthoredValue() else None
        if value is not None and value != neutral:
            said.append(f"{name} = {value}")
    return ", ".join(said)


#: the range of a RectLight's or DiskLight's ``nasset:spread`` (radians, full apex; spec/renderer.md#lights)
MIN_SPREAD, MAX_SPREAD = 1e-3, float(np.pi)


def light_spread(prim, time, file: str) -> float:
    """The ``nasset:spread`` of a RectLight or DiskLight prim (radians; unauthored: pi, a Lambertian emitter);
    ``SCENE_INVALID`` naming the attribute when it is not a finite float in [MIN_SPREAD, MAX_SPREAD]."""
    attr = prim.GetAttribute("nasset:spread")
    if not (attr and attr.HasAuthoredValue()):
        return MAX_SPREAD
    value = attr.Get(time)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not MIN_SPREAD <= float(value) <= MAX_SPREAD + 1e-6:
        raise SceneError("SCENE_INVALID", f"nasset:spread {value!r} must be a float in [{MIN_SPREAD:g}, pi] (radians)",
                         file=file, prim=str(prim.GetPath()), attribute="nasset:spread")
    return min(float(value), MAX_SPREAD)


#: microfacet distributions of a material's specular lobe (``nasset:microfacet`` on its surface shader)
MICROFACETS = ("ggx", "beckmann")


def shader_microfacet(shader, time, file: str) -> str:
    """The ``nasset:microfacet`` of a surface shader prim (spec/renderer.md#materials): ``ggx`` (unauthored) or
    ``beckmann``; ``SCENE_INVALID`` naming the attribute for another value."""
    attr = shader.GetPrim().GetAttribute("nasset:microfacet")
    if not (attr and attr.HasAuthoredValue()):
        return "ggx"
    value = attr.Get(time)
    if not isinstance(value, str) or value not in MICROFACETS:
        raise SceneError("SCENE_INVALID", f"nasset:microfacet {value!r} must be one of {', '.join(MICROFACETS)}",
                         file=file, prim=str(shader.GetPath()), attribute="nasset:microfacet")
    return value


def spread_profile(cos_a, spread: float):
    """The factor [N] of an area light's radiance toward directions at cos_a [N] from its emitting normal for a
    ``nasset:spread`` of ``spread`` radians (spec/renderer.md#lights, Cycles' soft-box grid): max(tan h - tan a, 0) N,
    h = spread / 2, N = 1 / (tan h - h) (3 / h^3 for h <= 0.05), which keeps the power; 1 at spread pi; 0 behind."""
    cos_a = np.asarray(cos_a, np.float64)
    if spread >= MAX_SPREAD:
        return np.where(cos_a > 0.0, 1.0, 0.0)
    h = 0.5 * spread
    norm = 3.0 / h**3 if h <= 0.05 else 1.0 / (np.tan(h) - h)
    c = np.maximum(cos_a, 1e-300)
    tan_a = np.sqrt(np.maximum(1.0 - c * c, 0.0)) / c
    return np.where(cos_a > 0.0, np.maximum(np.tan(h) - tan_a, 0.0) * norm, 0.0)


def normal_matrix(m3) -> np.ndarray:
    """The 3x3 matrix [3, 3] (or a stack [n, 3, 3] for m3 [n, 3, 3]) that takes object-space normals, as rows, to world
    normals of the same side, up to length, for the linear part ``m3`` of a row-vector transform: the cofactor matrix
    (its rows the cross products of m3's rows, = det(m3) inv(m3)^T) times the sign of det(m3). Unlike inv(m3)^T it exists
    for every transform: one that flattens a surface (a scale of 0 along its normal, a legal USD transform) still gives
    the surface's normal, and one that collapses it gives zero normals, on triangles of zero area that no ray meets."""
    m = np.asarray(m3, np.float64)
    r0, r1, r2 = m[..., 0, :], m[..., 1, :], m[..., 2, :]
    cof = np.stack([np.cross(r1, r2), np.cross(r2, r0), np.cross(r0, r1)], -2)
    sign = np.where(np.linalg.det(m) < 0, -1.0, 1.0)
    return cof * np.asarray(sign)[..., None, None]


def smooth_vertex_normals(points: np.ndarray, counts: np.ndarray, idx: np.ndarray, reversed_winding: bool) -> np.ndarray:
    """Unit normals [V,3] of the ``points`` [V,3] of polygons ``counts`` / ``idx``: at each polygon corner the
    cross product of its two edges, (next - p) x (prev - p) (area-weighted, Hydra's smooth normals of a cage), summed
    per point; negated for a reversed winding. The shading normals of a subdivision surface's cage without authored
    normals (spec/renderer.md#shading-normals). A point whose sum vanishes gets (0, 0, 1)."""
    starts = np.repeat(np.cumsum(counts) - counts, counts)
    n = np.repeat(counts, counts)
    k = np.arange(len(idx)) - starts
    nxt, prv = idx[starts + (k + 1) % n], idx[starts + (k - 1) % n]
    p = points[idx]
    a, b = points[nxt] - p, points[prv] - p
    cross = np.stack([a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1], a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
                      a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]], 1)
    acc = np.zeros((len(points), 3))
    np.add.at(acc, idx, -cross if reversed_winding else cross)
    length = np.sqrt((acc * acc).sum(1))
    out = np.tile([0.0, 0.0, 1.0], (len(points), 1))
    ok = length > 1e-300
    out[ok] = acc[ok] / length[ok, None]
    return out

#: MaterialX surface shaders read as UsdPreviewSurface (spec/renderer.md#materials): their inputs with the
#: MaterialX fallbacks, and the lobes UsdPreviewSurface lacks (warned about when they are on)
MTLX_SURFACES = {
    "ND_standard_surface_surfaceshader": {
        "inputs": {"base": 1.0, "base_color": (0.8, 0.8, 0.8), "metalness": 0.0, "specular_roughness": 0.2,
                   "specular_IOR": 1.5, "emission": 0.0, "emission_color": (1.0, 1.0, 1.0)},
        "glass": {"transmission": 0.0, "transmission_color": (1.0, 1.0, 1.0), "thin_walled": 0,
                  "specular_color": (1.0, 1.0, 1.0)},
        "dropped": ("coat", "subsurface", "sheen", "thin_film_thickness", "specular_anisotropy", "transmission_depth")},
    "ND_open_pbr_surface_surfaceshader": {
        "inputs": {"base_weight": 1.0, "base_color": (0.8, 0.8, 0.8), "base_metalness": 0.0, "specular_roughness": 0.3,
                   "specular_ior": 1.5, "emission_luminance": 0.0, "emission_color": (1.0, 1.0, 1.0)},
        "glass": {"transmission_weight": 0.0, "transmission_color": (1.0, 1.0, 1.0), "geometry_thin_walled": 0,
                  "specular_color": (1.0, 1.0, 1.0)},
        "dropped": ("coat_weight", "subsurface_weight", "fuzz_weight", "thin_film_weight",
                    "specular_roughness_anisotropy", "transmission_depth")},
}


def mtlx_preview_values(shader, sid: str, time, warn: Warn, finite) -> dict:
    """UsdPreviewSurface values of a MaterialX standard_surface or open_pbr_surface ``shader`` (id ``sid``, a key of
    :data:`MTLX_SURFACES`): base colour x weight, metalness, specular roughness and IOR, emission x colour, and the
    glass lobe (spec/renderer.md#transmission) as ``transmission`` (weight in [0, 1]), ``transmissionColor`` and
    ``specularTint`` (the specular colour: [3] in [0, 1] each) and ``thinWalled`` (bool); another lobe
    UsdPreviewSurface lacks is warned about when it is on, a connected input uses its own value (warned).
    ``finite(value, default, name)``: the caller's check of one input's value (SCENE_INVALID naming it)."""
    names = MTLX_SURFACES[sid]
    vals = {}
    for name, default in {**names["inputs"], **names["glass"]}.items():
        producer, v = input_source(shader.GetInput(name), time)
        if producer is not None:
            warn(f"MaterialX input {name!r} is connected; its own value is used", shader.GetPath())
        vals[name] = finite(v, default, name)
    for name in names["dropped"]:
        inp = shader.GetInput(name)
        v = inp.Get(time) if inp else None
        if v is not None and float(np.max(v)) > 0.0:
            warn(f"MaterialX {name} is dropped (no UsdPreviewSurface counterpart)", shader.GetPath())
    b, c, m, r, i, e, ec = (vals[k] for k in names["inputs"])
    t, tc, thin, sc = (vals[k] for k in names["glass"])
    return {"diffuseColor": tuple(np.clip(b * c, 0, 1)), "metallic": float(m), "roughness": float(r), "ior": float(i),
            "emissiveColor": tuple(np.maximum(e * ec, 0.0)), "useSpecularWorkflow": 0,
            "transmission": float(np.clip(t, 0.0, 1.0)), "transmissionColor": tuple(np.clip(tc, 0.0, 1.0)),
            # an index-matched solid bends nothing: it is read as a thin wall (refraction at IOR 1 sends every
            # microfacet's light straight on, a direction no GGX density holds)
            "thinWalled": bool(np.asarray(thin).ravel()[0] != 0) or abs(float(i) - 1.0) < INDEX_MATCHED,
            "specularTint": tuple(np.clip(sc, 0.0, 1.0))}
