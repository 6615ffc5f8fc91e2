"""Default studio scene for rendering a lone asset file: camera, distant key light, soft dome, ground."""

from __future__ import annotations

import numpy as np


def studio_stage(asset_path: str, *, ground: bool = True):
    """In-memory stage referencing ``asset_path`` at the origin, framed by a camera."""
    from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade

    from nasset_sdk.asset import Asset

    asset = Asset.open(asset_path, load="none")
    geo = asset.geometry()
    lo, hi = (np.asarray(a, np.float64) for a in geo.bounds())
    c = 0.5 * (lo + hi)
    r = float(np.linalg.norm(hi - lo)) * 0.5 or 1.0
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    obj = stage.DefinePrim("/World/Asset", "NeuralAsset")
    obj.GetReferences().AddReference(str(asset_path))
    cam = UsdGeom.Camera.Define(stage, "/World/Camera")
    cam.CreateFocalLengthAttr(35.0)
    cam.CreateHorizontalApertureAttr(20.955)
    cam.CreateVerticalApertureAttr(20.955)
    dist = r / np.tan(0.5 * 2 * np.arctan(20.955 / 70.0)) * 1.15
    eye = c + np.array([0.0, 0.35, 1.0]) / np.linalg.norm([0.0, 0.35, 1.0]) * dist
    m = Gf.Matrix4d().SetLookAt(Gf.Vec3d(*eye), Gf.Vec3d(*c), Gf.Vec3d(0, 1, 0)).GetInverse()
    cam.AddTransformOp().Set(m)
    key = UsdLux.DistantLight.Define(stage, "/World/Key")
    key.CreateIntensityAttr(3.0)
    key.CreateAngleAttr(1.0)
    key.AddRotateXYZOp().Set(Gf.Vec3f(-50.0, 30.0, 0.0))
    dome = UsdLux.DomeLight.Define(stage, "/World/Dome")
    dome.CreateIntensityAttr(0.15)
    if ground:
        g = UsdGeom.Mesh.Define(stage, "/World/Ground")
        s = r * 20
        y = float(lo[1])
        g.CreatePointsAttr([(-s, y, -s), (s, y, -s), (s, y, s), (-s, y, s)])
        g.CreateFaceVertexCountsAttr([4])
        g.CreateFaceVertexIndicesAttr([0, 3, 2, 1])
        g.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        mat = UsdShade.Material.Define(stage, "/World/Looks/Ground")
        sh = UsdShade.Shader.Define(stage, "/World/Looks/Ground/PreviewSurface")
        sh.CreateIdAttr("UsdPreviewSurface")
        sh.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(0.5, 0.5, 0.5))
        sh.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(0.8)
        mat.CreateSurfaceOutput().ConnectToSource(sh.ConnectableAPI(), "surface")
        UsdShade.MaterialBindingAPI.Apply(g.GetPrim()).Bind(mat)
    return stage
