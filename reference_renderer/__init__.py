"""Reference renderer: numpy + onnxruntime wavefront path tracer for USD scenes with neural assets.

    from nasset_reference_renderer import load_scene, render, RenderSettings
    result = render(load_scene("scene.usda"), RenderSettings(spp=64))
    result.image  # [H, W, 3] float64 radiance

spec/renderer.md states what a correct rendering of a neural asset is; this package implements it.
"""

from .film import read_exr, tonemap, write_exr, write_png
from .integrator import RenderResult, RenderSettings, RenderStats, render
from .plan import RenderPlan, make_plan
from .scene import Scene, SceneWarning, load_scene

__all__ = ["RenderPlan", "RenderResult", "RenderSettings", "RenderStats", "Scene", "SceneWarning", "load_scene",
           "make_plan", "read_exr", "render", "tonemap", "write_exr", "write_png"]
