"""Regenerates the light-unit test files: a grey plane under one Blender light each, exported by
Blender's own glTF exporter, and the same scene rendered by Cycles for reference numbers.

  blender -b --factory-startup --python tests/data/light_units/make_light_units.py -- OUT_DIR

Blender 3.4 (Debian's `blender` package). The tests do not need Blender: they read the files this
script wrote, checked in beside it (tests/integrator/test_light_units.cpp).

Scene (Blender's Z-up; glTF's Y-up after export): a 4 m square plane at z = 0 with a Principled
BSDF (base colour 0.8, metallic 0, roughness 1), a 26.6° camera 3 m above its centre looking
straight down (the image spans ±0.7 m of the plane), and one light 1 m above the centre:
  point.gltf  point light, Power 100 W, radius 0 (a true point)
  spot.gltf   spot light, Power 100 W, radius 0, size 45°, blend 0.15, pointing down
  sun.gltf    sun, Strength 3 W/m², angle 0, pointing down
Each is exported with the exporter's default settings (Lighting Mode "Standard", i.e.
convert_lighting_mode='SPEC': physical glTF units, 683 lm/W); only what to include (Include >
Punctual Lights and Cameras, off by default in 3.4) and the container (one .gltf with the buffer
embedded, so each case is a single small file) are chosen.

Cycles reference (cycles.json): the same Blender scene, the plane's material swapped for a Diffuse
BSDF of colour 0.8 (exactly Lambertian, as previs renders metallic 0 / specularFactor 0), direct
light only, 1-px box filter, 32×32 pixels. For each light: the mean linear red value of the
central 8×8 pixels over several seeds, with the standard error of that mean over the seeds.
"""
import json
import math
import os
import sys

import bpy

argv = sys.argv[sys.argv.index("--") + 1:]
out_dir = os.path.abspath(argv[0])
os.makedirs(out_dir, exist_ok=True)

ALBEDO = 0.8
WIDTH = HEIGHT = 32
SEEDS = 16
SPP = 64
CAMERA_HEIGHT_M = 3.0
LIGHT_HEIGHT_M = 1.0
CAMERA_FOV_RAD = 2.0 * math.atan(0.7 / CAMERA_HEIGHT_M)


def build_scene(kind):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    bpy.ops.mesh.primitive_plane_add(size=4.0, location=(0.0, 0.0, 0.0))
    plane = bpy.context.active_object
    plane.name = "plane"
    mat = bpy.data.materials.new("grey")
    mat.use_nodes = True
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (ALBEDO, ALBEDO, ALBEDO, 1.0)
    bsdf.inputs["Metallic"].default_value = 0.0
    bsdf.inputs["Roughness"].default_value = 1.0
    plane.data.materials.append(mat)

    cam_data = bpy.data.cameras.new("camera")
    cam_data.sensor_fit = "VERTICAL"
    cam_data.angle_y = CAMERA_FOV_RAD
    cam = bpy.data.objects.new("camera", cam_data)
    cam.location = (0.0, 0.0, CAMERA_HEIGHT_M)  # default orientation looks down -Z
    scene.collection.objects.link(cam)
    scene.camera = cam

    if kind == "point":
        light = bpy.data.lights.new("point", "POINT")
        light.energy = 100.0
        light.shadow_soft_size = 0.0
    elif kind == "spot":
        light = bpy.data.lights.new("spot", "SPOT")
        light.energy = 100.0
        light.shadow_soft_size = 0.0
        light.spot_size = math.radians(45.0)
        light.spot_blend = 0.15
    else:
        light = bpy.data.lights.new("sun", "SUN")
        light.energy = 3.0
        light.angle = 0.0
    obj = bpy.data.objects.new(kind, light)
    obj.location = (0.0, 0.0, LIGHT_HEIGHT_M)  # lights point down -Z by default
    scene.collection.objects.link(obj)

    scene.render.resolution_x = WIDTH
    scene.render.resolution_y = HEIGHT
    scene.render.resolution_percentage = 100
    return scene, plane


def cycles_centre(scene, plane):
    lambert = bpy.data.materials.new("lambert")
    lambert.use_nodes = True
    nodes, links = lambert.node_tree.nodes, lambert.node_tree.links
    nodes.clear()
    out = nodes.new("ShaderNodeOutputMaterial")
    diffuse = nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (ALBEDO, ALBEDO, ALBEDO, 1.0)
    diffuse.inputs["Roughness"].default_value = 0.0
    links.new(diffuse.outputs["BSDF"], out.inputs["Surface"])
    plane.data.materials[0] = lambert

    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = SPP
    scene.cycles.use_adaptive_sampling = False
    scene.cycles.use_denoising = False
    scene.cycles.max_bounces = 0  # direct light only
    scene.cycles.sample_clamp_direct = 0.0
    scene.cycles.sample_clamp_indirect = 0.0
    scene.cycles.filter_type = "BOX"
    scene.cycles.filter_width = 1.0
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    world = bpy.data.worlds.new("black")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    scene.world = world

    means = []
    for seed in range(SEEDS):
        scene.cycles.seed = seed + 1
        bpy.ops.render.render()
        image = bpy.data.images["Render Result"]
        path = os.path.join(out_dir, "_cycles_tmp.exr")
        scene.render.image_settings.file_format = "OPEN_EXR"
        scene.render.image_settings.color_depth = "32"
        image.save_render(path)
        loaded = bpy.data.images.load(path)
        px = list(loaded.pixels)  # RGBA, bottom row first
        w, h = loaded.size
        total = 0.0
        for y in range(h // 2 - 4, h // 2 + 4):
            for x in range(w // 2 - 4, w // 2 + 4):
                total += px[(y * w + x) * 4]
        means.append(total / 64.0)
        bpy.data.images.remove(loaded)
        os.remove(path)
    mean = sum(means) / len(means)
    var = sum((m - mean) ** 2 for m in means) / (len(means) - 1) / len(means)
    return mean, math.sqrt(var)


results = {"albedo": ALBEDO, "width": WIDTH, "height": HEIGHT, "spp": SPP, "seeds": SEEDS,
           "blender": bpy.app.version_string, "window": "central 8x8 pixels, red channel"}
for kind in ("point", "spot", "sun"):
    scene, plane = build_scene(kind)
    path = os.path.join(out_dir, kind + ".gltf")
    # Default settings apart from what to include (3.4 leaves lights and cameras out unless
    # asked) and the container (one embedded .gltf instead of a .glb).
    bpy.ops.export_scene.gltf(filepath=path, export_format="GLTF_EMBEDDED", export_lights=True,
                              export_cameras=True)
    mean, stderr = cycles_centre(scene, plane)
    results[kind] = {"mean": mean, "standardError": stderr}
    print(f"LIGHT_UNITS {kind} cycles centre mean {mean:.6f} +- {stderr:.6f}")

with open(os.path.join(out_dir, "cycles.json"), "w") as f:
    json.dump(results, f, indent=2)
    f.write("\n")
