#!/usr/bin/env python3
"""Count NaN, infinite and negative samples in an OpenEXR file (scanline or tiled; none, RLE or ZIP).

    python3 exrcheck.py IMAGE.exr [OUT.png]

Prints `nan=N inf=N neg=N min=V max=V`. With OUT.png, also writes the image as 8-bit sRGB at exposure 0,
as `photon-coordinator render -o X.png` does (`Image::to_srgb8`: non-finite → 0, clamp to [0, 1], sRGB
curve), so a PNG shows exactly the EXR that was measured and a reference is rendered once, not twice.
Standard library only (the machine has no numpy or OpenEXR module).
"""
import math
import struct
import sys
import zlib


def unpredict(data):
    """Undo OpenEXR's byte predictor and byte-plane split (shared by RLE and ZIP)."""
    out = bytearray(data)
    for j in range(1, len(out)):
        out[j] = (out[j - 1] + out[j] - 128) & 0xFF
    half = (len(out) + 1) // 2
    res = bytearray(len(out))
    res[0::2], res[1::2] = out[:half], out[half:]
    return bytes(res)


def rle_decode(src):
    out, i = bytearray(), 0
    while i < len(src):
        n = struct.unpack_from("b", src, i)[0]
        i += 1
        if n < 0:
            out += src[i:i - n]
            i -= n
        else:
            out += bytes([src[i]]) * (n + 1)
            i += 1
    return unpredict(out)


def attributes(buf):
    pos, attrs = 8, {}
    while buf[pos] != 0:
        end = buf.index(b"\0", pos)
        name = buf[pos:end].decode()
        end2 = buf.index(b"\0", end + 1)
        size = struct.unpack_from("<i", buf, end2 + 1)[0]
        attrs[name] = buf[end2 + 5:end2 + 5 + size]
        pos = end2 + 5 + size
    return attrs, pos + 1


def channel_types(chlist):
    types, pos = [], 0
    while chlist[pos] != 0:
        end = chlist.index(b"\0", pos)
        types.append(struct.unpack_from("<i", chlist, end + 1)[0])
        pos = end + 1 + 16
    return types


def srgb8(v):
    v = min(max(v, 0.0), 1.0) if math.isfinite(v) else 0.0
    v = 12.92 * v if v <= 0.0031308 else 1.055 * v ** (1 / 2.4) - 0.055
    return int(v * 255.0 + 0.5)


def write_png(path, w, h, rgb):
    """rgb: a bytearray of w*h*3 8-bit samples, rows top to bottom."""
    def chunk(kind, data):
        body = kind + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body))
    rows = b"".join(b"\0" + bytes(rgb[y * w * 3:(y + 1) * w * 3]) for y in range(h))
    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
    png += chunk(b"IDAT", zlib.compress(rows, 9)) + chunk(b"IEND", b"")
    with open(path, "wb") as f:
        f.write(png)


def main(path, png=None):
    buf = open(path, "rb").read()
    attrs, pos = attributes(buf)
    compression = attrs["compression"][0]
    if compression not in (0, 1, 2, 3):
        sys.exit(f"{path}: compression {compression} is not supported (only none, RLE, ZIPS, ZIP)")
    x0, y0, x1, y1 = struct.unpack("<4i", attrs["dataWindow"])
    types = channel_types(attrs["channels"])
    names = []
    pos_c = 0
    while attrs["channels"][pos_c] != 0:
        end = attrs["channels"].index(b"\0", pos_c)
        names.append(attrs["channels"][pos_c:end].decode())
        pos_c = end + 17
    if set(types) not in ({1}, {2}):
        sys.exit(f"{path}: channels must all be half or all float")
    nch = len(types)
    fmt, width = ("e", 2) if types[0] == 1 else ("f", 4)
    w, h = x1 - x0 + 1, y1 - y0 + 1
    tiled = "tiles" in attrs
    # Tile size, or for scanline files the lines per chunk (16 for ZIP, else 1).
    tw, th = struct.unpack_from("<2I", attrs["tiles"]) if tiled else (w, 16 if compression == 3 else 1)
    if "chunkCount" in attrs:
        count = struct.unpack("<i", attrs["chunkCount"])[0]
    else:
        count = math.ceil(w / tw) * math.ceil(h / th)
    offsets = struct.unpack_from(f"<{count}Q", buf, pos)
    rgb = bytearray(w * h * 3)
    slot = {name: "RGB".index(name) for name in names if name in "RGB" and len(name) == 1}
    nan = inf = neg = 0
    lo, hi = math.inf, -math.inf
    for off in offsets:
        head = 20 if tiled else 8
        size = struct.unpack_from("<i", buf, off + head - 4)[0]
        data = buf[off + head:off + head + size]
        if tiled:
            tx, ty = struct.unpack_from("<2i", buf, off)
            cx, cy = tx * tw, ty * th
            cw, chh = min(tw, w - cx), min(th, h - cy)
        else:
            cx, cy = 0, struct.unpack_from("<i", buf, off)[0] - y0
            cw, chh = w, min(th, h - cy)
        raw = cw * chh * nch * width
        if size < raw:  # a chunk that would not shrink is stored raw
            data = rle_decode(data) if compression == 1 else unpredict(zlib.decompress(data))
        # Layout: for each line of the chunk, each channel (sorted by name) holds cw samples.
        for i, (v,) in enumerate(struct.iter_unpack("<" + fmt, data)):
            line, rest = divmod(i, cw * nch)
            c, x = divmod(rest, cw)
            if names[c] in slot:
                rgb[((cy + line) * w + cx + x) * 3 + slot[names[c]]] = srgb8(v)
            if math.isnan(v):
                nan += 1
            elif math.isinf(v):
                inf += 1
            else:
                neg += v < 0
                lo, hi = min(lo, v), max(hi, v)
    print(f"nan={nan} inf={inf} neg={neg} min={lo:.4g} max={hi:.4g}")
    if png:
        write_png(png, w, h, rgb)


if __name__ == "__main__":
    main(*sys.argv[1:3])
