"""Renders a bench/scenes glTF with Blender Cycles on the CPU at several sample counts, timing each.

Run by bench/compare_blender.sh:
  blender -b --factory-startup --python bench/blender_cycles_gltf.py -- \
      SCENE.gltf ENV.hdr|none WIDTH HEIGHT MAX_DEPTH SEED FILTER_GLOSSY OUT_PREFIX SPP [SPP...]
FILTER_GLOSSY: "default" keeps Blender's (1.0), or a number (0 = off).
writes OUT_PREFIX<SPP>.exr (linear float RGB) per sample count and prints, per render,
  CYCLES_RENDER spp=<N> seconds=<time of bpy.ops.render.render>
That time includes Cycles' scene sync, BVH build and film readback (persistent data is off, so
every render syncs and builds again), not Blender's start-up, the glTF import or the file write.

The scene is Blender's own glTF importer's (geometry with the file's normals as custom split
normals, node transforms, +Y up converted to +Z up, the camera's pose). What the importer maps
differently from previs is fixed here, from the glTF JSON itself:
  - materials: the importer builds a Principled BSDF, whose diffuse is Disney's (roughness-
    dependent retro-reflection, not Lambert) and whose Specular input 3.4 maps from
    KHR_materials_specular only approximately. previs's glTF BSDF (gpu/shaders/shared/bsdf.h)
    with metallic 0 and specularFactor 0 is exactly Lambert: a Diffuse BSDF with roughness 0 here.
    Metallic 1: a Principled BSDF, metallic 1, the same roughness and base colour (both F0 =
    base colour; Schlick in previs, Cycles' interpolated Fresnel: equal at normal incidence and
    at grazing, slightly different between). Emitters: an Emission shader of colour
    emissiveFactor and strength KHR_materials_emissive_strength — Cycles' mesh emission of
    strength 1 has radiance equal to its colour, previs's unit too. Any other material is refused.
  - camera: vertical sensor fit with angle_y = yfov (the importer fits the wider side).
  - world: black, or the equirectangular map with closest-texel lookup (previs reads the texel
    containing the direction; Cycles would interpolate). Both use the same orientation
    (DESIGN.md §4) once the importer's Y-up to Z-up turn is applied.
"""
import json
import math
import os
import sys
import time

import bpy
import numpy

# Debian's Blender 3.4 importer still uses numpy.bool, which numpy 1.24 (Debian 12) removed.
if not hasattr(numpy, "bool"):
    numpy.bool = bool

argv = sys.argv[sys.argv.index("--") + 1:]
scene_path, env_path = argv[0], argv[1]
width, height, max_depth, seed = (int(v) for v in argv[2:6])
filter_glossy = argv[6]
out_prefix = argv[7]
spp_list = [int(v) for v in argv[8:]]

bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
bpy.ops.import_scene.gltf(filepath=scene_path)

with open(scene_path) as f:
    gltf = json.load(f)


def material_from_gltf(m):
    pbr = m.get("pbrMetallicRoughness", {})
    ext = m.get("extensions", {})
    color = pbr.get("baseColorFactor", [1.0, 1.0, 1.0, 1.0])
    metallic = pbr.get("metallicFactor", 1.0)
    roughness = pbr.get("roughnessFactor", 1.0)
    specular = ext.get("KHR_materials_specular", {}).get("specularFactor", 1.0)
    emissive = m.get("emissiveFactor", [0.0, 0.0, 0.0])
    strength = ext.get("KHR_materials_emissive_strength", {}).get("emissiveStrength", 1.0)
    out = bpy.data.materials.new(m["name"] + " (previs mapping)")
    out.use_nodes = True
    nodes, links = out.node_tree.nodes, out.node_tree.links
    nodes.clear()
    output = nodes.new("ShaderNodeOutputMaterial")
    if max(emissive) > 0.0:
        if max(color[:3]) > 0.0 or metallic > 0.0:
            sys.exit(f"{m['name']}: only black, non-metallic emitters are mapped")
        node = nodes.new("ShaderNodeEmission")
        node.inputs["Color"].default_value = (*emissive, 1.0)
        node.inputs["Strength"].default_value = strength
        links.new(node.outputs["Emission"], output.inputs["Surface"])
    elif metallic == 0.0 and specular == 0.0:
        node = nodes.new("ShaderNodeBsdfDiffuse")
        node.inputs["Color"].default_value = color
        node.inputs["Roughness"].default_value = 0.0  # Lambert
        links.new(node.outputs["BSDF"], output.inputs["Surface"])
    elif metallic == 1.0:
        node = nodes.new("ShaderNodeBsdfPrincipled")
        node.inputs["Base Color"].default_value = color
        node.inputs["Metallic"].default_value = 1.0
        node.inputs["Roughness"].default_value = roughness
        links.new(node.outputs["BSDF"], output.inputs["Surface"])
    else:
        sys.exit(f"{m['name']}: metallic {metallic}, specular {specular} is not mapped")
    return out


# The importer names its materials after the glTF's (make_scenes.py keeps them unique).
mapped = {m["name"]: material_from_gltf(m) for m in gltf["materials"]}
for obj in scene.objects:
    if obj.type != "MESH":
        continue
    for slot in obj.material_slots:
        name = slot.material.name if slot.material else None
        if name not in mapped:
            sys.exit(f"{obj.name}: material {name!r} is not in {scene_path}")
        slot.material = mapped[name]

cameras = [o for o in scene.objects if o.type == "CAMERA"]
if len(cameras) != 1:
    sys.exit(f"{scene_path}: expected one camera, found {len(cameras)}")
scene.camera = cameras[0]
cam = cameras[0].data
cam.sensor_fit = "VERTICAL"
cam.angle_y = gltf["cameras"][0]["perspective"]["yfov"]
cam.shift_x = cam.shift_y = 0.0

world = bpy.data.worlds.new("previs world")
world.use_nodes = True
nodes = world.node_tree.nodes
nodes.clear()
background = nodes.new("ShaderNodeBackground")
world_out = nodes.new("ShaderNodeOutputWorld")
world.node_tree.links.new(background.outputs["Background"], world_out.inputs["Surface"])
if env_path == "none":
    background.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    background.inputs["Strength"].default_value = 0.0
else:
    tex = nodes.new("ShaderNodeTexEnvironment")
    tex.image = bpy.data.images.load(env_path)
    tex.interpolation = "Closest"
    world.node_tree.links.new(tex.outputs["Color"], background.inputs["Color"])
scene.world = world

c = scene.cycles
scene.render.engine = "CYCLES"
c.device = "CPU"
scene.render.threads_mode = "FIXED"
scene.render.threads = os.cpu_count()
scene.render.use_persistent_data = False
c.use_adaptive_sampling = False
c.use_denoising = False
c.seed = seed
c.max_bounces = max_depth
c.diffuse_bounces = max_depth
c.glossy_bounces = max_depth
c.transmission_bounces = max_depth
c.transparent_max_bounces = max_depth
c.volume_bounces = max_depth
c.sample_clamp_direct = 0.0
c.sample_clamp_indirect = 0.0
# Filter glossy (blur_glossy) roughens glossy surfaces seen after a diffuse bounce: less caustic
# noise, at the price of bias. previs has nothing like it; Blender's default is kept unless asked.
if filter_glossy != "default":
    c.blur_glossy = float(filter_glossy)
# A 1-pixel box filter: previs jitters each sample uniformly in its pixel and averages equally.
c.filter_type = "BOX"
c.filter_width = 1.0
scene.view_settings.view_transform = "Standard"
scene.view_settings.look = "None"
scene.view_settings.exposure = 0.0
scene.view_settings.gamma = 1.0
scene.render.dither_intensity = 0.0
scene.render.film_transparent = False
scene.render.resolution_x = width
scene.render.resolution_y = height
scene.render.resolution_percentage = 100
settings = scene.render.image_settings
settings.file_format = "OPEN_EXR"
settings.color_mode = "RGB"
settings.color_depth = "32"
settings.exr_codec = "ZIP"
print(f"CYCLES_SETTINGS version={bpy.app.version_string} threads={scene.render.threads} "
      f"sampling_pattern={c.sampling_pattern} caustics_reflective={c.caustics_reflective} "
      f"caustics_refractive={c.caustics_refractive} blur_glossy={c.blur_glossy} "
      f"light_sampling_threshold={c.light_sampling_threshold} filter={c.filter_type}:"
      f"{c.filter_width} max_bounces={c.max_bounces} seed={c.seed}", flush=True)

for spp in spp_list:
    c.samples = spp
    start = time.perf_counter()
    bpy.ops.render.render()
    seconds = time.perf_counter() - start
    bpy.data.images["Render Result"].save_render(f"{out_prefix}{spp}.exr")
    print(f"CYCLES_RENDER spp={spp} seconds={seconds:.4f}", flush=True)
