#!/usr/bin/env python3
"""The Pareto front of precomputation time against error for one scene (docs/sparse-
precomputation.md, "With interreflection"): every method of prt-sparse-gi-bench's results.csv
files given (brute force and the sparse variants, gathering and path tracing) as a point, wall
seconds against the mean relative RMS error of relit B against the path-traced reference (model
and ground, every light). Writes <out>/sparse-gi-pareto-<scene>.png with gnuplot and prints the
points. Usage: sparse_gi_pareto.py OUT SCENE results.csv [results.csv ...]"""
import csv, subprocess, sys

out, scene, files = sys.argv[1], sys.argv[2], sys.argv[3:]
points = {}
for f in files:
    for r in csv.DictReader(open(f)):
        if r["scene"] != scene:
            continue
        name = f'{r["estimator"]} {r["method"]}' + (f' [{r["variant"]}]' if r["variant"] else "")
        p = points.setdefault(name, {"s": float(r["seconds"]), "e": []})
        p["e"].append(0.5 * (float(r["ref_model"]) + float(r["ref_ground"])))
rows = sorted((p["s"], sum(p["e"]) / len(p["e"]), n) for n, p in points.items())
front, best = [], float("inf")
for s, e, n in rows:
    if e < best:
        front.append(n)
        best = e
dat = f"{out}/sparse-gi-pareto-{scene}.dat"
with open(dat, "w") as d:
    for s, e, n in rows:
        d.write(f'{s} {e} "{n}"\n')
        print(f"{scene:10s} {n:42s} {s:8.2f} s  {100 * e:6.2f} %{'  (front)' if n in front else ''}")
png = f"{out}/sparse-gi-pareto-{scene}.png"
cmd = (f"set terminal pngcairo size 900,520 noenhanced; set output '{png}'; set logscale x; "
       f"set xlabel 'precomputation wall s, 2 cores, n = 32, K = 2'; "
       f"set ylabel 'relative RMS error vs the path-traced reference'; set format y '%.1f%%'; "
       f"set title '{scene}: time against error (brute force, gathering, path tracing, sparse)'; "
       f"plot '{dat}' using 1:($2*100) with points pt 7 ps 1.3 notitle, "
       f"'' using 1:($2*100):3 with labels offset 0,1 font ',8' notitle")
subprocess.run(["gnuplot", "-e", cmd], check=False)
print(f"wrote {png}")
