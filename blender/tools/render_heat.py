"""Renders a run's mesh_heat.glb as Blender shows it (glTF import, COLOR_0 into the Base Color),
headless Cycles CPU: .venv-blender/bin/python blender/tools/render_heat.py RUN/mesh_heat.glb OUT.png
(docs/images/mesh_heat.png: fixtures/meshes/bunny.obj, --style cube, 200 iterations)."""
import sys, math, bpy
from mathutils import Vector
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=sys.argv[1])
obj = [o for o in bpy.context.scene.objects if o.type == "MESH"][0]
print("attributes", [a.name for a in obj.data.color_attributes])
mat = bpy.data.materials.new("heat"); mat.use_nodes = True
nt = mat.node_tree; bsdf = nt.nodes["Principled BSDF"]
attr = nt.nodes.new("ShaderNodeVertexColor"); attr.layer_name = obj.data.color_attributes[0].name
nt.links.new(attr.outputs["Color"], bsdf.inputs["Base Color"])
obj.data.materials.clear(); obj.data.materials.append(mat)
scene = bpy.context.scene
cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam")); scene.collection.objects.link(cam)
cam.location = Vector((0.3, -4.6, 1.5)); cam.rotation_euler = (Vector((0, 0, 0)) - cam.location).to_track_quat("-Z", "Y").to_euler()
scene.camera = cam
sun = bpy.data.objects.new("sun", bpy.data.lights.new("sun", "SUN")); sun.data.energy = 3.5
sun.rotation_euler = (math.radians(40), 0, math.radians(20)); scene.collection.objects.link(sun)
w = bpy.data.worlds.new("w"); w.color = (0.5, 0.5, 0.52); scene.world = w
scene.render.engine = "CYCLES"; scene.cycles.device = "CPU"; scene.cycles.samples = 16
scene.render.resolution_x, scene.render.resolution_y = 480, 400
scene.render.filepath = sys.argv[2]
bpy.ops.render.render(write_still=True)
