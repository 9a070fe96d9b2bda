#!/usr/bin/env python3
"""Writes scenes/meshes/torus.ply, the mesh of scenes/ply-mesh.toml: the torus of scenes/meshes/make_meshes.py
(R = 0.5, r = 0.18) at 24 x 12 quads, as a binary little-endian PLY with normals (nx, ny, nz) and texture
coordinates (u, v) per vertex and quad faces (list uchar uint vertex_indices), about 15 KB.

    python3 tools/make_ply.py                       # from the repository root
    python3 tools/make_ply.py --format ascii -o /tmp/torus.ply

Python 3 standard library only.
"""

import argparse
import math
import struct
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
FORMATS = {"binary_little_endian": "<", "binary_big_endian": ">", "ascii": None}


def torus(R=0.5, r=0.18, nu=24, nv=12):
    """Vertices (position, normal, uv) on a (nu + 1) x (nv + 1) grid, the seams doubled for the UVs, and quads
    counter-clockwise seen from outside."""
    vertices = []
    for i in range(nu + 1):
        for j in range(nv + 1):
            u, v = 2 * math.pi * i / nu, 2 * math.pi * j / nv
            n = (math.cos(v) * math.cos(u), math.sin(v), math.cos(v) * math.sin(u))
            p = ((R + r * math.cos(v)) * math.cos(u), r * math.sin(v), (R + r * math.cos(v)) * math.sin(u))
            vertices.append((p, n, (i / nu, j / nv)))
    quads = []
    for i in range(nu):
        for j in range(nv):
            a, b = i * (nv + 1) + j, (i + 1) * (nv + 1) + j
            quads.append((a, a + 1, b + 1, b))
    return vertices, quads


def write(path, fmt, vertices, quads):
    header = (
        f"ply\nformat {fmt} 1.0\ncomment torus R=0.5 r=0.18, 24x12 quads, written by tools/make_ply.py\n"
        f"element vertex {len(vertices)}\n"
        + "".join(f"property float {name}\n" for name in ("x", "y", "z", "nx", "ny", "nz", "u", "v"))
        + f"element face {len(quads)}\nproperty list uchar uint vertex_indices\nend_header\n"
    )
    order = FORMATS[fmt]
    with open(path, "wb") as f:
        f.write(header.encode("ascii"))
        for p, n, uv in vertices:
            values = (*p, *n, *uv)
            if order:
                f.write(struct.pack(f"{order}8f", *values))
            else:
                f.write((" ".join("%.6f" % x for x in values) + "\n").encode("ascii"))
        for q in quads:
            if order:
                f.write(struct.pack(f"{order}B4I", 4, *q))
            else:
                f.write(("4 " + " ".join(str(k) for k in q) + "\n").encode("ascii"))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--format", choices=FORMATS, default="binary_little_endian")
    ap.add_argument("-o", "--output", type=Path, default=REPO / "scenes" / "meshes" / "torus.ply")
    args = ap.parse_args()
    vertices, quads = torus()
    write(args.output, args.format, vertices, quads)
    print(f"wrote {args.output} ({args.output.stat().st_size} bytes)")


if __name__ == "__main__":
    main()
