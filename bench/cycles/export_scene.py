#!/usr/bin/env python3
"""Writes the Cycles description of an image run (samples = "camera") from its run folder.

    python3 bench/cycles/export_scene.py RUN_DIR --out DIR

Reads, from the farm's own run folder, exactly what the farm traced:
  geometry.prtg  the world-space meshes after fit/scale/rotate/translate and the ground grid, in
                 double precision, with the shading normals (docs/transport-format.md);
  image.prti     the camera (eye, target, up, vertical fov, width, height) and the mesh each
                 pixel's centre ray sees (0xFFFFFFFF = background);
  scene.toml     the materials (brdf, albedo, specular, roughness) by mesh name; the ground's
                 table is [ground].
Writes DIR/scene.json (camera, materials, meshes) and DIR/mesh-<i>.bin per mesh (float32
positions, float32 normals, uint32 triangles, little-endian, counts in the JSON), and
DIR/pixel_mesh.bin (the farm's per-pixel mesh index, uint32, row-major from the top-left) that
compare.py uses to split the pixels into groups. render_camera.py reads scene.json.

Everything stays in prtfarm's world coordinates (+Y up, right-handed); the Blender script owns
the change to Blender's frame and the environment's orientation.
"""

import argparse
import json
import os
import struct
import sys

try:
    import tomllib
except ImportError:  # Python < 3.11
    tomllib = None

BACKGROUND = 0xFFFFFFFF


class Reader:
    def __init__(self, data, name):
        self.data, self.pos, self.name = data, 0, name

    def take(self, fmt, count=1):
        size = struct.calcsize("<" + fmt) * count
        if self.pos + size > len(self.data):
            sys.exit(f"{self.name}: truncated")
        out = struct.unpack_from("<" + fmt * count, self.data, self.pos)
        self.pos += size
        return out

    def raw(self, size):
        if self.pos + size > len(self.data):
            sys.exit(f"{self.name}: truncated")
        out = self.data[self.pos:self.pos + size]
        self.pos += size
        return out


def read_geometry(path):
    """geometry.prtg -> list of meshes (name, albedo, is_ground, positions, normals, triangles)."""
    data = open(path, "rb").read()
    r = Reader(data, path)
    if r.raw(8) != b"PRTGEOM1":
        sys.exit(f"{path}: not a geometry.prtg")
    (version,) = r.take("I")
    if version != 1:
        sys.exit(f"{path}: version {version}, this script reads 1")
    (count,) = r.take("I")
    bounds = r.take("d", 6)
    meshes = []
    for _ in range(count):
        (length,) = r.take("I")
        name = r.raw(length).decode("utf-8")
        albedo = r.take("f", 3)
        is_ground, ground_res = r.take("I", 2)
        nv, nf = r.take("Q", 2)
        positions = r.raw(24 * nv)
        normals = r.raw(24 * nv)
        triangles = r.raw(12 * nf)
        meshes.append(dict(name=name, albedo=list(albedo), is_ground=bool(is_ground),
                           ground_resolution=ground_res, vertices=nv, triangles=nf,
                           positions=positions, normals=normals, tris=triangles))
    if r.pos + 8 != len(data):
        sys.exit(f"{path}: {len(data) - r.pos - 8} unexpected bytes before the checksum")
    return meshes, bounds


def read_image(path):
    data = open(path, "rb").read()
    r = Reader(data, path)
    # PRTIMG02 (glossy pixels) and PRTIMG03 (supersampled) add tables after the pixels; the
    # camera and the per-pixel mesh come first in all three.
    if r.raw(8) not in (b"PRTIMG01", b"PRTIMG02", b"PRTIMG03"):
        sys.exit(f"{path}: not an image.prti (PRTIMG01, 02 or 03)")
    width, height = r.take("I", 2)
    eye, target, up = r.take("d", 3), r.take("d", 3), r.take("d", 3)
    (fov,) = r.take("d")
    pixel_mesh = r.raw(4 * width * height)
    return dict(width=width, height=height, eye=list(eye), target=list(target), up=list(up),
                fov_deg=fov), pixel_mesh


def parse_toml(path):
    text = open(path, "rb").read()
    if tomllib is None:
        sys.exit("export_scene.py needs Python >= 3.11 (tomllib)")
    return tomllib.loads(text.decode("utf-8"))


def material_of(table, albedo):
    """The Cycles material of a [[mesh]] or [ground] table. Lambert unless brdf says otherwise."""
    brdf = table.get("brdf", "lambert")
    m = dict(brdf=brdf, albedo=list(albedo))
    if brdf == "ggx":
        spec = table.get("specular", [1.0, 1.0, 1.0])
        if isinstance(spec, (int, float)):
            spec = [float(spec)] * 3
        m["specular"] = [float(s) for s in spec]
        m["roughness"] = float(table["roughness"])
    elif brdf != "lambert":
        # Phong and Ashikhmin-Shirley have no Cycles node with the same definition.
        m["unsupported"] = f"brdf = {brdf!r} has no Cycles equivalent in render_camera.py"
    return m


def f64_to_f32(raw):
    n = len(raw) // 8
    return struct.pack(f"<{n}f", *struct.unpack(f"<{n}d", raw))


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("run", help="a finished run folder (prt-farm --out): an image run, or a "
                   "vertex run rendered from its scene's [camera]")
    p.add_argument("--out", required=True, help="folder for scene.json and the mesh files")
    a = p.parse_args()
    os.makedirs(a.out, exist_ok=True)

    meshes, bounds = read_geometry(os.path.join(a.run, "geometry.prtg"))
    image_path = os.path.join(a.run, "image.prti")
    scene = parse_toml(os.path.join(a.run, "scene.toml"))
    vertex_run = not os.path.exists(image_path)
    if vertex_run:
        # A vertex run (glossy vertex transport, docs/glossy-transport.md): prt-view renders the
        # pack from the scene's [camera] (defaults of vocabulary/scene.h); the pixels' meshes
        # come from Cycles' index pass (run.sh writes pixel_mesh.bin from it after the first
        # render), so the placeholder here says "every pixel on mesh 0".
        c = scene.get("camera", {})
        camera = dict(eye=list(c.get("eye", [0.0, 1.0, 4.0])),
                      target=list(c.get("target", [0.0, 0.5, 0.0])),
                      up=list(c.get("up", [0.0, 1.0, 0.0])), fov_deg=c.get("fov", 40.0),
                      width=c.get("width", 640), height=c.get("height", 480))
        pixel_mesh = bytes(4 * camera["width"] * camera["height"])
    else:
        camera, pixel_mesh = read_image(image_path)
    tables = {t.get("name", f"mesh{i}"): t for i, t in enumerate(scene.get("mesh", []))}

    out_meshes = []
    for i, m in enumerate(meshes):
        table = scene.get("ground", {}) if m["is_ground"] else tables.get(m["name"])
        if table is None:
            sys.exit(f"mesh {m['name']!r} of geometry.prtg is not a [[mesh]] of scene.toml")
        file = f"mesh-{i}.bin"
        with open(os.path.join(a.out, file), "wb") as f:
            f.write(f64_to_f32(m["positions"]))
            f.write(f64_to_f32(m["normals"]))
            f.write(m["tris"])
        out_meshes.append(dict(index=i, name=m["name"], is_ground=m["is_ground"], file=file,
                               vertices=m["vertices"], triangles=m["triangles"],
                               material=material_of(table, m["albedo"])))
    with open(os.path.join(a.out, "pixel_mesh.bin"), "wb") as f:
        f.write(pixel_mesh)
    sampling = scene.get("sampling", {})
    desc = dict(source=os.path.abspath(a.run), coordinates="prtfarm world (+Y up)",
                camera=camera, meshes=out_meshes, bounds=list(bounds),
                cubemap_n=scene.get("scene", {}).get("n", 32),
                bounces=sampling.get("bounces", 0), vertex_run=vertex_run,
                supersample=scene.get("camera", {}).get("supersample", 1))
    with open(os.path.join(a.out, "scene.json"), "w") as f:
        json.dump(desc, f, indent=1)
    counts = {}
    for k in struct.unpack(f"<{len(pixel_mesh) // 4}I", pixel_mesh):
        counts[k] = counts.get(k, 0) + 1
    names = ", ".join(f"{meshes[k]['name'] if k != BACKGROUND else 'background'} {v}"
                      for k, v in sorted(counts.items()))
    print(f"{a.out}/scene.json: {len(meshes)} meshes, camera {camera['width']}x{camera['height']}"
          f" fov {camera['fov_deg']}; pixels: {names}")


if __name__ == "__main__":
    main()
