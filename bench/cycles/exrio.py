"""Minimal OpenEXR reader and PNG writer for the Cycles comparison (numpy and zlib only).

Debian 12 has no Python OpenEXR binding, so this reads what the two sides write: single-part
scanline EXRs with NO, ZIPS or ZIP compression and HALF or FLOAT channels (prt-view: float RGB,
ZIP; Blender with exr_codec = "ZIP", 32-bit). Anything else is refused with a clear error.
"""

import struct
import zlib

import numpy as np

_COMPRESSION = {0: "none", 1: "rle", 2: "zips", 3: "zip", 4: "piz", 5: "pxr24", 6: "b44",
                7: "b44a", 8: "dwaa", 9: "dwab"}
_LINES_PER_BLOCK = {0: 1, 2: 1, 3: 16}


def _header(data, path):
    if data[:4] != b"\x76\x2f\x31\x01":
        raise ValueError(f"{path}: not an OpenEXR file")
    version = struct.unpack_from("<I", data, 4)[0]
    if version & 0x200 or version & 0x1000:
        raise ValueError(f"{path}: tiled or multi-part EXR, not supported here")
    pos, attrs = 8, {}
    while data[pos] != 0:
        end = data.index(b"\0", pos)
        name = data[pos:end].decode()
        pos = end + 1
        end = data.index(b"\0", pos)
        kind = data[pos:end].decode()
        pos = end + 1
        (size,) = struct.unpack_from("<i", data, pos)
        pos += 4
        attrs[name] = (kind, data[pos:pos + size])
        pos += size
    return attrs, pos + 1


def _channels(raw):
    out, pos = [], 0
    while raw[pos] != 0:
        end = raw.index(b"\0", pos)
        name = raw[pos:end].decode()
        (ptype,) = struct.unpack_from("<i", raw, end + 1)  # then pLinear, 3 reserved bytes
        xs, ys = struct.unpack_from("<ii", raw, end + 9)
        if xs != 1 or ys != 1:
            raise ValueError("subsampled channels are not supported")
        out.append((name, ptype))
        pos = end + 17
    return out


def _unzip(block, expected):
    raw = bytearray(zlib.decompress(block))
    if len(raw) != expected:
        raise ValueError("EXR block decompressed to the wrong size")
    t = np.frombuffer(bytes(raw), dtype=np.uint8).astype(np.int32)
    # predictor: running sum of differences (mod 256)
    t = np.cumsum(t - np.concatenate(([0], np.full(t.size - 1, 128)))) & 0xFF
    t = t.astype(np.uint8)
    half = (t.size + 1) // 2
    out = np.empty_like(t)
    out[0::2] = t[:half]
    out[1::2] = t[half:]
    return out.tobytes()


def read_exr(path):
    """-> float32 array (height, width, channels) and the channel names (R, G, B first)."""
    data = open(path, "rb").read()
    attrs, pos = _header(data, path)
    chans = _channels(attrs["channels"][1])
    comp = attrs["compression"][1][0]
    if comp not in _LINES_PER_BLOCK:
        raise ValueError(f"{path}: compression {_COMPRESSION.get(comp, comp)} not supported "
                         "(write NONE, ZIPS or ZIP)")
    xmin, ymin, xmax, ymax = struct.unpack("<iiii", attrs["dataWindow"][1])
    w, h = xmax - xmin + 1, ymax - ymin + 1
    lines = _LINES_PER_BLOCK[comp]
    nblocks = (h + lines - 1) // lines
    offsets = struct.unpack_from(f"<{nblocks}Q", data, pos)
    sizes = [2 if t == 1 else 4 for _, t in chans]  # 0 uint, 1 half, 2 float
    out = np.zeros((h, w, len(chans)), dtype=np.float32)
    for off in offsets:
        y, size = struct.unpack_from("<ii", data, off)
        block = data[off + 8:off + 8 + size]
        n = min(lines, ymax + 1 - y)
        expected = n * w * sum(sizes)
        if comp != 0 and size < expected:
            block = _unzip(block, expected)
        p = 0
        for row in range(n):
            for c, (_, t) in enumerate(chans):
                dt = {0: "<u4", 1: "<f2", 2: "<f4"}[t]
                vals = np.frombuffer(block, dtype=dt, count=w, offset=p)
                out[y - ymin + row, :, c] = vals.astype(np.float32)
                p += w * sizes[c]
    names = [n for n, _ in chans]
    order = sorted(range(len(names)), key=lambda i: ("RGBA".find(names[i][-1]) % 10, names[i]))
    return out[:, :, order], [names[i] for i in order]


def read_rgb(path):
    img, names = read_exr(path)
    if img.shape[2] >= 3:
        return img[:, :, :3]
    return np.repeat(img[:, :, :1], 3, axis=2)


def write_png(path, rgb8):
    """rgb8: uint8 array (h, w, 3)."""
    h, w, _ = rgb8.shape
    raw = b"".join(b"\0" + rgb8[y].tobytes() for y in range(h))

    def chunk(tag, body):
        return (struct.pack(">I", len(body)) + tag + body
                + struct.pack(">I", zlib.crc32(tag + body) & 0xFFFFFFFF))

    png = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
           + chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))
    with open(path, "wb") as f:
        f.write(png)


def to_srgb8(linear, exposure=1.0):
    x = np.clip(np.nan_to_num(linear * exposure), 0.0, 1.0)
    s = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return np.round(s * 255).astype(np.uint8)
