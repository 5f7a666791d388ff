"""Cycles render of a prtfarm image run's camera view, for bench/cycles/compare.py.

    blender -b --factory-startup --python bench/cycles/render_camera.py -- \
        --scene DIR/scene.json --env MAP.exr --out render.exr \
        [--samples 128] [--seed 1] [--bounces 0] [--glossy-bounces 0] \
        [--pixel centre|box] [--index-out index.exr] [--threads 0]

scene.json and its mesh files come from bench/cycles/export_scene.py (the farm's own world-space
geometry, shading normals, camera and materials). What the render is:

* Frame. prtfarm's world is +Y up; Blender's world is +Z up and Cycles' equirectangular lookup
  puts +Z at the top row, +X at the image centre and +Y at u = 1/4. prtfarm (OpenEXR LatLongMap)
  puts +Y at the top row, +Z at the centre column and +X at column (w-1)/4
  (docs/conventions.md). Mapping every prtfarm point and direction p = (x, y, z) to Blender's
  (z, x, y) (a rotation, det +1) makes both lookups agree, so the geometry and the camera are
  rotated and the environment is looked up unrotated (no shader remap: Cycles' importance map
  stays aligned with the map's pixels). The remaining difference is the pixel-centre convention
  ((x+1/2)/w in Cycles against OpenEXR's x/(w-1)): under half a map pixel.
* Camera. Pinhole at eye looking at target, image right = forward x up, vertical fov, square
  pixels (vocabulary/camera_projection.h). --pixel centre: every sample's ray goes through the
  pixel centre (x+1/2, y+1/2) to within 0.005 px, as the farm's default image run: a GAUSSIAN
  pixel filter of width 0.01. Not BOX: Blender 3.4's Cycles ignores filter_width for the box
  filter and always spreads a box over the whole pixel (measured: with BOX 0.01, 410 of 19,200
  pixels of the bunny image see two meshes among 64 samples, the silhouette pixels; with
  GAUSSIAN 0.01, 13). --pixel box: a box filter over the pixel's footprint (width 1), for
  [camera] supersample runs.
* Materials. brdf "lambert": Diffuse BSDF (roughness 0, colour = albedo). brdf "ggx":
  Add(Diffuse BSDF(albedo), Glossy BSDF(GGX, colour = specular, roughness r)); Cycles squares r
  (alpha = r^2), has no Fresnel on the Glossy BSDF and uses separable Smith G1*G1. Shading
  normals are the farm's per-vertex normals (custom split normals, smooth shading).
  Shadow-terminator offsets are 0 (rays leave the true surface).
  --glossy-camera-only: Mix(Diffuse, Add(Diffuse, Glossy), Light Path "Is Camera Ray"), so that
  bounce rays see a GGX surface's diffuse part only (what prtfarm's glossy pixels with bounces
  assume of the surfaces their bounce rays reach, docs/image-relighting.md "Glossy pixels").
* World: the environment's file values as radiance (no colour transform), Closest interpolation
  (piecewise-constant pixels, as prtfarm reads a map), importance sampled with a map of the
  environment's own width.
* Integrator: --samples per pixel, no adaptive sampling, no denoising, no clamping, no fast GI,
  no glossy filter; max bounces = max(--bounces, --glossy-bounces), diffuse bounces = --bounces
  (0 = direct light only), glossy bounces = --glossy-bounces.
* Output: linear float32 RGB OpenEXR, row 0 = top. --index-out writes a second EXR from a
  1-sample, centre-ray render where each mesh emits (index + 1) and the background 0, so the
  pixel grouping can be checked against the farm's image.prti.
"""

import argparse
import json
import math
import os
import sys
import time

import bpy
import numpy as np
from mathutils import Matrix, Vector


def parse_args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    p = argparse.ArgumentParser(prog="blender -b --factory-startup --python render_camera.py --")
    p.add_argument("--scene", required=True, help="scene.json from export_scene.py")
    p.add_argument("--env", required=True, help="equirectangular environment (.exr / .hdr)")
    p.add_argument("--out", required=True, help="output EXR")
    p.add_argument("--samples", type=int, default=128)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--bounces", type=int, default=0, help="diffuse bounces (0 = direct only)")
    p.add_argument("--glossy-bounces", type=int, default=0)
    p.add_argument("--glossy-camera-only", action="store_true",
                   help="a GGX material's glossy lobe for camera rays only; other rays see its "
                        "Diffuse BSDF (prtfarm's approximation for glossy pixels with bounces)")
    p.add_argument("--pixel", choices=["centre", "box"], default="centre",
                   help="centre: one ray through the pixel centre (Gaussian filter of width "
                        "0.01); box: the pixel's footprint (box filter, width 1)")
    p.add_argument("--index-out", default=None, help="also write the per-pixel mesh index EXR")
    p.add_argument("--threads", type=int, default=0, help="0 = all cores")
    p.add_argument("--save-blend", default=None)
    return p.parse_args(argv)


def to_blender(v):
    """prtfarm (x, y, z), +Y up -> Blender (z, x, y), +Z up."""
    return (v[2], v[0], v[1])


def load_mesh(base, m):
    nv, nf = m["vertices"], m["triangles"]
    raw = np.fromfile(os.path.join(base, m["file"]), dtype="<u4")
    pos = raw[:3 * nv].view("<f4").reshape(nv, 3)
    nrm = raw[3 * nv:6 * nv].view("<f4").reshape(nv, 3)
    tri = raw[6 * nv:6 * nv + 3 * nf]
    assert tri.size == 3 * nf, m["file"]
    pos = pos[:, [2, 0, 1]].astype(np.float32)
    nrm = nrm[:, [2, 0, 1]].astype(np.float32)
    me = bpy.data.meshes.new(m["name"])
    me.vertices.add(nv)
    me.vertices.foreach_set("co", pos.ravel())
    me.loops.add(3 * nf)
    me.loops.foreach_set("vertex_index", tri.astype(np.int32))
    me.polygons.add(nf)
    me.polygons.foreach_set("loop_start", np.arange(0, 3 * nf, 3, dtype=np.int32))
    me.polygons.foreach_set("loop_total", np.full(nf, 3, dtype=np.int32))
    me.update(calc_edges=True)
    me.polygons.foreach_set("use_smooth", np.ones(nf, dtype=bool))
    if hasattr(me, "use_auto_smooth"):  # Blender < 4.1: custom normals need auto smooth
        me.use_auto_smooth = True
        me.auto_smooth_angle = math.pi
    me.normals_split_custom_set_from_vertices([tuple(n) for n in nrm])
    me.update()
    ob = bpy.data.objects.new(m["name"], me)
    bpy.context.scene.collection.objects.link(ob)
    ob.pass_index = m["index"] + 1
    ob.cycles.shadow_terminator_geometry_offset = 0.0
    ob.cycles.shadow_terminator_offset = 0.0
    return ob


def material(m, glossy_camera_only=False):
    mat_desc = m["material"]
    if "unsupported" in mat_desc:
        sys.exit("render_camera.py: mesh %r: %s" % (m["name"], mat_desc["unsupported"]))
    mat = bpy.data.materials.new(m["name"] + "-mat")
    mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    out.target = "ALL"
    diffuse = nt.nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = list(mat_desc["albedo"]) + [1.0]
    diffuse.inputs["Roughness"].default_value = 0.0
    shader = diffuse.outputs["BSDF"]
    if mat_desc["brdf"] == "ggx":
        glossy = nt.nodes.new("ShaderNodeBsdfGlossy")
        glossy.distribution = "GGX"
        glossy.inputs["Color"].default_value = list(mat_desc["specular"]) + [1.0]
        glossy.inputs["Roughness"].default_value = mat_desc["roughness"]
        add = nt.nodes.new("ShaderNodeAddShader")
        nt.links.new(diffuse.outputs["BSDF"], add.inputs[0])
        nt.links.new(glossy.outputs["BSDF"], add.inputs[1])
        shader = add.outputs["Shader"]
        if glossy_camera_only:
            # Mix(Diffuse, Diffuse + Glossy, Is Camera Ray): a bounce ray that reaches this
            # surface sees its diffuse part only, as prtfarm's vertex support rows do.
            path = nt.nodes.new("ShaderNodeLightPath")
            mix = nt.nodes.new("ShaderNodeMixShader")
            nt.links.new(path.outputs["Is Camera Ray"], mix.inputs["Fac"])
            nt.links.new(diffuse.outputs["BSDF"], mix.inputs[1])
            nt.links.new(add.outputs["Shader"], mix.inputs[2])
            shader = mix.outputs["Shader"]
    nt.links.new(shader, out.inputs["Surface"])
    return mat


def emission_material(name, value):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    em = nt.nodes.new("ShaderNodeEmission")
    em.inputs["Color"].default_value = (value, value, value, 1.0)
    em.inputs["Strength"].default_value = 1.0
    nt.links.new(em.outputs["Emission"], out.inputs["Surface"])
    return mat


def assign(ob, mat):
    ob.data.materials.clear()
    ob.data.materials.append(mat)


def setup_world(scene, env_path):
    world = bpy.data.worlds.new("env")
    scene.world = world
    world.use_nodes = True
    nt = world.node_tree
    nt.nodes.clear()
    img = bpy.data.images.load(os.path.abspath(env_path), check_existing=False)
    img.colorspace_settings.name = "Non-Color"  # file values are radiance
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    env.image = img
    env.projection = "EQUIRECTANGULAR"
    env.interpolation = "Closest"
    bg = nt.nodes.new("ShaderNodeBackground")
    bg.inputs["Strength"].default_value = 1.0
    out = nt.nodes.new("ShaderNodeOutputWorld")
    out.target = "ALL"
    nt.links.new(env.outputs["Color"], bg.inputs["Color"])
    nt.links.new(bg.outputs["Background"], out.inputs["Surface"])
    # importance map at the map's own resolution (Cycles' AUTOMATIC picks 4096x2048 for a
    # 1024x512 map, minutes of set-up on a loaded 2-core machine; it only changes the noise)
    world.cycles.sampling_method = "MANUAL"
    world.cycles.sample_map_resolution = max(img.size[0], 64)
    world.cycles.max_bounces = 1024
    return world, list(img.size)


def setup_camera(scene, cam_desc):
    eye = Vector(to_blender(cam_desc["eye"]))
    target = Vector(to_blender(cam_desc["target"]))
    up = Vector(to_blender(cam_desc["up"]))
    fwd = (target - eye).normalized()
    right = fwd.cross(up).normalized()  # CameraProjection: right = forward x up
    cam_up = right.cross(fwd)
    z = -fwd  # Blender cameras look along local -Z, local +Y is image up
    data = bpy.data.cameras.new("cam")
    data.type = "PERSP"
    data.sensor_fit = "VERTICAL"
    data.angle_y = math.radians(cam_desc["fov_deg"])
    data.shift_x = data.shift_y = 0.0
    data.clip_start = 1e-5
    data.clip_end = 1e8
    cam = bpy.data.objects.new("cam", data)
    scene.collection.objects.link(cam)
    cam.matrix_world = Matrix(((right.x, cam_up.x, z.x, eye.x), (right.y, cam_up.y, z.y, eye.y),
                               (right.z, cam_up.z, z.z, eye.z), (0, 0, 0, 1)))
    scene.camera = cam
    r = scene.render
    r.resolution_x, r.resolution_y = cam_desc["width"], cam_desc["height"]
    r.resolution_percentage = 100
    r.pixel_aspect_x = r.pixel_aspect_y = 1.0


PIXEL_FILTERS = {"centre": ("GAUSSIAN", 0.01), "box": ("BOX", 1.0)}


def setup_render(scene, a, samples, bounces, glossy_bounces, pixel):
    scene.render.engine = "CYCLES"
    cy = scene.cycles
    cy.device = "CPU"
    cy.feature_set = "SUPPORTED"
    cy.samples = samples
    cy.use_adaptive_sampling = False
    cy.use_denoising = False
    cy.time_limit = 0.0
    cy.seed = a.seed
    cy.use_animated_seed = False
    cy.sample_clamp_direct = 0.0
    cy.sample_clamp_indirect = 0.0
    cy.light_sampling_threshold = 0.0
    cy.use_fast_gi = False
    cy.caustics_reflective = True
    cy.caustics_refractive = True
    cy.blur_glossy = 0.0
    cy.min_light_bounces = 0
    cy.diffuse_bounces = bounces
    cy.glossy_bounces = glossy_bounces
    cy.max_bounces = max(bounces, glossy_bounces)
    cy.transmission_bounces = 0
    cy.volume_bounces = 0
    cy.transparent_max_bounces = 0
    cy.pixel_filter_type, cy.filter_width = PIXEL_FILTERS[pixel]
    cy.film_exposure = 1.0
    r = scene.render
    r.film_transparent = False
    r.use_compositing = False
    r.use_sequencer = False
    r.dither_intensity = 0.0
    r.use_border = False
    r.threads_mode = "FIXED" if a.threads > 0 else "AUTO"
    if a.threads > 0:
        r.threads = a.threads
    scene.display_settings.display_device = "sRGB"
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    scene.view_settings.use_curve_mapping = False
    im = r.image_settings
    im.file_format = "OPEN_EXR"
    im.color_mode = "RGB"
    im.color_depth = "32"
    im.exr_codec = "ZIP"
    r.use_file_extension = False


def render(scene, path):
    scene.render.filepath = os.path.abspath(path)
    t0 = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    return time.perf_counter() - t0


def main():
    a = parse_args()
    desc = json.load(open(a.scene))
    base = os.path.dirname(os.path.abspath(a.scene))
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    objects = []
    for m in desc["meshes"]:
        ob = load_mesh(base, m)
        assign(ob, material(m, a.glossy_camera_only))
        objects.append(ob)
    world, env_size = setup_world(scene, a.env)
    setup_camera(scene, desc["camera"])
    os.makedirs(os.path.dirname(os.path.abspath(a.out)), exist_ok=True)
    setup_render(scene, a, a.samples, a.bounces, a.glossy_bounces, a.pixel)
    if a.save_blend:
        bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(a.save_blend))
    seconds = render(scene, a.out)
    meta = dict(scene=os.path.abspath(a.scene), env=os.path.abspath(a.env), env_size=env_size,
                samples=a.samples, seed=a.seed, diffuse_bounces=a.bounces,
                glossy_bounces=a.glossy_bounces, pixel=a.pixel,
                glossy_camera_only=a.glossy_camera_only,
                filter=list(PIXEL_FILTERS[a.pixel]),
                seconds=seconds, blender=bpy.app.version_string,
                threads=scene.render.threads)
    if a.index_out:
        # the mesh each pixel-centre ray sees: emission (index + 1), black world, 1 sample
        for m, ob in zip(desc["meshes"], objects):
            assign(ob, emission_material("index%d" % m["index"], float(m["index"] + 1)))
        world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
        setup_render(scene, a, 1, 0, 0, "centre")
        meta["index_seconds"] = render(scene, a.index_out)
    with open(os.path.splitext(a.out)[0] + ".json", "w") as f:
        json.dump(meta, f, indent=1)
    print("render_camera.py: %s in %.1f s (%d samples, seed %d, diffuse bounces %d, glossy %d, "
          "pixel %s)" % (a.out, seconds, a.samples, a.seed, a.bounces, a.glossy_bounces, a.pixel))


if __name__ == "__main__":
    main()
