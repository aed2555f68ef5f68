"""Times the strength slider (docs/blender.md): the fixture bunny stylized (cube, 20 iterations)
through the installed extension, then 10 slider moves, and a cProfile of 5 more.

    BLENDER_USER_RESOURCES=$(mktemp -d) .venv-blender/bin/python blender/tools/time_slider.py \
        target/blender/geometry_in_style-0.1.0.zip target/debug/stylize
"""
import sys, time, tempfile, statistics, bpy
bpy.ops.wm.read_factory_settings(use_empty=True)
assert bpy.ops.extensions.package_install_files(filepath=sys.argv[1], repo="user_default", enable_on_install=True) == {"FINISHED"}
prefs = bpy.context.preferences.addons["bl_ext.user_default.geometry_in_style"].preferences
prefs.stylize_path = sys.argv[2]; prefs.runs_dir = tempfile.mkdtemp()
bpy.ops.wm.obj_import(filepath="fixtures/meshes/bunny.obj")
obj = bpy.context.selected_objects[0]; bpy.context.view_layer.objects.active = obj
obj.gis.iterations = 20
assert bpy.ops.gis.stylize() == {"FINISHED"}
obj.gis.strength = 7.0  # warm
ts = []
for lam in [3, 4, 5, 6, 7, 8, 9, 10, 11, 12]:
    t = time.perf_counter(); obj.gis.strength = float(lam); ts.append(time.perf_counter() - t)
print("vertices", len(obj.data.vertices), "slider move median ms %.1f min %.1f max %.1f" % (1e3*statistics.median(ts), 1e3*min(ts), 1e3*max(ts)))
import cProfile, os, pstats
prof = os.path.join(tempfile.mkdtemp(), "prof")
cProfile.run("for lam in [3,4,5,6,7]: obj.gis.strength = float(lam)", prof)
pstats.Stats(prof).sort_stats("cumtime").print_stats(14)
