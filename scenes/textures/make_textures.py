#!/usr/bin/env python3
"""Writes the images of scenes/textured.toml with the standard library only (zlib for PNG):

- wood.png: an sRGB colour image (wood rings) for the textured sphere;
- bricks.png: a grey height map of bricks (mortar low, bricks high) for the bump-mapped wall;
- ridges-normal.png: a tangent-space normal map (OpenGL convention, green = +v) of sine ridges for the torus.

Run from this folder: python3 make_textures.py. The outputs are committed; the script says how they were made.
"""
import math
import struct
import zlib


def png(path, width, height, channels, texel):
    """Writes an 8-bit PNG; texel(x, y) returns a tuple of `channels` values in 0..255, row 0 at the top."""
    raw = bytearray()
    for y in range(height):
        raw.append(0)  # filter: none
        for x in range(width):
            raw.extend(texel(x, y))
    colour_type = {1: 0, 3: 2}[channels]

    def chunk(kind, data):
        c = struct.pack(">I", len(data)) + kind + data
        return c + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n")
        f.write(chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, colour_type, 0, 0, 0)))
        f.write(chunk(b"IDAT", zlib.compress(bytes(raw), 9)))
        f.write(chunk(b"IEND", b""))


def wood(x, y, w=256, h=128):
    u, v = x / w, y / h
    r = math.hypot(u - 0.3, (v - 0.5) * 0.5) * 40 + 3 * math.sin(u * 13) + 1.5 * math.sin(v * 29)
    t = 0.5 + 0.5 * math.sin(r)
    t = t ** 3
    light, dark = (196, 140, 84), (110, 62, 30)
    return tuple(round(d + (l - d) * t) for l, d in zip(light, dark))


def brick_height(x, y, size=256, rows=8, cols=4, mortar=4):
    row_h = size // rows
    brick_w = size // cols
    row = y // row_h
    shift = brick_w // 2 if row % 2 else 0
    in_y = y % row_h
    in_x = (x + shift) % brick_w
    if in_y < mortar or in_x < mortar:
        return 30
    # A rounded bevel: the brick rises over 8 texels from the mortar.
    edge = min(in_y - mortar, row_h - 1 - in_y, in_x - mortar, brick_w - 1 - in_x, 8)
    return round(60 + 180 * math.sin(math.pi / 2 * edge / 8))


def ridges_normal(x, y, w=256, h=64, ridges_u=24, ridges_v=4, amplitude=0.12):
    # Height h = a·sin(2π·ridges_u·u)·(0.6 + 0.4 sin(2π·ridges_v·v)); the normal is (−∂h/∂u, −∂h/∂v, 1)
    # in units of the image, normalised and encoded as (n + 1)/2.
    u, v = (x + 0.5) / w, 1 - (y + 0.5) / h
    s = 0.6 + 0.4 * math.sin(2 * math.pi * ridges_v * v)
    dhdu = amplitude * 2 * math.pi * ridges_u * math.cos(2 * math.pi * ridges_u * u) * s / ridges_u
    dhdv = amplitude * math.sin(2 * math.pi * ridges_u * u) * 0.4 * 2 * math.pi * ridges_v * math.cos(2 * math.pi * ridges_v * v) / ridges_u
    n = (-dhdu, -dhdv, 1.0)
    length = math.sqrt(sum(c * c for c in n))
    return tuple(round((c / length * 0.5 + 0.5) * 255) for c in n)


png("wood.png", 256, 128, 3, wood)
png("bricks.png", 256, 256, 1, lambda x, y: (brick_height(x, y),))
png("ridges-normal.png", 256, 64, 3, ridges_normal)
