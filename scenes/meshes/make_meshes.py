#!/usr/bin/env python3
"""Writes the meshes of scenes/mesh.toml: a torus with normals and UVs, and an icosphere with neither (the
renderer computes smooth normals). Run from this folder: python3 make_meshes.py"""
import math


def torus(path, R=0.5, r=0.18, nu=40, nv=20):
    with open(path, "w") as f:
        f.write("# torus R=%g r=%g, %dx%d quads, with normals and UVs\n" % (R, r, nu, nv))
        for i in range(nu + 1):
            for j in range(nv + 1):
                u = 2 * math.pi * i / nu
                v = 2 * math.pi * j / nv
                n = (math.cos(v) * math.cos(u), math.sin(v), math.cos(v) * math.sin(u))
                p = ((R + r * math.cos(v)) * math.cos(u), r * math.sin(v), (R + r * math.cos(v)) * math.sin(u))
                f.write("v %.6f %.6f %.6f\n" % p)
                f.write("vn %.6f %.6f %.6f\n" % n)
                f.write("vt %.6f %.6f\n" % (i / nu, j / nv))
        for i in range(nu):
            for j in range(nv):
                a = i * (nv + 1) + j + 1
                b = (i + 1) * (nv + 1) + j + 1
                # Counter-clockwise seen from outside.
                f.write("f %d/%d/%d %d/%d/%d %d/%d/%d %d/%d/%d\n" % (a, a, a, a + 1, a + 1, a + 1, b + 1, b + 1, b + 1, b, b, b))


def icosphere(path, subdivisions=3):
    t = (1 + 5 ** 0.5) / 2
    verts = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
             (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    verts = [tuple(c / math.sqrt(sum(x * x for x in v)) for c in v) for v in verts]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
             (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11),
             (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    for _ in range(subdivisions):
        cache = {}

        def mid(a, b):
            key = (min(a, b), max(a, b))
            if key not in cache:
                m = [(verts[a][k] + verts[b][k]) / 2 for k in range(3)]
                l = math.sqrt(sum(x * x for x in m))
                verts.append(tuple(x / l for x in m))
                cache[key] = len(verts) - 1
            return cache[key]

        new = []
        for a, b, c in faces:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            new += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = new
    with open(path, "w") as f:
        f.write("# unit icosphere, %d triangles, positions and faces only\n" % len(faces))
        for v in verts:
            f.write("v %.6f %.6f %.6f\n" % v)
        for a, b, c in faces:
            f.write("f %d %d %d\n" % (a + 1, b + 1, c + 1))


torus("torus.obj")
icosphere("icosphere.obj")
