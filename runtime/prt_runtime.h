/* prt_runtime: relight a .prtpack inside your own program (docs/runtime.md).
 *
 * One C99 header over prtfarm's relighter, the same code prt-view runs: environment map → lighting
 * cubemap (integrated over each texel's solid angle), its Haar wavelet projection, exact lighting
 * or a budget of wavelet terms (NWA, BI, PBI: Ng et al. 2003; Overbeck et al. 2006), and the
 * pack's transport: 2D, 4D and adaptive 4D compressed columns (Cheslack-Postava et al. 2008 §4.5,
 * Eq. 8), clustered PCA (Overbeck et al. 2006 §6.3), vertex or image packs, one or three colour
 * channels. Glossy packs (per-vertex visibility, no transport) are relit towards the eye by the
 * per-block triple products of Inger et al. 2013, Algorithm 1 (prt_runtime_is_glossy). The library
 * links the C++ standard library, Draco, zstd and xxHash only.
 *
 * Conventions
 * - Every function that can fail returns a status (PRT_RUNTIME_OK = 0, else a PRT_RUNTIME_ERROR_*
 *   code) or NULL, and leaves a message naming the pack and the problem, readable on the same
 *   thread with prt_runtime_last_error(). No function aborts, throws or prints.
 * - The caller owns every output buffer and says how large it is; a wrong size is an error,
 *   never a write past it.
 * - Radiance is linear RGB, 3 floats per sample: albedo × (T·L), what prt-view --radiance-out
 *   writes (a glossy pack: the outgoing radiance towards the eye, ∫ L V ρ̃ dω). Samples are the
 * pack's, in the pack's order (meshes in pack order, each mesh's vertices in order; an image pack's
 * pixels row-major from the top), unless prt_runtime_set_sample_order() chose the runtime's order.
 * - Threads: a handle is used by one thread at a time, except prt_runtime_relight_range(), which
 *   any number of threads may call at once on one handle between prt_runtime_prepare() and the
 *   next call of anything else. Different handles are independent. prt_runtime_set_task_runner()
 *   is process-wide: call it before opening handles.
 */
#ifndef PRT_RUNTIME_PRT_RUNTIME_H_
#define PRT_RUNTIME_PRT_RUNTIME_H_

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define PRT_RUNTIME_VERSION 1

/* Status codes. */
#define PRT_RUNTIME_OK 0
#define PRT_RUNTIME_ERROR_ARGUMENT 1 /* a NULL pointer, a wrong size, a value out of range */
#define PRT_RUNTIME_ERROR_STATE 2    /* a call out of order (relight before an environment) */
#define PRT_RUNTIME_ERROR_INPUT 3    /* an unreadable or corrupt pack, or a bad environment map */
#define PRT_RUNTIME_ERROR_NUMERIC 4  /* a radiance that is not a finite float (overflow) */
#define PRT_RUNTIME_ERROR_MEMORY 5   /* out of memory */

/* Lighting approximations for terms > 0 (prt_runtime_set_lighting_mode). */
#define PRT_RUNTIME_LIGHTING_NWA 0 /* the N largest area-weighted terms of each frame, afresh */
#define PRT_RUNTIME_LIGHTING_BI 1  /* basic incremental: N terms of the change per frame */
#define PRT_RUNTIME_LIGHTING_PBI 2 /* per-band incremental (the default) */

/* Sample orders (prt_runtime_set_sample_order). */
#define PRT_RUNTIME_ORDER_PACK 0    /* the pack's order (the default) */
#define PRT_RUNTIME_ORDER_RUNTIME 1 /* the relighter's own order: no gather per frame */

/* A glossy pack's BRDF models (prt_runtime_material.brdf). */
#define PRT_RUNTIME_BRDF_LAMBERT 0
#define PRT_RUNTIME_BRDF_PHONG 1
#define PRT_RUNTIME_BRDF_ASHIKHMIN_SHIRLEY 2

typedef struct prt_runtime prt_runtime; /* opaque */

/* One mesh's material of a glossy pack (docs/scene-format.md, "Glossy materials"). */
typedef struct prt_runtime_material {
  int brdf;          /* PRT_RUNTIME_BRDF_* */
  float diffuse[3];  /* albedo of the Lambert part, each in [0, 1] */
  float specular[3]; /* weight of the specular lobe, each in [0, 1] (ignored for Lambert) */
  double exponent;   /* Phong s, Ashikhmin-Shirley n_u: in (0, 1e6] */
  double exponent_v; /* Ashikhmin-Shirley n_v: in (0, 1e6] */
} prt_runtime_material;

/* ---- Opening ------------------------------------------------------------------------------ */

/* Reads the pack (meshes, materials, metadata, the whole compressed transport) and readies it
 * for relighting. Needs: a readable .prtpack with a transport (TRNS or CPCA section), or a glossy
 * pack: visibility (VISB sections) and no transport, opened as prt-view opens it (its meshes,
 * per-vertex visibility and the materials of its metadata).
 * Returns NULL on error: an unreadable file, a corrupt or truncated pack (every checksum and
 * size is checked), a pack with neither transport nor visibility, memory. Safe on hostile
 * input. */
prt_runtime* prt_runtime_open_file(const char* path);
/* The same from bytes in memory (copied as needed: `data` may be freed after the call). */
prt_runtime* prt_runtime_open_memory(const void* data, size_t size);
/* Frees the handle and everything it owns. NULL is allowed. */
void prt_runtime_close(prt_runtime* rt);

/* This thread's last error message, "" if none. Valid until the next prt_runtime call on this
 * thread. */
const char* prt_runtime_last_error(void);

/* ---- What the pack holds ------------------------------------------------------------------ */

/* Spatial samples: vertices of all meshes, or an image pack's pixels. 0 for NULL. */
size_t prt_runtime_sample_count(const prt_runtime* rt);
/* 1 for an image pack (samples are the pixels of a fixed camera), else 0. */
int prt_runtime_is_image(const prt_runtime* rt);
/* 1 for a glossy pack, else 0. A glossy pack's samples are its vertices in the pack's order
 * (meshes in pack order, each mesh's vertices in order; the runtime's order is the same), each
 * with the material of its mesh from the pack's metadata (Lambert, Phong or Ashikhmin-Shirley;
 * docs/scene-format.md, "Glossy materials"). Its radiance depends on the view: every frame is
 * Algorithm 1 of Inger et al. 2013 for every vertex towards the eye (prt_runtime_set_eye), with
 * the exact diffuse cosine (prt-view's default). Terms, the lighting mode and PBI do not apply:
 * every relight is the full frame, whatever `terms`. Everything else (maps, rotation, preview,
 * ranges, the task runner) works as for a vertex pack. */
int prt_runtime_is_glossy(const prt_runtime* rt);
/* BRDF terms m of a glossy vertex pack (a GLSY section, docs/glossy-transport.md): its transport
 * holds m rows per vertex, relit like any vertex pack (every lighting mode, terms, PBI) and
 * combined per vertex for the eye (prt_runtime_set_eye) as B = w ⊙ Σ_i g_i(ω_o)·(T_i·L). A new
 * eye changes the next relight's colours only through that m-term sum; with PBI and unchanged
 * lighting the relight after an orbit step costs little more than the sum. 1 for any other
 * pack with a transport, 0 for a triple-product glossy pack. */
unsigned prt_runtime_brdf_terms(const prt_runtime* rt);
/* A glossy vertex pack (prt_runtime_brdf_terms > 1): the last relight's terms combined again for
 * the current eye (prt_runtime_set_eye), into out_rgb (out_samples = prt_runtime_sample_count,
 * the current order), without relighting: what a camera move costs (the m-term sum per vertex).
 * PRT_RUNTIME_ERROR_STATE for any other pack or before the first relight. */
int prt_runtime_reshade(prt_runtime* rt, float* out_rgb, size_t out_samples);
/* Colour channels of the transport (1, or 3 with coloured interreflection); 0 for a glossy
 * pack. */
unsigned prt_runtime_transport_channels(const prt_runtime* rt);
/* Lighting cubemap face size n (a glossy pack: its visibility's), and its 6·n² wavelet
 * coefficients (the largest useful term budget). */
unsigned prt_runtime_cubemap_size(const prt_runtime* rt);
unsigned prt_runtime_coefficient_count(const prt_runtime* rt);

/* Geometry of a vertex pack, for drawing: positions (3 floats per sample, the pack's order and
 * coordinates) and triangles (3 sample indices each, into the same order, all meshes).
 * prt_runtime_triangle_count is 0 for an image pack. The output sizes must match exactly
 * (PRT_RUNTIME_ERROR_ARGUMENT otherwise). Unaffected by prt_runtime_set_sample_order. */
size_t prt_runtime_triangle_count(const prt_runtime* rt);
int prt_runtime_get_positions(const prt_runtime* rt, float* xyz, size_t samples);
int prt_runtime_get_triangles(const prt_runtime* rt, uint32_t* indices, size_t triangles);

/* Which pixels of an image pack see the environment rather than a surface: background[i] = 1 for
 * such a pixel, 0 for a surface pixel, one byte per sample in the pack's order (pixels row-major
 * from the top; unaffected by prt_runtime_set_sample_order). Their radiance is always 0: a viewer
 * draws the environment there, as prt-view does. `samples` must equal prt_runtime_sample_count;
 * PRT_RUNTIME_ERROR_ARGUMENT for a vertex pack. */
int prt_runtime_get_image_background(const prt_runtime* rt, uint8_t* background, size_t samples);
/* How much of each pixel of an image pack is surface: coverage[i] in [0, 1], one float per sample
 * in the same order as prt_runtime_get_image_background. 1 on surface pixels and 0 on background
 * ones, except in a supersampled pack ([camera] supersample = k > 1, .prtpack 1.5;
 * docs/image-relighting.md, "Supersampling"), where it is the fraction of the pixel's k² rays that
 * hit a surface. A viewer draws radiance + (1 − coverage) · environment along the pixel's ray
 * (the runtime's radiance already holds the pixel's own weight). Errors as
 * prt_runtime_get_image_background. */
int prt_runtime_get_image_coverage(const prt_runtime* rt, float* coverage, size_t samples);

/* The camera the pack was baked with (an image pack's fixed view; a vertex pack's scene camera,
 * or prt-view's default when its scene had none): eye, target, up, vertical field of view in
 * degrees, width and height in pixels. Any pointer may be NULL. Unaffected by
 * prt_runtime_set_eye. */
int prt_runtime_get_camera(const prt_runtime* rt, float eye[3], float target[3], float up[3],
                           float* fov_deg, int* width, int* height);

/* The eye a glossy pack is relit towards (world coordinates, the pack's), set as often as every
 * frame; the pack's camera eye after opening. Cheap: the next relight uses it. Every component
 * must be finite (PRT_RUNTIME_ERROR_ARGUMENT otherwise). Accepted for every pack, so that a
 * viewer orbits any pack the same way; a vertex or image pack's radiance does not depend on it. */
int prt_runtime_set_eye(prt_runtime* rt, const float eye[3]);
int prt_runtime_get_eye(const prt_runtime* rt, float eye[3]);

/* A glossy pack's materials, one per mesh in pack order, from its metadata at opening (a mesh
 * without an entry is Lambert with its albedo); editable between frames: the next relight uses
 * them. prt_runtime_material_count is the mesh count of a glossy pack, 0 for any other (a vertex
 * pack's materials are baked into its transport). get/set: `mesh` < the count, every field in
 * its range (PRT_RUNTIME_ERROR_ARGUMENT otherwise; a refused material leaves the old one). */
unsigned prt_runtime_material_count(const prt_runtime* rt);
int prt_runtime_get_material(const prt_runtime* rt, unsigned mesh, prt_runtime_material* out);
int prt_runtime_set_material(prt_runtime* rt, unsigned mesh, const prt_runtime_material* material);

/* ---- Lighting ----------------------------------------------------------------------------- */

/* Linear RGB float lat-long map, rows from the top, width = 2 x height, OpenEXR's LatLongMap
   convention (+Y up), as prt-view reads an EXR. 0 on success.
 * rgb: width·height·3 floats, pixel (x, y) at 3·(y·width + x). Needs height ≥ 2, every value
 * finite (PRT_RUNTIME_ERROR_INPUT naming the pixel otherwise; negative values count as 0 light,
 * as prt-view clamps them). The map is copied; the lighting is resampled under the current
 * rotation. On error the previous environment stays. */
int prt_runtime_set_environment_latlong(prt_runtime* rt, const float* rgb, int width, int height);

/* Rotation of the environment: a direction d of the map lights from rotation·d. Row-major 3×3,
 * orthonormal with determinant +1 (to 1e-4; PRT_RUNTIME_ERROR_ARGUMENT otherwise). The identity
 * by default. Resamples the lighting when an environment is set (the cost of a frame's lighting:
 * see docs/runtime.md). */
int prt_runtime_set_rotation(prt_runtime* rt, const float rotation[9]); /* row-major */
/* The same, as an angle in radians about +Y (+Z turns towards +X), prt-view's --rotate. */
int prt_runtime_set_rotation_y(prt_runtime* rt, double radians);

/* Interactive rotation. Resampling the full map under a new rotation integrates every pixel over
 * the texels (tens of ms for 1024 × 512 at n = 32; docs/runtime.md, "Speed"). With preview = 1 a
 * rotation about +Y (prt_runtime_set_rotation_y, or a matrix about +Y) is one sparse pass over
 * precomputed weights instead: the map averaged onto a periodic grid 16·n cells wide (exact cell
 * means: the same power), its cell → texel weights integrated once, then shifted by the angle
 * (whole cells, blended linearly between them); about 1 ms native at n = 32. A general rotation
 * resamples a copy of the map reduced to 16·n pixels wide. The first preview frame after a new
 * map builds these (about the cost of one full resampling). With preview = 0 (the default) the
 * full map is resampled exactly again: a viewer sets 1 while the user drags and 0 when the
 * rotation stops, so that PBI converges to the exact frame. Resamples the lighting when an
 * environment is set and the setting changes. */
int prt_runtime_set_preview(prt_runtime* rt, int preview);

/* PRT_RUNTIME_LIGHTING_NWA, _BI or _PBI (the default) for relights with terms > 0. Switching
 * restarts the incremental state (its next frame starts from no light). Accepted and ignored for
 * a glossy pack. */
int prt_runtime_set_lighting_mode(prt_runtime* rt, int mode);

/* PRT_RUNTIME_ORDER_PACK (the default) or PRT_RUNTIME_ORDER_RUNTIME: the order of the samples in
 * every radiance output and in relight ranges. The runtime's order (each mesh along its Hilbert
 * curve) is the one the relighter produces, so a frame in it skips a gather; remap your vertex
 * buffer once with prt_runtime_get_sample_order. */
int prt_runtime_set_sample_order(prt_runtime* rt, int order);
/* pack_index[p] = the pack sample at position p of the runtime's order (`samples` entries). */
int prt_runtime_get_sample_order(const prt_runtime* rt, uint32_t* pack_index, size_t samples);

/* ---- Relighting --------------------------------------------------------------------------- */

/* Radiance per sample (RGB, samples x 3 floats): terms = 0 exact lighting, else that many
   wavelet terms (NWA, or PBI frames after prt_runtime_set_lighting_mode). 0 on success.
 * Needs an environment (PRT_RUNTIME_ERROR_STATE otherwise) and out_samples equal to
 * prt_runtime_sample_count (PRT_RUNTIME_ERROR_ARGUMENT). With BI or PBI each call is one frame:
 * it spends `terms` terms on the change since the last frame, so calls under still lighting
 * converge to the exact radiance. PRT_RUNTIME_ERROR_NUMERIC when a radiance overflows float.
 * A glossy pack: the full frame towards the current eye whatever `terms` (Algorithm 1; equals
 * prt-view --radiance-out of the same view). */
int prt_runtime_relight(prt_runtime* rt, unsigned terms, float* out_rgb, size_t out_samples);

/* A frame split across the host's threads, in two calls:
 * 1. prt_runtime_prepare(rt, terms) on one thread: chooses the frame's lighting terms (as
 *    prt_runtime_relight would; for BI and PBI it advances the incremental state). Cheap: no
 *    per-sample work.
 * 2. prt_runtime_relight_range(rt, first, count, out_rgb, out_samples) for ranges that together
 *    cover [0, sample count) exactly once, from any threads at the same time: each does its
 *    range's share of the frame (the transport's region of interest, docs/runtime.md,
 *    "Splitting a frame") and writes its samples' radiance into out_rgb (3 × sample count
 *    floats). Ranges are positions of the runtime's order (prt_runtime_get_sample_order): in
 *    that order a range writes out_rgb[3·first … 3·(first + count)); in the pack's order the
 *    same samples land at their pack positions, so a partition of [0, n) still writes every
 *    sample once. The values equal prt_runtime_relight's to float rounding (1e-6 relative).
 * prepare returns PRT_RUNTIME_ERROR_STATE when the previous prepared frame of an incremental
 * mode was not relit in full (its state would be torn); so does prt_runtime_relight.
 * A glossy pack: prepare only checks that there is an environment; each range relights its
 * vertices towards the eye current when it runs (do not call prt_runtime_set_eye while ranges
 * run), with the same values as prt_runtime_relight. */
int prt_runtime_prepare(prt_runtime* rt, unsigned terms);
int prt_runtime_relight_range(prt_runtime* rt, size_t first, size_t count, float* out_rgb,
                              size_t out_samples);

/* A host job system for the runtime's own parallel loops (process-wide; NULL: run on the calling
 * thread, the default). run(user, count, task, task_data) must call task(task_data, i) once for
 * every i in [0, count), on any threads, and return when all have returned. `concurrency` is
 * how many threads run will use (the runtime splits work into about that many parts). */
typedef void (*prt_runtime_task_runner)(void* user, size_t count,
                                        void (*task)(void* task_data, size_t index),
                                        void* task_data);
void prt_runtime_set_task_runner(prt_runtime_task_runner run, void* user, unsigned concurrency);

/* The largest decoded size of any one pack section or transport block that opening accepts
 * (process-wide; default 2 GiB, the reader's). A pack that claims more is refused with
 * PRT_RUNTIME_ERROR_INPUT before anything of that size is allocated: a host on a memory budget
 * (a browser tab, a console) sets its own. 0 restores the default. */
void prt_runtime_set_max_section_bytes(uint64_t bytes);

/* Bytes the handle holds (pack data, relighter, lighting and incremental state). */
size_t prt_runtime_memory_bytes(const prt_runtime* rt);

#ifdef __cplusplus
}
#endif

#endif /* PRT_RUNTIME_PRT_RUNTIME_H_ */
