# Blender (headless) imports a .chan with its bundled "Import Nuke chan" add-on, as a crew would,
# and prints the camera's world matrix at every frame of the file, one JSON object a line.
#   blender -b --factory-startup --python blender_import_chan.py -- FILE.chan OUT.jsonl
import json
import sys

import addon_utils
import bpy

chan, out = sys.argv[sys.argv.index("--") + 1:]
addon_utils.enable("io_anim_nuke_chan", default_set=True)
camera = bpy.data.objects["Camera"]
bpy.context.view_layer.objects.active = camera
# Nuke's rotation order, ZXY; the add-on's own default is XYZ.
bpy.ops.import_scene.import_chan(filepath=chan, rotation_order="ZXY", z_up=True)
frames = [int(line.split()[0]) for line in open(chan) if line.strip() and not line.startswith("#")]
with open(out, "w") as f:
    for frame in frames:
        bpy.context.scene.frame_set(frame)
        m = camera.matrix_world
        f.write(json.dumps({"frame": frame, "matrix": [list(row) for row in m],
                            "angleY": camera.data.angle_y}) + "\n")
