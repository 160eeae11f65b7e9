#!/usr/bin/env python3
"""Writes the glTF scenes that bench/compare_blender.sh renders with previs and with Blender Cycles.

  make_scenes.py area-lights OUT.gltf        the committed bench/scenes/area_lights_mirror.gltf
  make_scenes.py caustics OUT.gltf           the committed bench/scenes/caustics_glass.gltf
  make_scenes.py bunny DATA_DIR OUT.gltf     bench_scenes.cpp's bunnyScene() as glTF (generated
                                             into build/: the 69K-triangle mesh is not committed)
  make_scenes.py dragon DATA_DIR OUT.gltf    the throughput benchmark's 810K-triangle "dragon ×4"
                                             (bench_scenes.cpp's subdivide + meshOnPlaneScene)

Both renderers load the very same file, so geometry, normals, camera and materials agree by
construction. Materials use only what both map the same way (bench/blender_cycles_gltf.py says
how Blender's side is built):
  - Lambertian: metallic 0 and KHR_materials_specular specularFactor 0 (previs: no specular
    layer, pure Lambert; see gpu/shaders/shared/bsdf.h);
  - perfect mirror: metallic 1, roughness 0;
  - emitter: baseColor black (reflects nothing), emissiveFactor × KHR_materials_emissive_strength
    = radiance (previs's unit, scene/gltf_loader.cpp), doubleSided (Cycles' mesh lights emit from
    both faces; previs only from the front unless doubleSided).
Units are metres, +Y up (glTF).
"""
import math
import struct
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "scripts"))
from make_example_scene import Builder, box, sphere  # noqa: E402


def add_material(g, name, color, metallic=0.0, roughness=1.0, emission=None, double_sided=False):
    """Lambertian unless metallic; emission = (rgb factor, strength)."""
    m = {"name": name, "pbrMetallicRoughness": {
        "baseColorFactor": list(color) + [1.0], "metallicFactor": metallic,
        "roughnessFactor": roughness}}
    ext = {}
    if metallic == 0.0:
        ext["KHR_materials_specular"] = {"specularFactor": 0.0}
    if emission is not None:
        m["emissiveFactor"] = list(emission[0])
        ext["KHR_materials_emissive_strength"] = {"emissiveStrength": emission[1]}
    if ext:
        m["extensions"] = ext
    if double_sided:
        m["doubleSided"] = True
    g.gltf["materials"].append(m)
    return len(g.gltf["materials"]) - 1


def new_builder():
    g = Builder()
    g.gltf["asset"]["generator"] = "previs bench/scenes/make_scenes.py"
    g.gltf["extensionsUsed"] = ["KHR_materials_specular", "KHR_materials_emissive_strength"]
    del g.gltf["extensions"]  # no punctual lights
    return g


def look_at_quaternion(eye, target):
    """Rotation (x, y, z, w) of a glTF camera node at `eye` looking at `target`, +Y up: the camera
    looks along its -Z, as glm::inverse(glm::lookAt(eye, target, up)) in bench_scenes.cpp."""
    f = [t - e for t, e in zip(target, eye)]
    n = math.sqrt(sum(c * c for c in f))
    f = [c / n for c in f]
    up = (0.0, 1.0, 0.0)
    x = [f[1] * up[2] - f[2] * up[1], f[2] * up[0] - f[0] * up[2], f[0] * up[1] - f[1] * up[0]]
    n = math.sqrt(sum(c * c for c in x))
    x = [c / n for c in x]
    y = [x[1] * f[2] - x[2] * f[1], x[2] * f[0] - x[0] * f[2], x[0] * f[1] - x[1] * f[0]]
    z = [-c for c in f]
    # Columns x, y, z of the rotation matrix to a quaternion (Shepperd's method).
    m = [[x[0], y[0], z[0]], [x[1], y[1], z[1]], [x[2], y[2], z[2]]]
    tr = m[0][0] + m[1][1] + m[2][2]
    if tr > 0:
        s = 2.0 * math.sqrt(1.0 + tr)
        return [(m[2][1] - m[1][2]) / s, (m[0][2] - m[2][0]) / s, (m[1][0] - m[0][1]) / s, s / 4]
    i = max(range(3), key=lambda k: m[k][k])
    j, k = (i + 1) % 3, (i + 2) % 3
    s = 2.0 * math.sqrt(1.0 + m[i][i] - m[j][j] - m[k][k])
    q = [0.0, 0.0, 0.0, (m[k][j] - m[j][k]) / s]
    q[i] = s / 4
    q[j] = (m[j][i] + m[i][j]) / s
    q[k] = (m[k][i] + m[i][k]) / s
    return q


def add_camera(g, eye, target, yfov_deg=40.0):
    g.gltf["cameras"].append({"name": "bench", "type": "perspective", "perspective": {
        "yfov": math.radians(yfov_deg), "aspectRatio": 4 / 3, "znear": 0.01}})
    g.node("bench", camera=0, translation=list(eye), rotation=look_at_quaternion(eye, target))


def quad_xz(hx, hz):
    """A quad in the y = 0 plane facing +Y."""
    pos = [(-hx, 0, -hz), (hx, 0, -hz), (hx, 0, hz), (-hx, 0, hz)]
    return pos, [(0, 1, 0)] * 4, [0, 2, 1, 0, 3, 2]


def area_lights_scene(out):
    """A floor and a back wall (grey Lambert), a reddish Lambertian cube, a mirror sphere and two
    0.2 m × 0.2 m ceiling-height emitters just outside the frame (seen in the mirror), no
    environment: the light reaches most of the image through a small emitter, which is what
    light sampling of small area lights must get right."""
    g = new_builder()
    grey = add_material(g, "grey lambert", (0.6, 0.6, 0.6))
    red = add_material(g, "red lambert", (0.7, 0.25, 0.2))
    mirror = add_material(g, "mirror", (0.95, 0.95, 0.95), metallic=1.0, roughness=0.0)
    # Radiance 40: with two 0.04 m² emitters about 1 m above the floor, the floor's radiance is
    # ≈ 0.6/π · 2 · 40 · 0.04 ≈ 0.6, well exposed at exposure 0.
    warm = add_material(g, "warm emitter", (0, 0, 0), emission=((1.0, 0.9, 0.8), 40.0),
                        double_sided=True)
    cool = add_material(g, "cool emitter", (0, 0, 0), emission=((0.8, 0.9, 1.0), 40.0),
                        double_sided=True)
    g.node("Floor", mesh=g.mesh("floor", *quad_xz(1.5, 1.5), grey))
    # The back wall: the floor quad stood up, facing +Z.
    half = math.sqrt(0.5)
    g.node("BackWall", mesh=g.mesh("back wall", *quad_xz(1.5, 0.75), grey),
           translation=[0.0, 0.75, -0.8], rotation=[half, 0.0, 0.0, half])
    yaw = math.radians(30.0)
    g.node("Cube", mesh=g.mesh("cube", *box(0.15, 0.15, 0.15), red),
           translation=[-0.35, 0.15, -0.15], rotation=[0, math.sin(yaw / 2), 0, math.cos(yaw / 2)])
    g.node("MirrorSphere", mesh=g.mesh("mirror sphere", *sphere(0.2, 64, 128), mirror),
           translation=[0.3, 0.2, 0.05])
    # Facing down: the quad turned over about X.
    for name, material, xz in (("WarmLight", warm, (-0.4, 0.25)), ("CoolLight", cool, (0.5, -0.3))):
        g.node(name, mesh=g.mesh(name.lower(), *quad_xz(0.1, 0.1), material),
               translation=[xz[0], 1.0, xz[1]], rotation=[1.0, 0.0, 0.0, 0.0])
    add_camera(g, (0.0, 0.6, 1.8), (0.0, 0.25, 0.0))
    g.write(out)


def caustics_scene(out):
    """The photon-mapping benchmark (issue 9): a virtual glass ball (IOR 1.5, smooth) and a virtual
    Lambertian cube on a real table top with a real back wall, lit by one small real emitter
    (4 cm × 4 cm) above and behind the ball: the ball throws a focused caustic on the table that a
    path tracer reaches only by hitting the small emitter through the glass."""
    g = new_builder()
    g.gltf["extensionsUsed"] += ["KHR_materials_transmission", "KHR_materials_ior",
                                 "KHR_materials_volume"]
    grey = add_material(g, "table lambert", (0.6, 0.6, 0.6))
    wall = add_material(g, "wall lambert", (0.5, 0.5, 0.5))
    red = add_material(g, "red lambert", (0.7, 0.25, 0.2))
    g.gltf["materials"].append({
        "name": "glass", "pbrMetallicRoughness": {
            "baseColorFactor": [1.0, 1.0, 1.0, 1.0], "metallicFactor": 0.0, "roughnessFactor": 0.0},
        # A volume (thickness > 0): a solid ball that refracts, not a thin-walled bubble
        # (glTF's rule without KHR_materials_volume; docs/scene-format.md).
        "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1.0},
                       "KHR_materials_ior": {"ior": 1.5},
                       "KHR_materials_volume": {"thicknessFactor": 0.24}}})
    glass = len(g.gltf["materials"]) - 1
    # Radiance 2000 over 0.0016 m²: about 1 m away it gives the table a radiance near 0.6.
    lamp = add_material(g, "lamp", (0, 0, 0), emission=((1.0, 0.95, 0.9), 2000.0))
    g.node("Table", real=True, mesh=g.mesh("table", *quad_xz(1.0, 0.8), grey))
    half = math.sqrt(0.5)
    g.node("BackWall", real=True, mesh=g.mesh("back wall", *quad_xz(1.0, 0.6), wall),
           translation=[0.0, 0.6, -0.8], rotation=[half, 0.0, 0.0, half])
    g.node("GlassBall", mesh=g.mesh("glass ball", *sphere(0.12, 64, 128), glass),
           translation=[0.05, 0.12, 0.0])
    yaw = math.radians(25.0)
    g.node("Cube", mesh=g.mesh("cube", *box(0.08, 0.08, 0.08), red),
           translation=[-0.35, 0.08, -0.2], rotation=[0, math.sin(yaw / 2), 0, math.cos(yaw / 2)])
    g.node("Lamp", real=True, mesh=g.mesh("lamp", *quad_xz(0.02, 0.02), lamp),
           translation=[-0.25, 0.9, -0.35], rotation=[1.0, 0.0, 0.0, 0.0])
    add_camera(g, (0.0, 0.55, 1.3), (0.0, 0.1, 0.0))
    g.write(out)


def read_ply(path):
    """Binary little-endian PLY: float x, y, z vertices and uchar-count int/uint faces."""
    data = Path(path).read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode("ascii").splitlines()
    if "format binary_little_endian 1.0" not in header:
        sys.exit(f"{path}: expected a binary little-endian PLY")
    counts, props = {}, {}
    element = None
    for line in header:
        words = line.split()
        if words[:1] == ["element"]:
            element = words[1]
            counts[element] = int(words[2])
            props[element] = []
        elif words[:1] == ["property"]:
            props[element].append(words[1:])
    if props["vertex"] != [["float", "x"], ["float", "y"], ["float", "z"]]:
        sys.exit(f"{path}: expected vertices with float x, y, z only, got {props['vertex']}")
    if len(props["face"]) != 1 or props["face"][0][1] != "uchar":
        sys.exit(f"{path}: expected one uchar-counted face list, got {props['face']}")
    nv = counts["vertex"]
    positions = list(struct.iter_unpack("<3f", data[end:end + 12 * nv]))
    index_format = {"int": "<3i", "uint": "<3I"}[props["face"][0][2]]
    triangles, offset = [], end + 12 * nv
    for _ in range(counts["face"]):
        if data[offset] != 3:
            sys.exit(f"{path}: a face with {data[offset]} vertices (triangles only)")
        triangles.append(struct.unpack_from(index_format, data, offset + 1))
        offset += 13
    return positions, triangles


def smooth_normals(positions, triangles):
    """Area-weighted vertex normals, as bench_scenes.cpp's appendMesh()."""
    acc = [[0.0, 0.0, 0.0] for _ in positions]
    for t in triangles:
        a, b, c = (positions[i] for i in t)
        e1 = [b[k] - a[k] for k in range(3)]
        e2 = [c[k] - a[k] for k in range(3)]
        n = (e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
             e1[0] * e2[1] - e1[1] * e2[0])
        for i in t:
            for k in range(3):
                acc[i][k] += n[k]
    out = []
    for n in acc:
        length = math.sqrt(sum(c * c for c in n))
        out.append(tuple(c / length for c in n) if length > 0 else (0.0, 1.0, 0.0))
    return out


def bunny_scene(data_dir, out):
    """bench_scenes.cpp bunnyScene(): the Stanford bunny at its own scale (Lambert 0.8) on a 2 m
    Lambertian plane (0.5) at its lowest point, the same 40° camera; the environment map
    (rooitou_park_1k.hdr) is given to each renderer on its command line."""
    positions, triangles = read_ply(Path(data_dir) / "meshes" / "stanford_bunny.ply")
    floor_y = min(p[1] for p in positions)
    g = new_builder()
    floor = add_material(g, "floor lambert", (0.5, 0.5, 0.5))
    bunny = add_material(g, "bunny lambert", (0.8, 0.8, 0.8))
    plane, plane_normals, plane_indices = quad_xz(1.0, 1.0)
    g.node("Floor", mesh=g.mesh("floor", plane, plane_normals, plane_indices, floor),
           translation=[0.0, floor_y, 0.0])
    g.node("Bunny", mesh=g.mesh("bunny", positions, smooth_normals(positions, triangles),
                                [i for t in triangles for i in t], bunny))
    add_camera(g, (0.0, 0.16, 0.42), (-0.015, 0.1, 0.0))
    g.write(out)


def subdivide(positions, triangles):
    """bench_scenes.cpp subdivide(): each triangle split 1 → 4 at its edges' midpoints (shared
    per edge), in the same order, so the mesh is the throughput benchmark's."""
    positions = list(positions)
    midpoints = {}

    def mid(a, b):
        key = (min(a, b), max(a, b))
        if key not in midpoints:
            midpoints[key] = len(positions)
            pa, pb = positions[a], positions[b]
            positions.append(tuple(0.5 * (pa[k] + pb[k]) for k in range(3)))
        return midpoints[key]

    out = []
    for a, b, c in triangles:
        ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
        out += [(a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca)]
    return positions, out


def dragon_scene(data_dir, out, height=0.3):
    """bench_scenes.cpp meshOnPlaneScene(subdivide(dragon_vrip_res2.ply), env, 0.3): the dragon
    scaled to 0.3 m tall, centred on a 2 m Lambertian plane (0.5) at its lowest point, Lambert 0.8,
    the same 40° camera; the environment map is given on each renderer's command line."""
    positions, triangles = subdivide(*read_ply(Path(data_dir) / "meshes" / "dragon_vrip_res2.ply"))
    lo = [min(p[k] for p in positions) for k in range(3)]
    hi = [max(p[k] for p in positions) for k in range(3)]
    scale = height / max(hi[1] - lo[1], 1e-9)
    shift = (0.5 * (lo[0] + hi[0]), lo[1], 0.5 * (lo[2] + hi[2]))
    positions = [tuple(scale * (p[k] - shift[k]) for k in range(3)) for p in positions]
    g = new_builder()
    floor = add_material(g, "floor lambert", (0.5, 0.5, 0.5))
    dragon = add_material(g, "dragon lambert", (0.8, 0.8, 0.8))
    plane, plane_normals, plane_indices = quad_xz(1.0, 1.0)
    g.node("Floor", mesh=g.mesh("floor", plane, plane_normals, plane_indices, floor))
    g.node("Dragon", mesh=g.mesh("dragon", positions, smooth_normals(positions, triangles),
                                 [i for t in triangles for i in t], dragon))
    add_camera(g, (0.0, 0.55 * height, 1.45 * height), (0.0, 0.45 * height, 0.0))
    g.write(out)


if __name__ == "__main__":
    if sys.argv[1:2] == ["area-lights"] and len(sys.argv) == 3:
        area_lights_scene(sys.argv[2])
    elif sys.argv[1:2] == ["caustics"] and len(sys.argv) == 3:
        caustics_scene(sys.argv[2])
    elif sys.argv[1:2] == ["bunny"] and len(sys.argv) == 4:
        bunny_scene(sys.argv[2], sys.argv[3])
    elif sys.argv[1:2] == ["dragon"] and len(sys.argv) == 4:
        dragon_scene(sys.argv[2], sys.argv[3])
    else:
        sys.exit(__doc__)
