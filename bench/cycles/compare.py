#!/usr/bin/env python3
"""Per-pixel comparison of a prtfarm image relit by prt-view against two Cycles renders.

    python3 bench/cycles/compare.py --prt P.exr --cycles A.exr B.exr --scene DIR/scene.json \
        [--index INDEX.exr] [--label NAME] [--json out.json] [--png-prefix PREFIX]

P is prt-view's linear EXR of an image pack (albedo * T.L per pixel, the environment along the
camera ray on background pixels); A and B are render_camera.py renders of the same view with two
seeds. The reference is R = (A + B)/2. Cycles' own noise is removed from the mean squared error:
for independent renders with per-pixel variance s2, E[(A - B)^2] = 2 s2 and R's variance is s2/2,
so

    err2 = mean((P - R)^2) - mean((A - B)^2) / 4,    rel = sqrt(max(err2, 0) / mean(R^2))

over the pixels of a group. Groups come from the farm's own image.prti (pixel_mesh.bin written
by export_scene.py): "model" (every pixel whose centre ray sees a non-ground mesh), "ground",
each mesh by name when there are several, and the same groups without the pixels that have a
different mesh among their 8 neighbours ("-interior": silhouettes and the model's contact with
the ground excluded). Background pixels are not an accuracy figure; they are reported apart as
"background_check" (both sides draw the environment along the pixel's ray: it checks the
environment's orientation and the camera). The figures are for the three
channels pooled and per channel; "plain" is sqrt(mean((P-R)^2)/mean(R^2)) before the correction
and "noise" sqrt(mean((A-B)^2)/4/mean(R^2)), the correction's size; "mean ratio" is
sum(P)/sum(R), the group's brightness bias.

PNGs (--png-prefix): PREFIX-error.png, |P - R| / R of luminance on a false-colour scale from 0
(dark blue) to --error-scale (red; default 0.2 = 20 %), background black; PREFIX-side.png,
prtfarm | Cycles (A+B)/2 | error map, sRGB with one exposure for both renders.
"""

import argparse
import json
import os
import sys

import numpy as np

sys.dont_write_bytecode = True  # no __pycache__ in the source tree
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import exrio  # noqa: E402

BACKGROUND = 0xFFFFFFFF
LUMA = np.array([0.2126, 0.7152, 0.0722])


def groups_of(desc, pixel_mesh):
    meshes = desc["meshes"]
    h, w = pixel_mesh.shape
    padded = np.pad(pixel_mesh.astype(np.int64), 1, mode="edge")
    same = np.ones((h, w), dtype=bool)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            same &= padded[1 + dy:1 + dy + h, 1 + dx:1 + dx + w] == pixel_mesh
    ground_ids = [m["index"] for m in meshes if m["is_ground"]]
    model_ids = [m["index"] for m in meshes if not m["is_ground"]]
    out = {}
    out["model"] = np.isin(pixel_mesh, model_ids)
    if ground_ids:
        out["ground"] = np.isin(pixel_mesh, ground_ids)
    if len(model_ids) > 1:
        for m in meshes:
            if not m["is_ground"]:
                out[m["name"]] = pixel_mesh == m["index"]
    for name in list(out):
        out[name + "-interior"] = out[name] & same
    return out


def stats(P, A, B, mask):
    R = 0.5 * (A + B)
    n = int(mask.sum())
    if n == 0:
        return None
    p, r, a, b = P[mask], R[mask], A[mask], B[mask]

    def figures(p, r, a, b):
        sq = float(np.mean((p - r) ** 2))
        noise = float(np.mean((a - b) ** 2)) / 4.0
        ref = float(np.mean(r ** 2))
        corr = sq - noise
        return dict(rel=float(np.sqrt(max(corr, 0.0) / ref)), plain=float(np.sqrt(sq / ref)),
                    noise=float(np.sqrt(noise / ref)), err2=corr,
                    mean_ratio=float(np.sum(p) / np.sum(r)),
                    rmse=float(np.sqrt(max(corr, 0.0))), ref_rms=float(np.sqrt(ref)))

    out = dict(pixels=n, all=figures(p, r, a, b))
    for c, name in enumerate("RGB"):
        out[name] = figures(p[:, c], r[:, c], a[:, c], b[:, c])
    return out


def ramp(t):
    """0 -> dark blue, 0.25 cyan, 0.5 green, 0.75 yellow, 1 red (sRGB bytes)."""
    stops = np.array([[0, 0, 96], [0, 200, 255], [0, 200, 0], [255, 230, 0], [220, 0, 0]],
                     dtype=np.float64)
    x = np.clip(t, 0, 1) * (len(stops) - 1)
    i = np.minimum(x.astype(int), len(stops) - 2)
    f = (x - i)[..., None]
    return np.round(stops[i] * (1 - f) + stops[i + 1] * f).astype(np.uint8)


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--prt", required=True, help="prt-view's linear EXR")
    p.add_argument("--cycles", required=True, nargs=2, help="two Cycles renders, two seeds")
    p.add_argument("--scene", required=True, help="scene.json of export_scene.py")
    p.add_argument("--index", default=None, help="render_camera.py's --index-out EXR")
    p.add_argument("--label", default="")
    p.add_argument("--json", default=None)
    p.add_argument("--png-prefix", default=None)
    p.add_argument("--error-scale", type=float, default=0.2)
    p.add_argument("--exposure", type=float, default=0.0,
                   help="PNG exposure; 0 = the 99th percentile of the reference's surface "
                        "luminance maps to 0.9")
    a = p.parse_args()

    desc = json.load(open(a.scene))
    w, h = desc["camera"]["width"], desc["camera"]["height"]
    base = os.path.dirname(os.path.abspath(a.scene))
    pixel_mesh = np.fromfile(os.path.join(base, "pixel_mesh.bin"), dtype="<u4").reshape(h, w)
    P = exrio.read_rgb(a.prt).astype(np.float64)
    A = exrio.read_rgb(a.cycles[0]).astype(np.float64)
    B = exrio.read_rgb(a.cycles[1]).astype(np.float64)
    for name, img in (("prt", P), ("cycles A", A), ("cycles B", B)):
        if img.shape[:2] != (h, w):
            sys.exit(f"compare.py: {name} is {img.shape[1]}x{img.shape[0]}, the camera {w}x{h}")
    result = dict(label=a.label, prt=a.prt, cycles=a.cycles, width=w, height=h, groups={})
    surface = pixel_mesh != BACKGROUND
    if a.index:
        idx = np.rint(exrio.read_rgb(a.index)[:, :, 0]).astype(np.int64) - 1
        idx[idx < 0] = BACKGROUND
        agree = idx == pixel_mesh.astype(np.int64)
        result["index_agreement"] = dict(pixels=int(agree.sum()), of=int(agree.size),
                                         disagree=int((~agree).sum()))
    for name, mask in groups_of(desc, pixel_mesh).items():
        s = stats(P, A, B, mask)
        if s:
            result["groups"][name] = s
    # not an accuracy figure: both sides draw the environment along the pixel's ray there, so
    # it checks the environment's orientation and the camera convention
    s = stats(P, A, B, ~surface)
    if s:
        result["background_check"] = s

    if a.json:
        with open(a.json, "w") as f:
            json.dump(result, f, indent=1)
    if a.png_prefix:
        R = 0.5 * (A + B)
        lum_p, lum_r = P @ LUMA, R @ LUMA
        rel = np.abs(lum_p - lum_r) / np.maximum(lum_r, 1e-6)
        err = ramp(rel / a.error_scale)
        err[~surface] = 0
        exposure = a.exposure
        if exposure <= 0:
            exposure = 0.9 / max(float(np.percentile(lum_r[surface], 99)), 1e-6)
        side = np.concatenate([exrio.to_srgb8(P, exposure), exrio.to_srgb8(R, exposure), err],
                              axis=1)
        exrio.write_png(a.png_prefix + "-error.png", err)
        exrio.write_png(a.png_prefix + "-side.png", side)

    print(f"{a.label}: " + ", ".join(
        f"{g} {100 * s['all']['rel']:.2f}% (plain {100 * s['all']['plain']:.2f}%, noise "
        f"{100 * s['all']['noise']:.2f}%, ratio {s['all']['mean_ratio']:.4f})"
        for g, s in result["groups"].items() if not g.endswith("-interior"))
        + (f"; background (orientation check) {100 * result['background_check']['all']['plain']:.2f}%"
           if "background_check" in result else "")
        + (f"; Cycles index agrees on {result['index_agreement']['pixels']}/"
           f"{result['index_agreement']['of']} pixels" if "index_agreement" in result else ""))


if __name__ == "__main__":
    main()
