// libFuzzer harness for the runtime's C API (runtime/prt_runtime.h) over hostile packs: every
// input is opened twice through prt_runtime_open_memory, as is and with its checksums recomputed
// (ResealChecksums, so that mutations get past the section checksums into the transport, the
// meshes and the relighter's set-up), and each pack that opens is relit: exact, NWA, a PBI frame,
// a frame split into ranges, positions, triangles and the sample order, under a small map whose
// sun moves with the input; a glossy pack (visibility, no transport) the same way, towards an eye
// that moves with the input. An error status is the expected outcome of a bad input; a crash, a
// sanitizer report, a hang, or a NaN/Inf in an output that came back PRT_RUNTIME_OK is a bug.
// Built only with clang (runtime/CMakeLists.txt); CTest runs it a fixed number of runs on the
// reader's corpus (packager/fuzz_corpus) and the runtime's seeds (runtime/fuzz_corpus).
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "packager/prtpack_format.h"
#include "runtime/prt_runtime.h"

namespace {

void RequireFinite(const std::vector<float>& v, const char* what) {
  for (float x : v)
    if (!std::isfinite(x)) {
      std::fprintf(stderr, "runtime_fuzz: %s returned OK with a non-finite value\n", what);
      std::abort();
    }
}

void Exercise(const std::vector<uint8_t>& bytes) {
  prt_runtime* rt = prt_runtime_open_memory(bytes.data(), bytes.size());
  if (rt == nullptr) return;
  const std::size_t n = prt_runtime_sample_count(rt);
  // Bound the work per input (a valid pack of a million samples is not a bug, only slow).
  if (n == 0 || n > 50000 || prt_runtime_cubemap_size(rt) > 32) {
    prt_runtime_close(rt);
    return;
  }
  // A 16 × 8 sky with a sun whose pixel depends on the input.
  std::vector<float> map(16 * 8 * 3, 0.2f);
  const std::size_t sun = 3 * (bytes.empty() ? 0 : bytes[bytes.size() / 2] % (16 * 8));
  map[sun] = map[sun + 1] = map[sun + 2] = 50.0f;
  std::vector<float> rgb(3 * n);
  // An eye from the input (a glossy pack's frames depend on it; others accept and ignore it).
  const float b0 = bytes.empty() ? 0.0f : static_cast<float>(bytes[bytes.size() / 3]);
  const float eye[3] = {0.05f * b0 - 6.0f, 2.0f, 3.0f - 0.02f * b0};
  if (prt_runtime_set_eye(rt, eye) != PRT_RUNTIME_OK) {
    std::fprintf(stderr, "runtime_fuzz: set_eye refused a finite eye: %s\n",
                 prt_runtime_last_error());
    std::abort();
  }
  if (prt_runtime_set_environment_latlong(rt, map.data(), 16, 8) == PRT_RUNTIME_OK) {
    if (prt_runtime_relight(rt, 0, rgb.data(), n) == PRT_RUNTIME_OK) RequireFinite(rgb, "exact");
    prt_runtime_set_lighting_mode(rt, PRT_RUNTIME_LIGHTING_NWA);
    if (prt_runtime_relight(rt, 7, rgb.data(), n) == PRT_RUNTIME_OK) RequireFinite(rgb, "NWA");
    prt_runtime_set_lighting_mode(rt, PRT_RUNTIME_LIGHTING_PBI);
    prt_runtime_set_rotation_y(rt, 0.5);
    prt_runtime_set_preview(rt, static_cast<int>(bytes.size() & 1));
    if (prt_runtime_relight(rt, 9, rgb.data(), n) == PRT_RUNTIME_OK) RequireFinite(rgb, "PBI");
    if (prt_runtime_prepare(rt, 5) == PRT_RUNTIME_OK) {
      const bool ok =
          prt_runtime_relight_range(rt, 0, n / 2, rgb.data(), n) == PRT_RUNTIME_OK &&
          prt_runtime_relight_range(rt, n / 2, n - n / 2, rgb.data(), n) == PRT_RUNTIME_OK;
      if (ok) RequireFinite(rgb, "ranges");
    }
  }
  std::vector<float> xyz(3 * n);
  if (prt_runtime_get_positions(rt, xyz.data(), n) == PRT_RUNTIME_OK) RequireFinite(xyz, "xyz");
  const std::size_t nt = prt_runtime_triangle_count(rt);
  if (nt <= 200000) {
    std::vector<uint32_t> tri(3 * nt);
    if (prt_runtime_get_triangles(rt, tri.data(), nt) == PRT_RUNTIME_OK)
      for (uint32_t v : tri)
        if (v >= n) {
          std::fprintf(stderr, "runtime_fuzz: triangle index %u of %zu samples\n", v, n);
          std::abort();
        }
  }
  std::vector<uint8_t> background(n);
  if (prt_runtime_get_image_background(rt, background.data(), n) == PRT_RUNTIME_OK)
    for (uint8_t b : background)
      if (b > 1) {
        std::fprintf(stderr, "runtime_fuzz: background flag %u\n", unsigned{b});
        std::abort();
      }
  std::vector<uint32_t> order(n);
  prt_runtime_get_sample_order(rt, order.data(), n);
  prt_runtime_close(rt);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  // A memory budget, as a browser tab would set one: sections claiming more are refused before
  // they are allocated (the reader's default, 2 GiB, is the fuzzer's whole RSS limit).
  prt_runtime_set_max_section_bytes(16 << 20);
  std::vector<uint8_t> bytes(data, data + size);
  Exercise(bytes);
  prt::pack::ResealChecksums(bytes);
  Exercise(bytes);
  return 0;
}
