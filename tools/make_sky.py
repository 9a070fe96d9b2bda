#!/usr/bin/env python3
"""Writes scenes/textures/sky.hdr, the environment of scenes/sky.toml: a 256 x 128 equirectangular Radiance HDR
(RGBE, uncompressed scanlines) in photon's layout (docs/SCENE.md, `type = "environment"`: column u and row v map
to the polar angle pi*v from +y and the azimuth pi*(2u - 1) from -z towards +x).

The sky is a blue gradient from the horizon to the zenith, a sun of radius 2.5 degrees at 35 degrees elevation
towards -x -z with radiance 2000 (about 2/3 of the sky's light), and a dull brown ground below the horizon.

    python3 tools/make_sky.py                 # from the repository root
    python3 tools/make_sky.py -o /tmp/sky.hdr

Python 3 standard library only.
"""

import argparse
import math
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
WIDTH, HEIGHT = 256, 128
SUN_ELEVATION, SUN_AZIMUTH, SUN_RADIUS = math.radians(35.0), math.radians(-45.0), math.radians(2.5)
SUN = (2000.0, 1900.0, 1700.0)


def direction(u, v):
    theta, phi = math.pi * v, math.pi * (2.0 * u - 1.0)
    return (math.sin(theta) * math.sin(phi), math.cos(theta), -math.sin(theta) * math.cos(phi))


def radiance(d):
    x, y, z = d
    ce = math.cos(SUN_ELEVATION)
    sun = (ce * math.sin(SUN_AZIMUTH), math.sin(SUN_ELEVATION), -ce * math.cos(SUN_AZIMUTH))
    if x * sun[0] + y * sun[1] + z * sun[2] > math.cos(SUN_RADIUS):
        return SUN
    if y < 0.0:
        return (0.12, 0.10, 0.08)
    t = y ** 0.5
    horizon, zenith = (1.1, 1.2, 1.3), (0.25, 0.45, 0.95)
    return tuple(h + (zz - h) * t for h, zz in zip(horizon, zenith))


def rgbe(c):
    m = max(c)
    if m < 1e-32:
        return bytes(4)
    mantissa, exponent = math.frexp(m)
    scale = mantissa * 256.0 / m
    return bytes([int(c[0] * scale), int(c[1] * scale), int(c[2] * scale), exponent + 128])


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("-o", "--output", type=Path, default=REPO / "scenes" / "textures" / "sky.hdr")
    args = parser.parse_args()
    out = bytearray(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n" + f"-Y {HEIGHT} +X {WIDTH}\n".encode())
    for j in range(HEIGHT):
        for i in range(WIDTH):
            # The texel's mean over a 4 x 4 grid, so the sun's edge is antialiased.
            acc = [0.0, 0.0, 0.0]
            for a in range(4):
                for b in range(4):
                    c = radiance(direction((i + (a + 0.5) / 4) / WIDTH, (j + (b + 0.5) / 4) / HEIGHT))
                    acc = [s + x / 16.0 for s, x in zip(acc, c)]
            out += rgbe(acc)
    args.output.write_bytes(bytes(out))
    print(f"{args.output}: {WIDTH} x {HEIGHT}, {len(out)} bytes")


if __name__ == "__main__":
    main()
