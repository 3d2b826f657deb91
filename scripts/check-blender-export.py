#!/usr/bin/env python3
"""By hand: run `workbench export --to blender`'s snippet in Blender's own Python module (bpy).

Starts an empty factory scene, adds a 35 mm UV sphere (made the active object, as the snippet
expects), runs the snippet and prints the Principled BSDF's subsurface method and the inputs it
set, as Blender holds them, for comparison with fit.json's medium.
Needs `pip install --target <dir> bpy==4.2.0` (519 MB, CPython 3.11) and PYTHONPATH=<dir>; not
part of the suite for that size (docs/medium.md, "Exports").
Usage: PYTHONPATH=<dir> python3 scripts/check-blender-export.py <export dir>/blender.py
"""
import sys

import bpy

bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.mesh.primitive_uv_sphere_add(radius=0.035)
with open(sys.argv[1]) as f:
    exec(f.read())
obj = bpy.context.active_object
bsdf = obj.data.materials[0].node_tree.nodes["Principled BSDF"]
print("Subsurface Method", bsdf.subsurface_method)
for name in ["Base Color", "Subsurface Weight", "Subsurface Radius", "Subsurface Scale", "IOR",
             "Roughness"]:
    v = bsdf.inputs[name].default_value
    print(name, tuple(v) if hasattr(v, "__len__") else v)
