"""What the lighting cubemap alone does to an unoccluded, upward-facing diffuse pixel.

    blender -b --factory-startup --python bench/cycles/cubemap_bias.py -- MAP.exr [MAP2.exr ...] [--n 32]

prtfarm relights with L_j, the average radiance over each cubemap texel (docs/conventions.md),
and T_j = (1/pi) * integral over texel j of max(0, n.w) dw, so an unoccluded pixel gets
(1/pi) sum_j L_j * integral_j cos, whereas the exact value (what Cycles renders) is
(1/pi) * integral L cos. They differ where radiance and cosine vary together inside one texel:
a sun near the horizon, smeared over a texel about 2.8 degrees wide at n = 32, is the large case.
This prints both and their ratio per channel for a ground normal (+Y), from the map's own pixels
on OpenEXR's LatLongMap cells cut into 4x4 sub-cells (the power of sunrise.exr comes out 8.8228,
as in docs/conventions.md). Run inside Blender only to read DWAB-compressed EXRs.
"""
import sys

import bpy
import numpy as np


def load(path):
    img = bpy.data.images.load(path)
    img.colorspace_settings.name = "Non-Color"
    w, h = img.size
    px = np.empty(w * h * 4, dtype=np.float32)
    img.pixels.foreach_get(px)
    return np.maximum(px.reshape(h, w, 4)[::-1, :, :3].astype(np.float64), 0.0)  # row 0 = top


def main():
    argv = sys.argv[sys.argv.index("--") + 1:]
    n, s = 32, 4
    if "--n" in argv:
        i = argv.index("--n"); n = int(argv[i + 1]); del argv[i:i + 2]
    for name in argv:
        L = load(name)
        h, w, _ = L.shape
        # sub-cell centres in pixel coordinates, cells clipped at [0, w-1] x [0, h-1]
        def edges(N):
            e = []
            for p in range(N):
                lo, hi = max(p - .5, 0), min(p + .5, N - 1)
                e.append(lo + (hi - lo) * np.arange(s + 1) / s)
            return np.array(e)  # N x (s+1)
        ex, ey = edges(w), edges(h)
        phi_e = -2 * np.pi * (ex / (w - 1) - .5)          # w x s+1
        th_e = np.pi * (.5 - ey / (h - 1))                 # h x s+1
        dphi = np.abs(np.diff(phi_e, axis=1))              # w x s
        dsin = np.sin(th_e[:, :-1]) - np.sin(th_e[:, 1:])  # h x s
        phic = (phi_e[:, :-1] + phi_e[:, 1:]) / 2
        thc = (th_e[:, :-1] + th_e[:, 1:]) / 2
        # full grid: rows (h,s) x cols (w,s)
        TH = thc.reshape(-1)[:, None]; PH = phic.reshape(-1)[None, :]
        Om = dsin.reshape(-1)[:, None] * dphi.reshape(-1)[None, :]
        dx = np.sin(PH) * np.cos(TH); dy = np.sin(TH) * np.ones_like(PH); dz = np.cos(PH) * np.cos(TH)
        Lsub = np.repeat(np.repeat(L, s, axis=0), s, axis=1)
        ax = np.stack([np.abs(dx), np.abs(dy), np.abs(dz)])
        face = np.argmax(ax, axis=0)
        m = np.max(ax, axis=0)
        comps = [dx, dy, dz]
        # face id with sign, u,v the other two components / m
        u = np.where(face == 0, dy, dx) / m
        v = np.where(face == 2, dy, dz) / m
        sign = np.where(np.choose(face, comps) > 0, 0, 1)
        fid = face * 2 + sign
        tx = np.clip(((u + 1) / 2 * n).astype(int), 0, n - 1); ty = np.clip(((v + 1) / 2 * n).astype(int), 0, n - 1)
        tex = (fid * n + ty) * n + tx
        cosg = np.maximum(dy, 0)
        T = tex.ravel(); O = Om.ravel(); C = (cosg * Om).ravel()
        So = np.bincount(T, O, 6 * n * n); Sc = np.bincount(T, C, 6 * n * n)
        for c, ch in enumerate("RGB"):
            LO = np.bincount(T, (Lsub[:, :, c] * Om).ravel(), 6 * n * n)
            exact = np.sum(Lsub[:, :, c] * cosg * Om) / np.pi
            prt = np.sum(LO / np.maximum(So, 1e-30) * Sc) / np.pi
            print(name.split("/")[-1], ch, "exact E/pi %.5f  cubemap n=32 %.5f  ratio %.4f" % (exact, prt, prt / exact), "power", np.sum(Lsub[:,:,c]*Om))

main()
