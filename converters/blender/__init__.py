"""Blender (bpy) converter: Cycles ground truth, rna surface and fiber bakes, scene conversion."""
