#!/usr/bin/env python3
"""Writes scenes/gltf/showcase.glb, the glTF of scenes/gltf-showcase.toml: a floor with an embedded 8 x 8 checker
texture (tiled 4 x 4) and a normal texture of one pillow per checker cell, read in the frame of the floor's
TANGENT attribute; a rough gold sphere (metallic 1, roughness 0.35), a rough glass sphere and a smooth glass
sphere (KHR_materials_transmission, KHR_materials_ior 1.5, roughness 0.3 and 0); behind them a lattice screen,
a cut-out (alphaMode MASK) whose base colour texture's alpha opens round holes; a perspective camera; and a
KHR_lights_punctual spot light above the gold sphere. The spot's cone leaves out the smooth glass sphere, so the
scene has no caustic of a point-like light through smooth glass, which no camera path can complete (the path
tracer's image of it converges to the same as bdpt's). About 60 KB.

    python3 tools/make_gltf.py                      # from the repository root
    python3 tools/make_gltf.py -o /tmp/showcase.glb

Python 3 standard library only (the PNG through zlib, the GLB through struct).
"""

import argparse
import json
import math
import struct
import zlib
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def png(width, height, texel, channels=3):
    """An 8-bit RGB (or, with channels=4, RGBA) PNG; texel(x, y) gives (r, g, b[, a]) with y from the top."""
    raw = b"".join(b"\0" + bytes(c for x in range(width) for c in texel(x, y)) for y in range(height))

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    header = struct.pack(">IIBBBBB", width, height, 8, 2 if channels == 3 else 6, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b"")


def sphere(radius=1.0, nu=32, nv=16):
    """Positions, normals and UVs on a (nu + 1) x (nv + 1) latitude-longitude grid, and triangles wound
    counter-clockwise seen from outside (glTF's front)."""
    pos, nor, uv = [], [], []
    for j in range(nv + 1):
        theta = math.pi * j / nv
        for i in range(nu + 1):
            phi = 2 * math.pi * i / nu
            n = (math.sin(theta) * math.cos(phi), math.cos(theta), -math.sin(theta) * math.sin(phi))
            nor.append(n)
            pos.append(tuple(radius * c for c in n))
            uv.append((i / nu, j / nv))
    tris = []
    for j in range(nv):
        for i in range(nu):
            a, b = j * (nu + 1) + i, (j + 1) * (nu + 1) + i
            if j > 0:
                tris.append((a, b, a + 1))
            if j < nv - 1:
                tris.append((a + 1, b, b + 1))
    return pos, nor, uv, tris


def floor(half=4.0, tiles=4.0):
    """A square in y = 0 facing +y, its UVs tiling the texture `tiles` times."""
    pos = [(-half, 0, half), (half, 0, half), (half, 0, -half), (-half, 0, -half)]
    nor = [(0, 1, 0)] * 4
    uv = [(0, tiles), (tiles, tiles), (tiles, 0), (0, 0)]
    return pos, nor, uv, [(0, 1, 2), (0, 2, 3)]


def screen(z=-1.6, half_width=3.5, height=2.4, hole=0.6):
    """A vertical rectangle in the plane z, facing +z, from the floor up to `height`; its UVs tile the lattice
    texture once every `hole` units, the image's top-left at the top-left corner."""
    pos = [(-half_width, 0, z), (half_width, 0, z), (half_width, height, z), (-half_width, height, z)]
    nor = [(0, 0, 1)] * 4
    u, v = 2 * half_width / hole, height / hole
    uv = [(0, v), (u, v), (u, 0), (0, 0)]
    return pos, nor, uv, [(0, 1, 2), (0, 2, 3)]


def pillow_normals(n=64, cells=8, strength=0.08):
    """A tangent-space normal texture (glTF: x right, y up in the image) of n x n texels: a pillow
    h = strength * sin(pi a) sin(pi b) in each of cells x cells cells, stored as (normal + 1) / 2."""
    def texel(x, y):
        side = n // cells
        a = (x % side + 0.5) / side
        b = 1.0 - (y % side + 0.5) / side
        dx = strength * math.pi * math.cos(math.pi * a) * math.sin(math.pi * b)
        dy = strength * math.pi * math.sin(math.pi * a) * math.cos(math.pi * b)
        norm = math.sqrt(dx * dx + dy * dy + 1.0)
        return tuple(round(255 * (c / norm + 1) / 2) for c in (-dx, -dy, 1.0))
    return png(n, n, texel)


def lattice(n=64, radius=0.36):
    """An RGBA texture of one round hole (alpha 0) of `radius` (in tiles) in a pale wooden tile (alpha 1)."""
    def texel(x, y):
        r = math.hypot((x + 0.5) / n - 0.5, (y + 0.5) / n - 0.5)
        grain = 215 + round(20 * math.sin(40 * (y + 0.5) / n))
        return (grain, grain, grain, 0 if r < radius else 255)
    return png(n, n, texel, channels=4)


class Buffer:
    """The binary chunk, its buffer views and accessors."""

    def __init__(self):
        self.data, self.views, self.accessors = bytearray(), [], []

    def view(self, blob):
        while len(self.data) % 4:
            self.data.append(0)
        self.views.append({"buffer": 0, "byteOffset": len(self.data), "byteLength": len(blob)})
        self.data += blob
        return len(self.views) - 1

    def floats(self, rows, kind):
        flat = [c for r in rows for c in r]
        view = self.view(struct.pack(f"<{len(flat)}f", *flat))
        acc = {"bufferView": view, "componentType": 5126, "count": len(rows), "type": kind}
        if kind == "VEC3":
            acc["min"] = [min(r[k] for r in rows) for k in range(3)]
            acc["max"] = [max(r[k] for r in rows) for k in range(3)]
        self.accessors.append(acc)
        return len(self.accessors) - 1

    def indices(self, tris):
        flat = [i for t in tris for i in t]
        view = self.view(struct.pack(f"<{len(flat)}H", *flat))
        self.accessors.append({"bufferView": view, "componentType": 5123, "count": len(flat), "type": "SCALAR"})
        return len(self.accessors) - 1

    def primitive(self, mesh, material, tangent=None):
        """A triangle primitive; `tangent` (x, y, z, w), when given, is every vertex's TANGENT."""
        pos, nor, uv, tris = mesh
        attributes = {"POSITION": self.floats(pos, "VEC3"), "NORMAL": self.floats(nor, "VEC3"),
                      "TEXCOORD_0": self.floats(uv, "VEC2")}
        if tangent is not None:
            attributes["TANGENT"] = self.floats([tangent] * len(pos), "VEC4")
        return {"attributes": attributes, "indices": self.indices(tris), "material": material}


def look_down(pitch_deg):
    """The unit quaternion (x, y, z, w) turning −z down by `pitch_deg` about +x."""
    a = math.radians(-pitch_deg) / 2
    return [math.sin(a), 0.0, 0.0, math.cos(a)]


def document():
    buf = Buffer()
    checker = png(8, 8, lambda x, y: (200, 200, 200) if (x + y) % 2 == 0 else (40, 40, 48))
    images = [buf.view(checker), buf.view(pillow_normals()), buf.view(lattice())]
    ball = buf.primitive(sphere(0.7), 1)
    # The floor's u runs along +x and its v along +z (glTF's v is down the image), so photon's up-the-image
    # v' = 1 - v runs along -z: the bitangent w (n x t) = w (+y x +x) = -w z points up the image for w = +1.
    floor_primitive = buf.primitive(floor(), 0, tangent=(1.0, 0.0, 0.0, 1.0))
    # The three spheres share one set of accessors, each mesh with its own material.
    meshes = [
        {"name": "floor", "primitives": [floor_primitive]},
        {"name": "rough gold", "primitives": [ball]},
        {"name": "rough glass", "primitives": [dict(ball, material=2)]},
        {"name": "smooth glass", "primitives": [dict(ball, material=3)]},
        {"name": "lattice screen", "primitives": [buf.primitive(screen(), 4)]},
    ]
    glass = {"KHR_materials_transmission": {"transmissionFactor": 1.0}, "KHR_materials_ior": {"ior": 1.5}}
    materials = [
        {"name": "checker floor", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "metallicFactor": 0.0,
                                                           "roughnessFactor": 0.8},
         "normalTexture": {"index": 1}},
        {"name": "rough gold", "pbrMetallicRoughness": {"baseColorFactor": [1.0, 0.77, 0.34, 1.0],
                                                        "metallicFactor": 1.0, "roughnessFactor": 0.35}},
        {"name": "rough glass", "pbrMetallicRoughness": {"metallicFactor": 0.0, "roughnessFactor": 0.3},
         "extensions": glass},
        {"name": "smooth glass", "pbrMetallicRoughness": {"metallicFactor": 0.0, "roughnessFactor": 0.0},
         "extensions": glass},
        {"name": "lattice", "alphaMode": "MASK", "alphaCutoff": 0.5, "doubleSided": True,
         "pbrMetallicRoughness": {"baseColorTexture": {"index": 2}, "baseColorFactor": [0.8, 0.6, 0.4, 1.0],
                                  "metallicFactor": 0.0, "roughnessFactor": 0.6}},
    ]
    # The camera 6.5 units in front at height 2.2, looking down at the spheres' centres (height 0.7).
    pitch = math.degrees(math.atan2(2.2 - 0.7, 6.5))
    nodes = [
        {"name": "floor", "mesh": 0},
        {"name": "gold", "mesh": 1, "translation": [-1.6, 0.7, 0.0]},
        {"name": "rough glass", "mesh": 2, "translation": [0.0, 0.7, 0.0]},
        {"name": "smooth glass", "mesh": 3, "translation": [1.6, 0.7, 0.0]},
        {"name": "lattice screen", "mesh": 4},
        {"name": "camera", "camera": 0, "translation": [0.0, 2.2, 6.5], "rotation": look_down(pitch)},
        # Above the gold sphere and 1 in front, aimed at its centre: the cone (0.45 rad, 25.8 degrees) reaches
        # the rough glass and the lattice, and stays 2.7 degrees clear of the smooth glass sphere.
        {"name": "spot", "translation": [-1.6, 5.0, 1.0],
         "rotation": look_down(90.0 - math.degrees(math.atan2(1.0, 4.3))),
         "extensions": {"KHR_lights_punctual": {"light": 0}}},
    ]
    lights = [
        {"name": "key", "type": "spot", "color": [1.0, 0.95, 0.85], "intensity": 60.0,
         "spot": {"innerConeAngle": 0.25, "outerConeAngle": 0.45}},
    ]
    doc = {
        "asset": {"version": "2.0", "generator": "photon tools/make_gltf.py"},
        "extensionsUsed": ["KHR_lights_punctual", "KHR_materials_transmission", "KHR_materials_ior"],
        "scene": 0,
        "scenes": [{"nodes": list(range(len(nodes)))}],
        "nodes": nodes,
        "meshes": meshes,
        "materials": materials,
        "cameras": [{"type": "perspective", "perspective": {"yfov": math.radians(40.0), "aspectRatio": 1.5,
                                                            "znear": 0.05}}],
        "extensions": {"KHR_lights_punctual": {"lights": lights}},
        "images": [{"bufferView": v, "mimeType": "image/png"} for v in images],
        # The checker nearest, the normals and the lattice's alpha bilinear (round holes), all repeating.
        "samplers": [{"magFilter": 9728, "wrapS": 10497, "wrapT": 10497},
                     {"magFilter": 9729, "wrapS": 10497, "wrapT": 10497}],
        "textures": [{"source": 0, "sampler": 0}, {"source": 1, "sampler": 1}, {"source": 2, "sampler": 1}],
        "buffers": [{"byteLength": len(buf.data)}],
        "bufferViews": buf.views,
        "accessors": buf.accessors,
    }
    return doc, bytes(buf.data)


def glb(doc, data):
    """The GLB container: a 12-byte header, the JSON chunk padded with spaces, the binary chunk with zeros."""
    text = json.dumps(doc, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    data += b"\0" * (-len(data) % 4)
    total = 12 + 8 + len(text) + 8 + len(data)
    return (struct.pack("<4sII", b"glTF", 2, total) + struct.pack("<I4s", len(text), b"JSON") + text
            + struct.pack("<I4s", len(data), b"BIN\0") + data)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("-o", "--output", type=Path, default=REPO / "scenes/gltf/showcase.glb")
    args = parser.parse_args()
    args.output.parent.mkdir(parents=True, exist_ok=True)
    blob = glb(*document())
    args.output.write_bytes(blob)
    print(f"{args.output}: {len(blob)} bytes")


if __name__ == "__main__":
    main()
