"""Render a baked ``.glb`` in Blender (pip ``bpy``) from a raytrad camera: the lightmap as
Blender's glTF importer sets it up (emissive texture on ``TEXCOORD_1``), Cycles on the
CPU, no lights and a black world, so only the bake shows.

    python tools/blender_view.py BAKED.glb OUT.png X,Y,Z TX,TY,TZ FOV WIDTH HEIGHT

Run it with a Python that has ``bpy`` (``pip install bpy``; an optional benchmark and
test dependency, never a runtime one). Positions are raytrad's (y up) in metres, the
field of view vertical in degrees. Prints the UV layers and the emission image found.
"""

from __future__ import annotations

import math
import sys


def main(argv: list[str]) -> None:
    import bpy
    from mathutils import Vector

    path, out, position, target, fov, width, height = argv
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_scene.gltf(filepath=path)

    def blender(text: str) -> Vector:  # glTF y up -> Blender z up
        x, y, z = (float(v) for v in text.split(","))
        return Vector((x, -z, y))

    camera = bpy.data.objects.new("raytrad", bpy.data.cameras.new("raytrad"))
    bpy.context.scene.collection.objects.link(camera)
    camera.location = blender(position)
    camera.rotation_euler = (blender(target) - camera.location).to_track_quat("-Z", "Y").to_euler()
    camera.data.sensor_fit = "VERTICAL"
    camera.data.angle = math.radians(float(fov))
    scene = bpy.context.scene
    scene.camera = camera
    scene.world = bpy.data.worlds.new("black")
    scene.world.color = (0.0, 0.0, 0.0)
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 16
    scene.cycles.max_bounces = 0  # the camera sees the baked emission only
    scene.render.resolution_x, scene.render.resolution_y = int(width), int(height)
    scene.render.resolution_percentage = 100
    scene.view_settings.view_transform = "Standard"
    scene.render.filepath = out
    for obj in bpy.data.objects:
        if obj.type == "MESH":
            print("uv layers", obj.name, [uv.name for uv in obj.data.uv_layers])
    for material in bpy.data.materials:
        for node in material.node_tree.nodes if material.node_tree else []:
            if node.type == "TEX_IMAGE" and node.image is not None:
                print("emission image", material.name, node.image.name, node.image.size[:])
    bpy.ops.render.render(write_still=True)


if __name__ == "__main__":
    main(sys.argv[1:])
