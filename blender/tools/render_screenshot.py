"""Renders docs/images/blender.png headless: the fixture bunny before (left) and after (right)
the extension's Stylize with the cube style, the right one being the same mesh with the shape key
"Stylized" at the strength shown. A Cycles CPU render of the scene (no window: Blender cannot
screenshot its UI headless), made through the installed extension exactly as an artist's click.

    BLENDER_USER_RESOURCES=$(mktemp -d) .venv-blender/bin/python blender/tools/render_screenshot.py \
        target/blender/geometry_in_style-0.1.0.zip target/debug/stylize docs/images/blender.png
"""

import math
import sys
import tempfile

import bpy
from mathutils import Vector

zip_path, stylize, out = sys.argv[1:4]
strength = float(sys.argv[4]) if len(sys.argv) > 4 else 8.0
bpy.ops.wm.read_factory_settings(use_empty=True)
assert bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default", enable_on_install=True) == {"FINISHED"}
prefs = bpy.context.preferences.addons["bl_ext.user_default.geometry_in_style"].preferences
prefs.stylize_path = stylize
prefs.runs_dir = tempfile.mkdtemp(prefix="gis-shot-")

scene = bpy.context.scene
objs = []
for name, x in (("Before", -1.25), ("After", 1.25)):
    bpy.ops.wm.obj_import(filepath="fixtures/meshes/bunny.obj", forward_axis="NEGATIVE_Z", up_axis="Y")
    obj = bpy.context.selected_objects[0]
    obj.name = name
    bpy.ops.object.shade_smooth()
    obj.dimensions = obj.dimensions * (2.0 / max(obj.dimensions))
    bpy.ops.object.transform_apply(location=False, rotation=True, scale=True)
    bpy.ops.object.origin_set(type="ORIGIN_GEOMETRY", center="BOUNDS")
    obj.location = (x, 0.0, 0.0)
    objs.append(obj)
after = objs[1]
bpy.context.view_layer.objects.active = after
after.gis.style = "CUBE"
after.gis.iterations = 200
assert bpy.ops.gis.stylize() == {"FINISHED"}, after.gis.status
after.gis.strength = strength
print(after.gis.sanity)

mat = bpy.data.materials.new("clay")
mat.diffuse_color = (0.75, 0.55, 0.4, 1.0)
for o in objs:
    o.data.materials.append(mat)
    o.location.z = -min((o.matrix_world @ Vector(c)).z for c in o.bound_box) + o.location.z
bpy.ops.mesh.primitive_plane_add(size=30.0, location=(0, 0, 0))
cam_data = bpy.data.cameras.new("cam")
cam = bpy.data.objects.new("cam", cam_data)
scene.collection.objects.link(cam)
cam.location = (0.0, -8.0, 3.4)
direction = Vector((0.0, 0.0, 0.8)) - cam.location
cam.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()
scene.camera = cam
sun = bpy.data.objects.new("sun", bpy.data.lights.new("sun", "SUN"))
sun.data.energy = 4.0
sun.rotation_euler = (math.radians(50), math.radians(10), math.radians(30))
scene.collection.objects.link(sun)
world = bpy.data.worlds.new("w")
world.color = (0.32, 0.34, 0.38)
scene.world = world
scene.render.engine = "CYCLES"
scene.cycles.device = "CPU"
scene.cycles.samples = 24
scene.render.resolution_x, scene.render.resolution_y = 960, 480
scene.render.filepath = out
bpy.ops.render.render(write_still=True)
print("wrote", out)
