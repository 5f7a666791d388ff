/* The C interface (prtpack.h) compiled as C: opens the seed pack fuzz_corpus/small.prtpack
 * (written from prtpack_test_util.h's MakeSmallInput), checks meshes, albedo, metadata and the
 * transport blocks bit for bit against the generator, and the error paths; with a second
 * argument, fuzz_corpus/compressed_transport_rgb.prtpack (a 1.1 pack whose transport has 3
 * colour channels), its version and channel count; with a third, fuzz_corpus/cpca.prtpack (a 1.3
 * pack whose transport is clustered PCA: prtpack_test_util.h's MakeSmallCpcaTransport), its
 * cluster ids, coefficients and vectors against the generator's numbers.
 * Usage: prtpack_c_test path/to/small.prtpack [path/to/compressed_transport_rgb.prtpack
 *                                              [path/to/cpca.prtpack]] */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "packager/prtpack.h"

static int failures = 0;
#define CHECK(cond)                                                            \
  do {                                                                         \
    if (!(cond)) {                                                             \
      fprintf(stderr, "%s:%d: CHECK failed: %s\n", __FILE__, __LINE__, #cond); \
      ++failures;                                                              \
    }                                                                          \
  } while (0)

/* prt::pack::testing::PseudoRandomBytes, in C. */
static void pseudo_random_bytes(unsigned char* b, size_t n, uint32_t seed, int compressible) {
  uint32_t x = seed * 2654435761u + 1;
  size_t i;
  for (i = 0; i < n; ++i) {
    x ^= x << 13;
    x ^= x >> 17;
    x ^= x << 5;
    b[i] = compressible ? (unsigned char)((x & 3) == 0 ? x >> 8 : 0) : (unsigned char)x;
  }
}

static unsigned char* read_file(const char* path, size_t* size) {
  FILE* f = fopen(path, "rb");
  unsigned char* data;
  long n;
  if (!f) return NULL;
  fseek(f, 0, SEEK_END);
  n = ftell(f);
  fseek(f, 0, SEEK_SET);
  data = (unsigned char*)malloc((size_t)n);
  if (data && fread(data, 1, (size_t)n, f) != (size_t)n) {
    free(data);
    data = NULL;
  }
  fclose(f);
  *size = (size_t)n;
  return data;
}

static void check_pack(prtpack* p) {
  uint32_t major = 0, minor = 0;
  prtpack_section_info s;
  prtpack_mesh m, again;
  float rgb[3];
  const char* json = NULL;
  size_t json_length = 0, b, i;
  prtpack_transport_info t;
  prtpack_block_info bi;
  static const uint32_t columns[3] = {3, 5, 1};
  static const size_t sizes[3] = {120, 40, 0};
  unsigned char expect[128], got[128];

  CHECK(prtpack_version(p, &major, &minor) == PRTPACK_OK && major == 1 && minor == 0);
  CHECK(prtpack_section_count(p) == 6);
  CHECK(prtpack_get_section_info(p, 0, &s) == PRTPACK_OK && strcmp(s.type, "META") == 0);
  CHECK(prtpack_get_section_info(p, 1, &s) == PRTPACK_OK && strcmp(s.type, "MESH") == 0 &&
        s.codec == 2 && s.offset % 64 == 0 && s.known == 1);
  CHECK(prtpack_get_section_info(p, 6, &s) == PRTPACK_ERROR && strlen(prtpack_last_error()) > 0);

  CHECK(prtpack_mesh_count(p) == 2);
  CHECK(prtpack_get_mesh(p, 0, &m) == PRTPACK_OK);
  CHECK(strcmp(m.name, "octa") == 0 && m.vertex_count == 6 && m.triangle_count == 8);
  CHECK(m.triangles[0] == 0 && m.triangles[1] == 2 && m.triangles[2] == 4);
  CHECK(fabsf(m.positions[0] - 1.0f) < 1e-4f && fabsf(m.positions[3] + 1.0f) < 1e-4f);
  CHECK(fabsf(m.normals[2 * 3 + 1] - 1.0f) < 1e-3f);
  CHECK(m.albedo[0] == 0.5f && m.albedo[1] == 0.25f && m.albedo[2] == 0.75f && !m.is_ground);
  CHECK(prtpack_get_mesh(p, 0, &again) == PRTPACK_OK && again.positions == m.positions);
  CHECK(prtpack_get_mesh(p, 1, &m) == PRTPACK_OK && m.is_ground == 1 && m.grid_resolution == 4);
  CHECK(prtpack_get_mesh(p, 2, &m) == PRTPACK_ERROR);
  CHECK(strstr(prtpack_last_error(), "out of range") != NULL);
  CHECK(prtpack_get_albedo(p, 0, rgb) == PRTPACK_OK && rgb[2] == 0.75f);

  CHECK(prtpack_get_metadata(p, &json, &json_length) == PRTPACK_OK);
  CHECK(json != NULL && strlen(json) == json_length && strstr(json, "\"report\"") != NULL &&
        strstr(json, "\"rays\":42") != NULL);

  CHECK(prtpack_transport_kind(p) == PRTPACK_TRANSPORT_COLUMNS);
  {
    prtpack_cpca_info ci;
    CHECK(prtpack_get_cpca_info(p, &ci) == PRTPACK_ERROR &&
          strstr(prtpack_last_error(), "CPCA") != NULL);
  }
  CHECK(prtpack_get_transport_info(p, &t) == PRTPACK_OK);
  CHECK(t.encoding == 7 && t.row_count == 12 && t.column_count == 9 && t.block_count == 3);
  CHECK(t.channels == 1); /* a 1.0 pack */
  {
    /* A vertex pack: no image (IMGE is for image-relighting packs, .prtpack 1.2). */
    prtpack_image_info im;
    CHECK(prtpack_has_image(p) == 0);
    CHECK(prtpack_get_image(p, &im) == PRTPACK_ERROR && strstr(prtpack_last_error(), "IMGE"));
    CHECK(prtpack_has_image(NULL) == 0);
  }
  CHECK(t.params_size == 5 && t.params[0] == 1 && t.params[4] == 5);
  for (b = 0; b < 3; ++b) {
    CHECK(prtpack_get_block_info(p, b, &bi) == PRTPACK_OK);
    CHECK(bi.column_count == columns[b] && bi.raw_size == sizes[b]);
    pseudo_random_bytes(expect, sizes[b], (uint32_t)b + 1, b == 0);
    memset(got, 0xAB, sizeof got);
    CHECK(prtpack_get_transport_block(p, b, got, sizes[b]) == PRTPACK_OK);
    for (i = 0; i < sizes[b]; ++i) CHECK(got[i] == expect[i]);
  }
  CHECK(prtpack_get_transport_block(p, 0, got, 7) == PRTPACK_ERROR);
  CHECK(prtpack_get_block_info(p, 3, &bi) == PRTPACK_ERROR);
  CHECK(prtpack_verify(p) == PRTPACK_OK);
}

/* A 1.1 pack of MakeSmallInput's meshes with a 3-channel transport of 3 × 12 rows. */
static void check_rgb_pack(const char* path) {
  uint32_t major = 0, minor = 0;
  prtpack_transport_info t;
  prtpack* p = prtpack_open_file(path);
  CHECK(p != NULL);
  if (!p) return;
  CHECK(prtpack_version(p, &major, &minor) == PRTPACK_OK && major == 1 && minor == 1);
  CHECK(prtpack_get_transport_info(p, &t) == PRTPACK_OK);
  CHECK(t.channels == 3 && t.row_count == 36 && t.column_count == 24 && t.encoding == 3);
  CHECK(prtpack_verify(p) == PRTPACK_OK);
  prtpack_close(p);
}

static int close_to(float got, double want) {
  return fabs((double)got - want) <= 1e-6 * (1.0 + fabs(want));
}

/* A 1.3 pack of MakeSmallInput's meshes with MakeSmallCpcaTransport(1): 12 rows, n = 2, K = 2,
 * S = 2; row r in cluster 1 when r % 3 == 0; quantiser maxima 255 (vectors) and 2047
 * (coefficients). */
static void check_cpca_pack(const char* path) {
  uint32_t major = 0, minor = 0;
  prtpack_transport_info t;
  prtpack_cpca_info info;
  prtpack_cpca_vector v;
  size_t r;
  static const uint32_t mean0_index[3] = {0, 3, 7};
  static const int mean0_q[3] = {100, -50, 255};
  prtpack* p = prtpack_open_file(path);
  CHECK(p != NULL);
  if (!p) return;
  CHECK(prtpack_version(p, &major, &minor) == PRTPACK_OK && major == 1 && minor == 3);
  CHECK(prtpack_transport_kind(p) == PRTPACK_TRANSPORT_CPCA);
  CHECK(prtpack_get_transport_info(p, &t) == PRTPACK_ERROR &&
        strstr(prtpack_last_error(), "CPCA") != NULL);
  CHECK(prtpack_get_cpca_info(p, &info) == PRTPACK_OK);
  CHECK(info.row_count == 12 && info.channels == 1 && info.cubemap_n == 2 &&
        info.column_count == 24 && info.row_wavelet == 0);
  CHECK(info.cluster_count == 2 && info.basis_count == 2 && info.term_count == 12);
  for (r = 0; r < 12; ++r) {
    const uint32_t k = r % 3 == 0 ? 1u : 0u;
    const double q0 = (double)((int)(r * 37 % 2000) - 1000);
    CHECK(info.cluster_of[r] == k);
    CHECK(close_to(info.coefficients[2 * r], q0 * (k ? 1.0 : 0.5) / 2047));
    CHECK(close_to(info.coefficients[2 * r + 1], k ? -(double)(r * 10) * 0.75 / 2047 : 0.0));
  }
  CHECK(prtpack_get_cpca_mean(p, 0, &v) == PRTPACK_OK && v.term_count == 3);
  for (r = 0; r < 3 && v.term_count == 3; ++r) {
    CHECK(v.index[r] == mean0_index[r]);
    CHECK(close_to(v.value[r], mean0_q[r] * 1.5 / 255));
  }
  CHECK(prtpack_get_cpca_basis(p, 0, 1, &v) == PRTPACK_OK && v.term_count == 0 && v.index == NULL &&
        v.value == NULL);
  CHECK(prtpack_get_cpca_basis(p, 1, 1, &v) == PRTPACK_OK && v.term_count == 1 &&
        v.index[0] == 23 && close_to(v.value[0], -0.125));
  CHECK(prtpack_get_cpca_basis(p, 1, 0, &v) == PRTPACK_OK && v.term_count == 4 && v.index[3] == 8 &&
        close_to(v.value[3], -2 * 0.5 / 255));
  CHECK(prtpack_get_cpca_mean(p, 2, &v) == PRTPACK_ERROR &&
        strstr(prtpack_last_error(), "out of range") != NULL);
  CHECK(prtpack_get_cpca_basis(p, 0, 2, &v) == PRTPACK_ERROR &&
        strstr(prtpack_last_error(), "out of range") != NULL);
  CHECK(prtpack_get_cpca_info(NULL, &info) == PRTPACK_ERROR);
  CHECK(prtpack_verify(p) == PRTPACK_OK);
  prtpack_close(p);
}

int main(int argc, char** argv) {
  size_t size = 0;
  unsigned char* data;
  prtpack* p;
  if (argc < 2 || argc > 4) {
    fprintf(stderr, "usage: %s small.prtpack [compressed_transport_rgb.prtpack [cpca.prtpack]]\n",
            argv[0]);
    return 2;
  }
  if (argc >= 3) check_rgb_pack(argv[2]);
  if (argc == 4) check_cpca_pack(argv[3]);
  CHECK(prtpack_transport_kind(NULL) == PRTPACK_TRANSPORT_NONE);
  p = prtpack_open_file(argv[1]);
  CHECK(p != NULL);
  if (p) check_pack(p);
  prtpack_close(p);

  data = read_file(argv[1], &size);
  CHECK(data != NULL && size > 64);
  if (data) {
    p = prtpack_open_memory(data, size);
    CHECK(p != NULL);
    if (p) check_pack(p);
    prtpack_close(p);
    /* A damaged section table is refused at open with a clear message. */
    data[64 + 20] ^= 0x01;
    CHECK(prtpack_open_memory(data, size) == NULL);
    CHECK(strstr(prtpack_last_error(), "checksum") != NULL);
    /* Truncated. */
    data[64 + 20] ^= 0x01;
    CHECK(prtpack_open_memory(data, size - 1) == NULL);
    CHECK(strstr(prtpack_last_error(), "truncated") != NULL);
    free(data);
  }
  CHECK(prtpack_open_file("/nonexistent/x.prtpack") == NULL);
  CHECK(strstr(prtpack_last_error(), "/nonexistent/x.prtpack") != NULL);
  CHECK(prtpack_open_memory(NULL, 0) == NULL);
  CHECK(prtpack_mesh_count(NULL) == 0);
  prtpack_close(NULL);
  if (failures) {
    fprintf(stderr, "%d checks failed\n", failures);
    return 1;
  }
  printf("prtpack C API: all checks passed\n");
  return 0;
}
