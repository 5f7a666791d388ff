#!/usr/bin/env python3
"""Re-baking after an edit (issue 27; docs/farm.md "Stages and re-runs"): what re-runs.

For each kind of edit a lighting artist makes to a scene, farm the scene fresh once, copy that
finished run folder, edit the scene and run `prt-farm --resume` on the copy, and print what
re-ran (report.json "stages"), the rays traced and the wall time against the fresh run's, all
measured in one session on the same ranks. Writes the table to OUT/rebake.md too.

    scripts/bench.sh rebake          (OUT defaults to bench-out/rebake)
    rebake_bench.py BUILD_DIR OUT [--np 2] [--scene default]
"""
import argparse
import json
import os
import shutil
import subprocess
import sys
import time


def run_farm(build, np, scene, out, extra):
    cmd = ["mpirun", "-np", str(np), "--bind-to", "none", os.path.join(build, "farm", "prt-farm"),
           scene, "--out", out, "-q"] + extra
    t0 = time.monotonic()
    subprocess.run(cmd, check=True)
    return time.monotonic() - t0


def report(run):
    with open(os.path.join(run, "report.json")) as f:
        return json.load(f)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("build")
    ap.add_argument("out")
    ap.add_argument("--np", type=int, default=2)
    args = ap.parse_args()
    build, out = os.path.abspath(args.build), os.path.abspath(args.out)
    os.makedirs(out, exist_ok=True)
    data = os.path.join(build, "data")
    base = open(os.path.join(os.path.dirname(__file__), "..", "scenes", "default.toml")).read()
    base = base.replace('"meshes/', '"' + data + '/meshes/').replace('"envmaps/', '"' + data +
                                                                      '/envmaps/')

    def scene_file(name, text):
        path = os.path.join(out, name + ".toml")
        with open(path, "w") as f:
            f.write(text)
        return path

    def edit(old, new):
        assert old in base, old
        return base.replace(old, new, 1)

    edits = [
        ("albedo", edit("albedo = [0.8, 0.8, 0.8]", "albedo = [0.9, 0.5, 0.3]"), []),
        ("compression keep_fraction", edit("keep_fraction = 0.05", "keep_fraction = 0.1"), []),
        ("compression bits", edit("bits = 9", "bits = 12"), []),
        ("compression scheme", edit('scheme = "adaptive4d"', 'scheme = "4d"'), []),
        ("material (glossy lobe)", edit('albedo = [0.8, 0.8, 0.8]',
                                        'albedo = [0.8, 0.8, 0.8]\nbrdf = "phong"\n'
                                        'specular = [0.1, 0.1, 0.1]\nexponent = 30'), []),
        ("camera", edit("fov = 35.0", "fov = 45.0"), []),
        ("environments", edit('"' + data + '/envmaps/city.exr"]',
                              '"' + data + '/envmaps/city.exr", "' + data +
                              '/envmaps/studio.exr"]'), []),
        ("comment", edit("# prtfarm's default scene", "# prtfarm's default scene, edited"), []),
        ("rays per texel 4 -> 8", edit("rays_per_texel = 4", "rays_per_texel = 8"), []),
        ("mesh moved", edit('up = "+y" }', 'up = "+y" }\ntranslate = [0.1, 0.0, 0.0]'), []),
    ]

    fresh = os.path.join(out, "fresh")
    shutil.rmtree(fresh, ignore_errors=True)
    print("fresh run of the default scene ...", flush=True)
    t_fresh = run_farm(build, args.np, scene_file("base", base), fresh, ["--force"])
    rep_fresh = report(fresh)
    rows = [("fresh run", "rows, compression, estimate, assets", rep_fresh["rays_traced"], t_fresh,
             rep_fresh["wall_seconds"])]
    comp_fresh = next(s["wall_seconds"] for s in rep_fresh["stages"] if s["name"] == "compression")
    for name, text, extra in edits:
        run = os.path.join(out, "edit-" + name.split()[0] + str(len(rows)))
        shutil.rmtree(run, ignore_errors=True)
        shutil.copytree(fresh, run)
        print("edit:", name, "...", flush=True)
        t = run_farm(build, args.np, scene_file("edit%d" % len(rows), text), run,
                     ["--resume"] + extra)
        rep = report(run)
        ran = [s["name"] for s in rep["stages"]
               if s["status"] in ("ran", "resumed", "updated")]
        rows.append((name, ", ".join(ran) if ran else "nothing", rep["rays_traced"], t,
                     rep["wall_seconds"]))

    lines = ["| edit | re-ran | rays traced | wall (mpirun) s | prt-farm s | against fresh |",
             "|---|---|---|---|---|---|"]
    for name, ran, rays, t, wall in rows:
        lines.append("| %s | %s | %s | %.1f | %.1f | %.3fx |" %
                     (name, ran, "{:,}".format(rays), t, wall, t / t_fresh))
    lines.append("")
    lines.append("fresh run's compression stage alone: %.1f s (%.3fx the fresh run)" %
                 (comp_fresh, comp_fresh / t_fresh))
    text = "\n".join(lines)
    print(text)
    with open(os.path.join(out, "rebake.md"), "w") as f:
        f.write(text + "\n")


if __name__ == "__main__":
    sys.exit(main())
