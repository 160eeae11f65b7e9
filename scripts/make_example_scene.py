#!/usr/bin/env python3
"""Writes examples/cubes_spheres/scene.gltf: the paper's second test scene in miniature.

Real phantoms (a table top and three cubes, marked {"previs": {"role": "real"}}) and virtual
objects (a metal sphere, a glass sphere, a diffuse sphere), lit by a rectangular area light and a
point light, seen by one perspective camera. Units are metres, +Y up (glTF). Run it again after
changing it; the .gltf is committed so the example needs nothing generated at build time.
"""
import base64
import json
import math
import struct
import sys
from pathlib import Path


class Builder:
    def __init__(self):
        self.data = bytearray()
        self.gltf = {
            "asset": {"version": "2.0", "generator": "previs make_example_scene.py"},
            "extensionsUsed": ["KHR_lights_punctual", "KHR_materials_transmission",
                               "KHR_materials_ior", "KHR_materials_volume",
                               "KHR_materials_emissive_strength"],
            "scene": 0, "scenes": [{"nodes": []}], "nodes": [], "meshes": [], "materials": [],
            "accessors": [], "bufferViews": [], "buffers": [],
            "cameras": [], "extensions": {"KHR_lights_punctual": {"lights": []}},
        }

    def _view(self, payload, target):
        while len(self.data) % 4:
            self.data.append(0)
        offset = len(self.data)
        self.data += payload
        self.gltf["bufferViews"].append(
            {"buffer": 0, "byteOffset": offset, "byteLength": len(payload), "target": target})
        return len(self.gltf["bufferViews"]) - 1

    def _accessor(self, view, ctype, count, atype, lo=None, hi=None):
        acc = {"bufferView": view, "componentType": ctype, "count": count, "type": atype}
        if lo is not None:
            acc["min"], acc["max"] = lo, hi
        self.gltf["accessors"].append(acc)
        return len(self.gltf["accessors"]) - 1

    def mesh(self, name, positions, normals, indices, material):
        pos = self._view(b"".join(struct.pack("<3f", *p) for p in positions), 34962)
        nrm = self._view(b"".join(struct.pack("<3f", *n) for n in normals), 34962)
        idx = self._view(b"".join(struct.pack("<I", i) for i in indices), 34963)
        lo = [min(p[k] for p in positions) for k in range(3)]
        hi = [max(p[k] for p in positions) for k in range(3)]
        prim = {"attributes": {"POSITION": self._accessor(pos, 5126, len(positions), "VEC3", lo, hi),
                               "NORMAL": self._accessor(nrm, 5126, len(normals), "VEC3")},
                "indices": self._accessor(idx, 5125, len(indices), "SCALAR"),
                "material": material}
        self.gltf["meshes"].append({"name": name, "primitives": [prim]})
        return len(self.gltf["meshes"]) - 1

    def material(self, name, **kw):
        m = {"name": name, "pbrMetallicRoughness": {
            "baseColorFactor": kw.get("color", [0.8, 0.8, 0.8, 1.0]),
            "metallicFactor": kw.get("metallic", 0.0),
            "roughnessFactor": kw.get("roughness", 0.8)}}
        ext = {}
        if "transmission" in kw:
            ext["KHR_materials_transmission"] = {"transmissionFactor": kw["transmission"]}
            ext["KHR_materials_ior"] = {"ior": kw.get("ior", 1.5)}
        if "thickness" in kw:
            # A solid that refracts; without KHR_materials_volume glTF means a thin wall.
            ext["KHR_materials_volume"] = {"thicknessFactor": kw["thickness"]}
        if "emission" in kw:
            m["emissiveFactor"] = [1.0, 1.0, 1.0]
            ext["KHR_materials_emissive_strength"] = {"emissiveStrength": kw["emission"]}
        if ext:
            m["extensions"] = ext
        self.gltf["materials"].append(m)
        return len(self.gltf["materials"]) - 1

    def node(self, name, real=False, **kw):
        n = {"name": name, **kw}
        if real:
            n["extras"] = {"previs": {"role": "real"}}
        self.gltf["nodes"].append(n)
        self.gltf["scenes"][0]["nodes"].append(len(self.gltf["nodes"]) - 1)

    def write(self, path):
        self.gltf["buffers"] = [{"byteLength": len(self.data), "uri":
            "data:application/octet-stream;base64," + base64.b64encode(self.data).decode()}]
        Path(path).write_text(json.dumps(self.gltf, indent=1) + "\n")


def box(hx, hy, hz):
    pos, nrm, idx = [], [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            n = [0.0, 0.0, 0.0]
            n[axis] = sign
            u, v = [(1, 2), (2, 0), (0, 1)][axis]
            base = len(pos)
            for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                p = [0.0, 0.0, 0.0]
                p[axis] = sign
                p[u], p[v] = a, b
                pos.append((p[0] * hx, p[1] * hy, p[2] * hz))
                nrm.append(tuple(n))
            quad = [0, 1, 2, 0, 2, 3] if sign > 0 else [0, 2, 1, 0, 3, 2]
            idx += [base + q for q in quad]
    return pos, nrm, idx


def sphere(r, rings=24, segments=48):
    pos, nrm, idx = [], [], []
    for i in range(rings + 1):
        theta = math.pi * i / rings
        for j in range(segments + 1):
            phi = 2 * math.pi * j / segments
            n = (math.sin(theta) * math.cos(phi), math.cos(theta), math.sin(theta) * math.sin(phi))
            pos.append(tuple(r * c for c in n))
            nrm.append(n)
    for i in range(rings):
        for j in range(segments):
            a = i * (segments + 1) + j
            b = a + segments + 1
            # The first and last rings meet at the poles: one triangle per quad there.
            if i != 0:
                idx += [a, a + 1, b]
            if i != rings - 1:
                idx += [a + 1, b + 1, b]
    return pos, nrm, idx


def main(out):
    g = Builder()
    table = g.material("table", color=[0.7, 0.62, 0.5, 1.0], roughness=0.9)
    paper = g.material("paper", color=[0.85, 0.85, 0.82, 1.0], roughness=1.0)
    metal = g.material("metal", color=[0.95, 0.93, 0.88, 1.0], metallic=1.0, roughness=0.05)
    glass = g.material("glass", color=[1.0, 1.0, 1.0, 1.0], roughness=0.0, transmission=1.0,
                       thickness=0.12)
    red = g.material("red plastic", color=[0.8, 0.1, 0.08, 1.0], roughness=0.4)
    lamp = g.material("softbox", color=[0.0, 0.0, 0.0, 1.0], emission=12.0)

    g.node("Table", real=True, mesh=g.mesh("table", *box(0.6, 0.02, 0.4), table),
           translation=[0, -0.02, 0])
    for k, (x, z, s, yaw) in enumerate([(-0.35, -0.1, 0.06, 20), (-0.2, 0.12, 0.05, -35),
                                        (-0.42, 0.15, 0.04, 60)]):
        q = [0, math.sin(math.radians(yaw) / 2), 0, math.cos(math.radians(yaw) / 2)]
        g.node(f"Cube{k}", real=True, mesh=g.mesh(f"cube{k}", *box(s, s, s), paper),
               translation=[x, s, z], rotation=q)
    g.node("MetalSphere", mesh=g.mesh("metal sphere", *sphere(0.08), metal),
           translation=[0.1, 0.08, -0.05])
    g.node("GlassSphere", mesh=g.mesh("glass sphere", *sphere(0.06), glass),
           translation=[0.3, 0.06, 0.12])
    g.node("RedSphere", mesh=g.mesh("red sphere", *sphere(0.05), red),
           translation=[0.05, 0.05, 0.2])
    # A softbox above the set, facing down (the box's -Y face points at the table).
    # The set's lights are real: they light the real-only solution too.
    g.node("Softbox", real=True, mesh=g.mesh("softbox", *box(0.25, 0.005, 0.15), lamp),
           translation=[0.0, 0.9, 0.1])
    # KHR_lights_punctual intensities are candela: 0.6 W/sr × 683 lm/W (docs/scene-format.md).
    g.gltf["extensions"]["KHR_lights_punctual"]["lights"].append(
        {"name": "key", "type": "point", "color": [1.0, 0.9, 0.8], "intensity": 409.8})
    g.node("KeyLight", real=True, extensions={"KHR_lights_punctual": {"light": 0}},
           translation=[0.6, 0.7, 0.6])
    g.gltf["cameras"].append({"name": "SceneCamera", "type": "perspective", "perspective":
                              {"yfov": math.radians(40), "aspectRatio": 4 / 3, "znear": 0.01}})
    # Camera 1 m away, 0.45 m up, looking down at the table centre.
    pitch = -math.atan2(0.45, 1.0)
    g.node("SceneCamera", camera=0, translation=[0.0, 0.45, 1.0],
           rotation=[math.sin(pitch / 2), 0, 0, math.cos(pitch / 2)])
    g.write(out)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "examples/cubes_spheres/scene.gltf")
