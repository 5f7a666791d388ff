/* Plain C interface to the .prtpack reader (docs/prtpack-format.md), for runtimes and engines
 * that do not speak C++. Same guarantees as prtpack_reader.h: safe on untrusted input; every
 * failure returns NULL or PRTPACK_ERROR and leaves a message, readable with prtpack_last_error()
 * on the same thread, that names the file and the problem. No function aborts or throws.
 *
 * Memory: a prtpack handle owns everything it returns pointers to (meshes, metadata, transport
 * parameters, the CPCA transport's arrays); the pointers stay valid until prtpack_close().
 * Transport blocks are copied into caller memory. A handle may be used from one thread at a time.
 */
#ifndef PRT_PACKAGER_PRTPACK_H_
#define PRT_PACKAGER_PRTPACK_H_

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define PRTPACK_OK 0
#define PRTPACK_ERROR (-1)

typedef struct prtpack prtpack; /* opaque */

typedef struct prtpack_section_info {
  char type[5];         /* FourCC, NUL-terminated ("MESH"); unprintable bytes shown as '?' */
  uint32_t flags;       /* bit 0: critical */
  uint32_t codec;       /* 0 none, 1 zstd, 2 draco */
  uint32_t id;          /* mesh index for MESH and MATL */
  uint64_t offset;      /* in the file, aligned */
  uint64_t stored_size; /* bytes in the file */
  uint64_t raw_size;    /* bytes once decoded */
  uint64_t checksum;    /* XXH64 of the stored bytes */
  int known;            /* 1 if this reader understands the section type */
} prtpack_section_info;

typedef struct prtpack_mesh {
  const char* name; /* NUL-terminated */
  size_t vertex_count;
  size_t triangle_count;
  const float* positions;    /* 3 × vertex_count; vertex i is vertex i of the packed mesh */
  const float* normals;      /* 3 × vertex_count, unit */
  const uint32_t* triangles; /* 3 × triangle_count, indices < vertex_count */
  float albedo[3];           /* linear RGB in [0, 1] */
  int is_ground;             /* 1 for the ground plane */
  uint32_t grid_resolution;  /* ground plane: vertices per side, else 0 */
} prtpack_mesh;

/* The transport T has row_count rows (channels × V spatial samples; V = the meshes' vertices in
 * mesh order) and column_count columns. Rows are channel-major: row c·V + v is colour channel c
 * (0 r, 1 g, 2 b) of spatial sample v, so that B_c(v) = albedo_c(v) · Σ_j T[c·V + v][j]·L_c[j].
 * With channels = 1 (every 1.0 pack) one row per sample serves r, g and b:
 * B_c(v) = albedo_c(v) · Σ_j T[v][j]·L_c[j]. */
typedef struct prtpack_transport_info {
  uint32_t encoding;     /* the transport encoder's format version */
  uint64_t row_count;    /* rows of T: channels × spatial samples */
  uint64_t column_count; /* columns over all blocks */
  size_t block_count;
  const uint8_t* params; /* opaque global parameters (owned by the handle) */
  size_t params_size;
  uint32_t channels; /* colour channels of T, 1 or 3 (.prtpack 1.1; 1 in a 1.0 pack) */
} prtpack_transport_info;

typedef struct prtpack_block_info {
  uint64_t first_column;
  uint32_t column_count;
  uint64_t raw_size; /* bytes prtpack_get_transport_block writes */
} prtpack_block_info;

/* Image relighting (.prtpack 1.2, the IMGE section): the rows of T are the pixels of a fixed
 * camera, row-major from the top-left (V = width·height), instead of mesh vertices. A pixel's
 * radiance is B_c(p) = w_c(pixel_mesh[p]) · Σ_j T[c·V + p][j]·L_c[j], w the mesh's weight from
 * prtpack_get_image_weight: its albedo, or for glossy pixels (.prtpack 1.4) the colour their
 * rows were normalised by (docs/image-relighting.md, "Glossy pixels"); a pixel whose
 * pixel_mesh is PRTPACK_BACKGROUND sees the environment itself (its row is 0): draw the
 * environment map along the camera ray (pinhole at eye looking at target, vertical fov_deg,
 * pixel centres at +½; docs/image-relighting.md). */
#define PRTPACK_BACKGROUND 0xFFFFFFFFu
typedef struct prtpack_image_info {
  uint32_t width;
  uint32_t height;
  double eye[3];
  double target[3];
  double up[3];
  double fov_deg;             /* vertical field of view */
  const uint32_t* pixel_mesh; /* width·height mesh indices or PRTPACK_BACKGROUND (owned) */
} prtpack_image_info;

/* The kind of transport a pack carries (prtpack_transport_kind): none (geometry, perhaps
 * visibility), compressed columns (the TRNS section: prtpack_get_transport_info and blocks) or
 * clustered PCA (the CPCA section, .prtpack 1.3: prtpack_get_cpca_info and vectors). */
#define PRTPACK_TRANSPORT_NONE 0
#define PRTPACK_TRANSPORT_COLUMNS 1
#define PRTPACK_TRANSPORT_CPCA 2

/* A clustered-PCA transport (docs/cpca.md): row r of T, taken in the orthonormal row-wavelet
 * basis (row_wavelet: 0 Haar, 1 D4, over the cubemap of docs/conventions.md, column_count =
 * 6·cubemap_n²), is approximated from its cluster k = cluster_of[r] as
 *   T̂_r = m_k + Σ_{i<basis_count} w_{r,i} · u_{k,i},
 * with m_k the cluster's mean and u_{k,i} its basis vectors (prtpack_get_cpca_mean / _basis)
 * and w_{r,i} = coefficients[r·basis_count + i]. Relighting (Overbeck et al. 2006, Eq. 7–8):
 * with L̂_c the lighting of channel c in the same wavelet basis, project once per frame
 * P_{k,i} = u_{k,i}·L̂_c and M_k = m_k·L̂_c, then B_c(v) = albedo_c(v) · (M_k + Σ_i w_{r,i} P_{k,i})
 * for row r = c·V + v (channels = 3) or r = v (channels = 1). Rows and channels as in TRNS. */
typedef struct prtpack_cpca_info {
  uint64_t row_count;         /* rows of T: channels × spatial samples */
  uint32_t channels;          /* 1 or 3 */
  uint32_t cubemap_n;         /* cubemap face size n */
  uint64_t column_count;      /* 6·n² wavelet coefficients per row */
  uint32_t row_wavelet;       /* the basis of the vectors: 0 Haar, 1 D4 */
  uint32_t cluster_count;     /* K */
  uint32_t basis_count;       /* S basis vectors per cluster (0: plain vector quantisation) */
  uint64_t term_count;        /* stored mean and basis terms over all clusters */
  const uint32_t* cluster_of; /* row_count cluster ids, each < cluster_count (owned) */
  const float* coefficients;  /* row_count × basis_count, row-major, dequantised (owned; NULL
                               * when basis_count is 0) */
} prtpack_cpca_info;

/* One sparse, dequantised vector over the column_count wavelet coefficients: term k is
 * index[k] ↦ value[k], indices strictly increasing; every other coefficient is 0. */
typedef struct prtpack_cpca_vector {
  size_t term_count;
  const uint32_t* index; /* term_count indices < column_count (owned; NULL when empty) */
  const float* value;    /* term_count values (owned; NULL when empty) */
} prtpack_cpca_vector;

/* The last error on this thread, or "" if none. Valid until the next prtpack call on it. */
const char* prtpack_last_error(void);

/* Opens a pack from a file (memory-mapped) or from `size` bytes at `data` (copied; the caller may
 * free its buffer afterwards). Checks the header, its checksum and the section table. Returns
 * NULL on failure: unreadable file, not a .prtpack, unsupported major version, truncated,
 * corrupted header or table, unknown critical section. */
prtpack* prtpack_open_file(const char* path);
prtpack* prtpack_open_memory(const void* data, size_t size);
/* Frees the handle and everything it returned. NULL is allowed. */
void prtpack_close(prtpack* pack);

/* Format version of the open file. */
int prtpack_version(const prtpack* pack, uint32_t* major, uint32_t* minor);

/* Number of sections (0 if pack is NULL), and section `index`'s table entry. */
size_t prtpack_section_count(const prtpack* pack);
int prtpack_get_section_info(const prtpack* pack, size_t index, prtpack_section_info* out);

/* Number of meshes (0 if pack is NULL), and mesh `index` decoded (on first use; later calls
 * return the same arrays). Errors: index out of range, checksum mismatch, Draco failure, counts
 * that disagree with the section table, non-finite values. */
size_t prtpack_mesh_count(const prtpack* pack);
int prtpack_get_mesh(prtpack* pack, size_t index, prtpack_mesh* out);
/* Mesh `index`'s albedo without decoding the mesh. */
int prtpack_get_albedo(prtpack* pack, size_t index, float rgb[3]);

/* The META JSON text (NUL-terminated, `length` excludes the NUL; length may be NULL). Errors:
 * checksum mismatch, zstd failure, not a JSON object. */
int prtpack_get_metadata(prtpack* pack, const char** json, size_t* length);

/* The transport's parameters and block count. Errors: no TRNS section (none, or a CPCA
 * transport: prtpack_transport_kind), index corrupted. */
int prtpack_get_transport_info(prtpack* pack, prtpack_transport_info* out);
int prtpack_get_block_info(prtpack* pack, size_t block, prtpack_block_info* out);
/* Block `block` decompressed into dst, which must hold exactly raw_size bytes (dst_size ==
 * raw_size). Verifies the block's checksum. Errors: out of range, wrong size, checksum mismatch,
 * decompression failure. */
int prtpack_get_transport_block(prtpack* pack, size_t block, void* dst, size_t dst_size);

/* PRTPACK_TRANSPORT_NONE, _COLUMNS (TRNS) or _CPCA; PRTPACK_TRANSPORT_NONE if pack is NULL.
 * Cheap: reads the section table only. */
int prtpack_transport_kind(const prtpack* pack);

/* The CPCA transport's shape, cluster ids and coefficients (the whole section decoded and
 * validated on first use; later calls return the same arrays). Errors: no CPCA section (a TRNS
 * pack, or none), checksum or zstd failure, a header or body that does not decode (every count,
 * index, value and cluster id is checked). */
int prtpack_get_cpca_info(prtpack* pack, prtpack_cpca_info* out);
/* Cluster `cluster`'s mean m_k, and its basis vector u_{k,basis}. Errors: those of
 * prtpack_get_cpca_info, cluster ≥ cluster_count, basis ≥ basis_count. */
int prtpack_get_cpca_mean(prtpack* pack, size_t cluster, prtpack_cpca_vector* out);
int prtpack_get_cpca_basis(prtpack* pack, size_t cluster, size_t basis, prtpack_cpca_vector* out);

/* 1 if the pack is an image-relighting pack (has an IMGE section), 0 if not or pack is NULL. */
int prtpack_has_image(const prtpack* pack);
/* The image's camera and per-pixel meshes (decoded on first use). Errors: no IMGE section,
 * checksum or zstd failure, a pixel naming a mesh the pack lacks, a pixel count that does not
 * match the transport's rows. */
int prtpack_get_image(prtpack* pack, prtpack_image_info* out);
/* The weight w of mesh `mesh`'s pixels in an image pack: *glossy = 1 where its pixels are glossy
 * (their rows hold the whole BRDF with the camera's view; rgb is the stored weight), else 0 and
 * rgb is the mesh's albedo. Errors: those of prtpack_get_image, mesh out of range. */
int prtpack_get_image_weight(prtpack* pack, size_t mesh, int* glossy, float rgb[3]);
/* Supersampled image packs (.prtpack 1.5; docs/image-relighting.md, "Supersampling"): a pixel
 * is k×k rays over its footprint, and its radiance is
 *   B_c(p) = w_c(p) · Σ_j T[c·V + p][j]·L_c[j] + (1 − coverage(p)) · E_c(p),
 * E the environment along the pixel's centre ray. prtpack_get_image_pixel gives every image
 * pack's pixel its own weight w_c(p) and coverage: in a supersampled pack the stored ones, in
 * any other the pixel's mesh weight (prtpack_get_image_weight) and coverage 1 (0 and weight 0
 * for background). *supersample is k (1 for a pack that is not supersampled). Errors: those of
 * prtpack_get_image, pixel out of range. */
int prtpack_get_image_supersample(prtpack* pack, int* supersample);
int prtpack_get_image_pixel(prtpack* pack, size_t pixel, float rgb[3], float* coverage);

/* Every checksum and structural rule (prt-pack verify). PRTPACK_OK if all hold. */
int prtpack_verify(prtpack* pack);

#ifdef __cplusplus
}
#endif

#endif /* PRT_PACKAGER_PRTPACK_H_ */
