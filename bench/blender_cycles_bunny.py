"""Renders previs's benchmark scene "bunny" with Blender Cycles on the CPU and prints the time.

Run by bench/compare_blender.sh:  blender -b --factory-startup --python bench/blender_cycles_bunny.py -- \
    MESH.ply ENV.hdr WIDTH HEIGHT SPP MAX_DEPTH OUT.png
The scene matches bench/bench_scenes.cpp's bunnyScene(): the Stanford bunny (Lambertian, albedo 0.8)
on a 2 m Lambertian plane (albedo 0.5) at the bunny's lowest point, lit only by the environment map,
seen by a 40° (vertical) pinhole camera. previs is +Y up, Blender +Z up: (x, y, z) -> (x, -z, y).
"""
import math
import sys
import time

import bpy
from mathutils import Matrix, Vector

argv = sys.argv[sys.argv.index("--") + 1:]
mesh_path, env_path = argv[0], argv[1]
width, height, spp, max_depth = (int(v) for v in argv[2:6])
out_path = argv[6]

Y_UP_TO_Z_UP = Matrix.Rotation(math.radians(90.0), 4, "X")

bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene

bpy.ops.import_mesh.ply(filepath=mesh_path)
bunny = bpy.context.selected_objects[0]
bunny.matrix_world = Y_UP_TO_Z_UP
ys = [v.co.y for v in bunny.data.vertices]  # PLY is +Y up
floor_y = min(ys)


def diffuse(name, albedo):
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    nodes = m.node_tree.nodes
    nodes.clear()
    out = nodes.new("ShaderNodeOutputMaterial")
    bsdf = nodes.new("ShaderNodeBsdfDiffuse")
    bsdf.inputs["Color"].default_value = (albedo, albedo, albedo, 1.0)
    bsdf.inputs["Roughness"].default_value = 0.0  # Lambert
    m.node_tree.links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
    return m


bunny.data.materials.append(diffuse("bunny", 0.8))
bpy.ops.mesh.primitive_plane_add(size=2.0, location=(0.0, 0.0, floor_y))
plane = bpy.context.active_object
plane.data.materials.append(diffuse("floor", 0.5))

world = bpy.data.worlds.new("env")
world.use_nodes = True
nodes = world.node_tree.nodes
nodes.clear()
tex = nodes.new("ShaderNodeTexEnvironment")
tex.image = bpy.data.images.load(env_path)
bg = nodes.new("ShaderNodeBackground")
wout = nodes.new("ShaderNodeOutputWorld")
world.node_tree.links.new(tex.outputs["Color"], bg.inputs["Color"])
world.node_tree.links.new(bg.outputs["Background"], wout.inputs["Surface"])
scene.world = world

# Camera: previs bench's eye/target in previs coordinates, converted.
eye = Vector((0.0, 0.16, 0.42))
target = Vector((-0.015, 0.1, 0.0))
to_z_up = lambda v: Vector((v.x, -v.z, v.y))
cam_data = bpy.data.cameras.new("cam")
cam_data.sensor_fit = "VERTICAL"
cam_data.angle_y = math.radians(40.0)
cam = bpy.data.objects.new("cam", cam_data)
scene.collection.objects.link(cam)
cam.location = to_z_up(eye)
direction = to_z_up(target) - to_z_up(eye)
cam.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()
scene.camera = cam

scene.render.engine = "CYCLES"
scene.cycles.device = "CPU"
scene.cycles.samples = spp
scene.cycles.use_adaptive_sampling = False
scene.cycles.use_denoising = False
scene.cycles.max_bounces = max_depth
scene.cycles.diffuse_bounces = max_depth
scene.cycles.glossy_bounces = max_depth
scene.cycles.transmission_bounces = max_depth
scene.cycles.caustics_reflective = True
scene.cycles.caustics_refractive = True
scene.cycles.sample_clamp_direct = 0.0
scene.cycles.sample_clamp_indirect = 0.0
scene.render.resolution_x = width
scene.render.resolution_y = height
scene.render.resolution_percentage = 100
scene.render.filepath = out_path

start = time.perf_counter()
bpy.ops.render.render(write_still=True)
seconds = time.perf_counter() - start
print(f"CYCLES_SECONDS {seconds:.3f} threads {scene.render.threads}")
