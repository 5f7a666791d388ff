// Software z-buffer rasteriser: near-plane clipping (Sutherland–Hodgman against one plane), edge
// functions with the top-left fill rule, perspective-correct interpolation (attributes a/z and 1/z
// are affine in screen space; Heckbert & Moreton 1991), z-test on view depth.
//
// A frame runs in three parallel passes (docs/viewer.md, "Rasteriser"):
//  1. vertices: each vertex is transformed to view space and, in front of the near plane,
//     projected once (the old code did it per triangle corner, 3× over);
//  2. triangles: a triangle with a vertex behind the near plane is clipped (its new vertices join
//     the frame's vertex array); one whose box holds no pixel centre, or whose area is zero or not
//     finite, is dropped; the rest are counted into, then copied to, the screen tiles they
//     touch (kTileW × kTileH pixels), keeping triangle order inside each tile;
//  3. tiles: each tile draws its triangles in that order, then fills its uncovered pixels with
//     the background, a row's run of rays at a time (BackgroundFunction's batch call).
// Every per-pixel quantity is the same floating-point expression as in the straightforward
// rasteriser (rasterizer_reference.cpp, compared pixel for pixel in rasterizer_test.cpp), in
// the same order per pixel, so that coverage, depth and colour do not depend on the tiling or on
// the number of threads.
#include "viewer/rasterizer.h"

#include <tbb/parallel_for.h>

#if defined(__x86_64__)
#include <immintrin.h>
#endif

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <numbers>
#include <stdexcept>
#include <string>

#include "vocabulary/errors.h"

namespace prt {

namespace {

constexpr double kFloatMax = static_cast<double>(std::numeric_limits<float>::max());
constexpr int kTileW = 64, kTileH = 32;
constexpr std::size_t kChunk = 4096;  // triangles per task of pass 2, vertices per task of pass 1

struct ClipVertex {
  Vec3 view;
  std::array<double, 3> rgb;
};

[[gnu::always_inline]] inline ClipVertex Lerp(const ClipVertex& a, const ClipVertex& b, double t) {
  ClipVertex r;
  r.view = a.view + (b.view - a.view) * t;
  for (int c = 0; c < 3; ++c) r.rgb[c] = a.rgb[c] + (b.rgb[c] - a.rgb[c]) * t;
  return r;
}

// Keeps the part of a triangle with view z ≥ near: 0, 3 or 4 vertices.
[[gnu::always_inline]] inline int ClipNear(const ClipVertex in[3], double near, ClipVertex out[4]) {
  int n = 0;
  for (int i = 0; i < 3; ++i) {
    const ClipVertex& a = in[i];
    const ClipVertex& b = in[(i + 1) % 3];
    const bool ina = a.view.z >= near, inb = b.view.z >= near;
    if (ina) out[n++] = a;
    if (ina != inb) out[n++] = Lerp(a, b, (near - a.view.z) / (b.view.z - a.view.z));
  }
  return n;
}

// A vertex in front of the near plane on the screen: pixel position, 1/z and colour/z (the
// quantities that are affine in screen space).
struct ScreenVertex {
  double px, py, inv_z;
  double rgb_over_z[3];
};

[[gnu::always_inline]] inline ScreenVertex Project(const CameraProjection& cam, const Vec3& view,
                                                   const double rgb[3]) {
  ScreenVertex s;
  cam.ViewToPixel(view, s.px, s.py);
  s.inv_z = 1.0 / view.z;
  for (int c = 0; c < 3; ++c) s.rgb_over_z[c] = rgb[c] * s.inv_z;
  return s;
}

// A screen triangle: three vertices of the frame's screen-vertex array, the triangle it came
// from, and the pixel centres inside its box, clamped to the image.
struct ScreenTriangle {
  uint32_t v[3];
  int32_t id;
  int32_t xmin, xmax, ymin, ymax;
};

// Edge function of the edge a→b at p: positive on one side, zero on the line. Evaluated with the
// endpoints in a canonical order and negated when swapped, so that the two triangles sharing an
// edge get bitwise opposite values and no pixel is lost or drawn twice along it.
[[gnu::always_inline]] inline double Edge(double ax, double ay, double bx, double by, double px,
                                          double py) {
  if (ax > bx || (ax == bx && ay > by)) {
    return -((ax - bx) * (py - by) - (ay - by) * (px - bx));
  }
  return (bx - ax) * (py - ay) - (by - ay) * (px - ax);
}

// The pixel centres x + ½, y + ½ inside the box of three screen vertices, clamped to the image;
// false when there is none, or the box is not finite, or the triangle's area is zero or not
// finite (nothing would be drawn).
[[gnu::always_inline]] inline bool Box(const ScreenVertex& a, const ScreenVertex& b,
                                       const ScreenVertex& c, double w, double h,
                                       ScreenTriangle& t) {
  const ScreenVertex* v[3] = {&a, &b, &c};
  double xmin = std::numeric_limits<double>::infinity(), xmax = -xmin, ymin = xmin, ymax = -xmin;
  for (int i = 0; i < 3; ++i) {
    xmin = std::min(xmin, v[i]->px);
    xmax = std::max(xmax, v[i]->px);
    ymin = std::min(ymin, v[i]->py);
    ymax = std::max(ymax, v[i]->py);
  }
  if (!std::isfinite(xmin + xmax + ymin + ymax)) return false;
  // Clamped in double first so that a huge projected triangle cannot overflow an int.
  t.xmin = static_cast<int>(std::ceil(std::clamp(xmin - 0.5, 0.0, w)));
  t.xmax = static_cast<int>(std::floor(std::clamp(xmax - 0.5, -1.0, w - 1.0)));
  t.ymin = static_cast<int>(std::ceil(std::clamp(ymin - 0.5, 0.0, h)));
  t.ymax = static_cast<int>(std::floor(std::clamp(ymax - 0.5, -1.0, h - 1.0)));
  if (t.xmin > t.xmax || t.ymin > t.ymax) return false;
  const double area = Edge(a.px, a.py, b.px, b.py, c.px, c.py);
  return area != 0.0 && std::isfinite(area);
}

// Top-left rule: a pixel centre exactly on an edge belongs to the triangle whose interior lies to
// its right (+x) or, for a horizontal edge, below it (+y). `nx, ny` is the inward edge normal.
[[gnu::always_inline]] inline bool OwnsEdge(double nx, double ny) {
  return nx > 0.0 || (nx == 0.0 && ny > 0.0);
}

// A screen triangle ready to draw: its edges in the canonical endpoint order of Edge(), so that
// the per-pixel value esign·(row − edy·(x + ½ − ex0)), row = edx·(y + ½ − ey0), is the same
// floating-point expression Edge() evaluates (bitwise), with the per-edge and per-row parts
// hoisted out of the pixel loop. Edge i is opposite vertex i: (1→2), (2→0), (0→1).
struct TriangleSetup {
  double s, inv_area;
  double ex0[3], ey0[3], edx[3], edy[3], esign[3];
  bool owns[3];
  double iz[3];
  const ScreenVertex* v[3];
  int32_t id;
};

[[gnu::always_inline]] inline void Setup(const ScreenTriangle& t, const ScreenVertex* verts,
                                         TriangleSetup& e) {
  for (int i = 0; i < 3; ++i) e.v[i] = &verts[t.v[i]];
  const double px[3] = {e.v[0]->px, e.v[1]->px, e.v[2]->px};
  const double py[3] = {e.v[0]->py, e.v[1]->py, e.v[2]->py};
  const double area = Edge(px[0], py[0], px[1], py[1], px[2], py[2]);
  e.s = area > 0.0 ? 1.0 : -1.0;
  const int ea[3] = {1, 2, 0}, eb[3] = {2, 0, 1};
  for (int i = 0; i < 3; ++i) {
    const double dx = px[eb[i]] - px[ea[i]], dy = py[eb[i]] - py[ea[i]];
    e.owns[i] = OwnsEdge(-e.s * dy, e.s * dx);
  }
  for (int i = 0; i < 3; ++i) {
    double ax = px[ea[i]], ay = py[ea[i]], bx = px[eb[i]], by = py[eb[i]];
    e.esign[i] = e.s;
    if (ax > bx || (ax == bx && ay > by)) {
      std::swap(ax, bx);
      std::swap(ay, by);
      e.esign[i] = -e.s;
    }
    e.ex0[i] = ax;
    e.ey0[i] = ay;
    e.edx[i] = bx - ax;
    e.edy[i] = by - ay;
    e.iz[i] = e.v[i]->inv_z;
  }
  e.inv_area = 1.0 / area;
  e.id = t.id;
}

// Pixel p of a covered centre with edge values w: z-test, then depth, triangle and colour.
[[gnu::always_inline]] inline void Shade(const TriangleSetup& e, const double w[3], std::size_t p,
                                         RasterImage& img) {
  // Screen-space barycentrics; 1/z and rgb/z are affine in screen space.
  double b[3];
  for (int i = 0; i < 3; ++i) b[i] = e.s * w[i] * e.inv_area;
  const double inv_z = b[0] * e.iz[0] + b[1] * e.iz[1] + b[2] * e.iz[2];
  if (!(inv_z > 0.0)) return;
  const double z = 1.0 / inv_z;
  if (!(z < img.depth[p])) return;
  img.depth[p] = static_cast<float>(z);
  img.triangle[p] = e.id;
  for (int c = 0; c < 3; ++c) {
    // Perspective-correct interpolation is a convex combination of the three vertex colours
    // (weights b_i·(1/z_i)·z ≥ 0 summing to 1), which are finite floats (checked on entry): v
    // lies within their range up to double rounding (~1e-16 relative, far below half a float
    // ulp), so it converts to a finite float; the clamp states that bound.
    const double v = (b[0] * e.v[0]->rgb_over_z[c] + b[1] * e.v[1]->rgb_over_z[c] +
                      b[2] * e.v[2]->rgb_over_z[c]) *
                     z;
    img.rgb[3 * p + c] = static_cast<float>(std::clamp(v, -kFloatMax, kFloatMax));
  }
}

// Columns [x0, x1] of rows [y0, y1], one pixel at a time.
[[gnu::always_inline]] inline void DrawRows(const TriangleSetup& e, int x0, int x1, int y0, int y1,
                                            int width, RasterImage& img) {
  for (int y = y0; y <= y1; ++y) {
    const double pyc = y + 0.5;
    double row[3];
    for (int i = 0; i < 3; ++i) row[i] = e.edx[i] * (pyc - e.ey0[i]);
    for (int x = x0; x <= x1; ++x) {
      const double pxc = x + 0.5;
      double w[3];
      bool inside = true;
      for (int i = 0; i < 3; ++i) {
        w[i] = e.esign[i] * (row[i] - e.edy[i] * (pxc - e.ex0[i]));
        if (w[i] < 0.0 || (w[i] == 0.0 && !e.owns[i])) {
          inside = false;
          break;
        }
      }
      if (inside) Shade(e, w, static_cast<std::size_t>(y) * width + x, img);
    }
  }
}

#if defined(__x86_64__)
// DrawRows four pixels at a time (AVX2, no FMA: each lane rounds every product and sum as the
// scalar code does, so the edge values, barycentrics, depths and colours are bitwise the same).
__attribute__((target("avx2"))) void DrawRowsAvx2(const TriangleSetup& e, int x0, int x1, int y0,
                                                  int y1, int width, RasterImage& img) {
  const __m256d zero = _mm256_setzero_pd();
  const __m256d lane_offset = _mm256_set_pd(3.5, 2.5, 1.5, 0.5);
  const __m256i lane_index = _mm256_set_epi64x(3, 2, 1, 0);
  __m256d not_owns[3], esign[3], edy[3], ex0[3];
  for (int i = 0; i < 3; ++i) {
    not_owns[i] = _mm256_castsi256_pd(_mm256_set1_epi64x(e.owns[i] ? 0 : -1));
    esign[i] = _mm256_set1_pd(e.esign[i]);
    edy[i] = _mm256_set1_pd(e.edy[i]);
    ex0[i] = _mm256_set1_pd(e.ex0[i]);
  }
  const __m256d s = _mm256_set1_pd(e.s), inv_area = _mm256_set1_pd(e.inv_area);
  const __m256d iz0 = _mm256_set1_pd(e.iz[0]), iz1 = _mm256_set1_pd(e.iz[1]),
                iz2 = _mm256_set1_pd(e.iz[2]), one = _mm256_set1_pd(1.0);
  for (int y = y0; y <= y1; ++y) {
    const double pyc = y + 0.5;
    __m256d row[3];
    for (int i = 0; i < 3; ++i) row[i] = _mm256_set1_pd(e.edx[i] * (pyc - e.ey0[i]));
    const std::size_t row_start = static_cast<std::size_t>(y) * width;
    for (int x = x0; x <= x1; x += 4) {
      const __m256d pxc = _mm256_add_pd(_mm256_set1_pd(static_cast<double>(x)), lane_offset);
      // Lanes past x1 are out.
      __m256d out = _mm256_castsi256_pd(
          _mm256_cmpgt_epi64(lane_index, _mm256_set1_epi64x(static_cast<int64_t>(x1 - x))));
      __m256d w[3];
      for (int i = 0; i < 3; ++i) {
        w[i] = _mm256_mul_pd(
            esign[i], _mm256_sub_pd(row[i], _mm256_mul_pd(edy[i], _mm256_sub_pd(pxc, ex0[i]))));
        out = _mm256_or_pd(out, _mm256_cmp_pd(w[i], zero, _CMP_LT_OQ));
        out = _mm256_or_pd(out, _mm256_and_pd(_mm256_cmp_pd(w[i], zero, _CMP_EQ_OQ), not_owns[i]));
      }
      const int in_mask = ~_mm256_movemask_pd(out) & 0xf;
      if (in_mask == 0) continue;
      const __m256d b0 = _mm256_mul_pd(_mm256_mul_pd(s, w[0]), inv_area);
      const __m256d b1 = _mm256_mul_pd(_mm256_mul_pd(s, w[1]), inv_area);
      const __m256d b2 = _mm256_mul_pd(_mm256_mul_pd(s, w[2]), inv_area);
      const __m256d inv_z = _mm256_add_pd(
          _mm256_add_pd(_mm256_mul_pd(b0, iz0), _mm256_mul_pd(b1, iz1)), _mm256_mul_pd(b2, iz2));
      const __m256d z = _mm256_div_pd(one, inv_z);
      const __m128i load_mask = _mm_set_epi32(in_mask & 8 ? -1 : 0, in_mask & 4 ? -1 : 0,
                                              in_mask & 2 ? -1 : 0, in_mask & 1 ? -1 : 0);
      const __m256d depth =
          _mm256_cvtps_pd(_mm_maskload_ps(img.depth.data() + row_start + x, load_mask));
      const int draw =
          in_mask & _mm256_movemask_pd(_mm256_and_pd(_mm256_cmp_pd(inv_z, zero, _CMP_GT_OQ),
                                                     _mm256_cmp_pd(z, depth, _CMP_LT_OQ)));
      if (draw == 0) continue;
      alignas(32) double zs[4], vs[3][4];
      _mm256_store_pd(zs, z);
      for (int c = 0; c < 3; ++c) {
        const __m256d v = _mm256_mul_pd(
            _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(b0, _mm256_set1_pd(e.v[0]->rgb_over_z[c])),
                                        _mm256_mul_pd(b1, _mm256_set1_pd(e.v[1]->rgb_over_z[c]))),
                          _mm256_mul_pd(b2, _mm256_set1_pd(e.v[2]->rgb_over_z[c]))),
            z);
        _mm256_store_pd(vs[c], v);
      }
      for (int k = 0; k < 4; ++k) {
        if (!(draw & (1 << k))) continue;
        const std::size_t p = row_start + x + k;
        img.depth[p] = static_cast<float>(zs[k]);
        img.triangle[p] = e.id;
        for (int c = 0; c < 3; ++c)
          img.rgb[3 * p + c] = static_cast<float>(std::clamp(vs[c][k], -kFloatMax, kFloatMax));
      }
    }
  }
}

const bool g_raster_avx2 = [] {
  __builtin_cpu_init();  // a static initializer may run before the one that fills the CPU model
  return __builtin_cpu_supports("avx2") != 0;
}();
#endif

// Pass 2's output for one chunk of triangles.
struct Chunk {
  std::vector<ScreenTriangle> tris;
  std::vector<ScreenVertex> extra;   // vertices made by near clipping
  std::vector<uint32_t> tile_count;  // then: where the chunk's entries of each tile start
};

// A frame's working arrays, kept from one frame to the next by the calling thread (a frame
// allocates ~15 MB for 83k triangles; fresh pages cost a page fault each, ~10 % of a frame). A
// call made while the thread's arrays are in use (a nested call from a TBB task) gets its own.
struct Scratch {
  bool busy = false;
  std::vector<Vec3> view;
  std::vector<ScreenVertex> verts;
  std::vector<Chunk> chunk;
  std::vector<ScreenTriangle> binned;
};

class ScratchLease {
 public:
  ScratchLease() {
    static thread_local Scratch kept;
    if (!kept.busy) {
      scratch_ = &kept;
    } else {
      own_ = std::make_unique<Scratch>();
      scratch_ = own_.get();
    }
    scratch_->busy = true;
  }
  ~ScratchLease() { scratch_->busy = false; }
  ScratchLease(const ScratchLease&) = delete;
  ScratchLease& operator=(const ScratchLease&) = delete;
  Scratch& get() { return *scratch_; }

 private:
  std::unique_ptr<Scratch> own_;
  Scratch* scratch_ = nullptr;
};

// Runs body(i) built for AVX2 (no FMA: the arithmetic rounds as in the default build, bitwise)
// or for the default target: the passes' bodies and what they call are always inlined, so the
// AVX2 build gets SSE4.1 rounding for floor/ceil and wider moves throughout.
template <typename F>
void RunDefault(const F& body, std::size_t i) {
  body(i);
}
#if defined(__x86_64__)
template <typename F>
__attribute__((target("avx2"))) void RunAvx2(const F& body, std::size_t i) {
  body(i);
}
#endif
template <typename F>
void Run(bool avx2, const F& body, std::size_t i) {
#if defined(__x86_64__)
  if (avx2) {
    RunAvx2(body, i);
    return;
  }
#endif
  (void)avx2;
  RunDefault(body, i);
}

// Draws the pixels of `t` in columns [x0, x1] and rows [y0, y1] (its tile).
[[gnu::always_inline]] inline void DrawTriangle(const ScreenTriangle& t, const ScreenVertex* verts,
                                                int x0, int x1, int y0, int y1, int width,
                                                bool simd, RasterImage& img) {
  x0 = std::max(x0, t.xmin);
  x1 = std::min(x1, t.xmax);
  y0 = std::max(y0, t.ymin);
  y1 = std::min(y1, t.ymax);
  if (x0 > x1 || y0 > y1) return;
  TriangleSetup e;
  Setup(t, verts, e);
#if defined(__x86_64__)
  if (simd) {
    DrawRowsAvx2(e, x0, x1, y0, y1, width, img);
    return;
  }
#endif
  (void)simd;
  DrawRows(e, x0, x1, y0, y1, width, img);
}

}  // namespace

RasterImage RasterizeTriangles(const Camera& camera, std::span<const Vec3> positions,
                               std::span<const std::array<uint32_t, 3>> triangles,
                               std::span<const float> vertex_rgb, const RasterOptions& options) {
  const CameraProjection cam(camera);
  if (vertex_rgb.size() != 3 * positions.size()) {
    throw std::invalid_argument("RasterizeTriangles: " + std::to_string(vertex_rgb.size()) +
                                " colour values for " + std::to_string(positions.size()) +
                                " vertices");
  }
  for (std::size_t i = 0; i < vertex_rgb.size(); ++i) {
    if (!std::isfinite(vertex_rgb[i]))
      throw NumericalError("RasterizeTriangles: vertex " + std::to_string(i / 3) +
                           " colour (channel " + std::to_string(i % 3) + ") is " +
                           (std::isnan(vertex_rgb[i]) ? "NaN" : "Inf"));
  }
  for (std::size_t i = 0; i < triangles.size(); ++i) {
    for (uint32_t v : triangles[i]) {
      if (v >= positions.size()) {
        throw std::invalid_argument("RasterizeTriangles: triangle " + std::to_string(i) +
                                    " has vertex index " + std::to_string(v) + " out of range");
      }
    }
  }
  if (positions.size() > std::numeric_limits<uint32_t>::max() / 2 ||
      triangles.size() > static_cast<std::size_t>(std::numeric_limits<int32_t>::max()))
    throw std::invalid_argument("RasterizeTriangles: too many vertices or triangles");
  const double near = options.near > 0.0 ? options.near : 1e-3;
#if defined(__x86_64__)
  const bool simd = g_raster_avx2 && !options.scalar;
#else
  const bool simd = false;
#endif
  const int width = camera.width, height = camera.height;
  const double wd = width, hd = height;

  // Pass 1: every vertex in view space, and on the screen when in front of the near plane.
  const std::size_t nv = positions.size();
  ScratchLease lease;
  Scratch& scratch = lease.get();
  std::vector<Vec3>& view = scratch.view;
  std::vector<ScreenVertex>& verts = scratch.verts;
  view.resize(nv);
  verts.resize(nv);
  tbb::parallel_for(std::size_t{0}, (nv + kChunk - 1) / kChunk, [&](std::size_t ch) {
    const std::size_t end = std::min(nv, (ch + 1) * kChunk);
    for (std::size_t v = ch * kChunk; v < end; ++v) {
      view[v] = cam.ToView(positions[v]);
      if (view[v].z >= near) {
        const double rgb[3] = {vertex_rgb[3 * v], vertex_rgb[3 * v + 1], vertex_rgb[3 * v + 2]};
        verts[v] = Project(cam, view[v], rgb);
      }
    }
  });

  // Pass 2: screen triangles per chunk of triangles, in triangle order (a clipped triangle's
  // two halves in the order of the straightforward rasteriser). A clipped triangle's vertices go
  // to its chunk's `extra`, numbered from nv + (its index there) until the chunks are joined.
  const std::size_t chunks = (triangles.size() + kChunk - 1) / kChunk;
  const int tiles_x = (width + kTileW - 1) / kTileW, tiles_y = (height + kTileH - 1) / kTileH;
  const std::size_t tiles = static_cast<std::size_t>(tiles_x) * tiles_y;
  std::vector<Chunk>& chunk = scratch.chunk;
  if (chunk.size() < chunks) chunk.resize(chunks);
  const auto clip_and_count = [&](std::size_t ch) __attribute__((always_inline)) {
    Chunk& out = chunk[ch];
    out.tile_count.assign(tiles, 0);
    out.tris.clear();
    out.tris.reserve(kChunk);
    out.extra.clear();
    const std::size_t end = std::min(triangles.size(), (ch + 1) * kChunk);
    const auto keep = [&](ScreenTriangle& t) {
      for (int ty = t.ymin / kTileH; ty <= t.ymax / kTileH; ++ty)
        for (int tx = t.xmin / kTileW; tx <= t.xmax / kTileW; ++tx)
          ++out.tile_count[static_cast<std::size_t>(ty) * tiles_x + tx];
      out.tris.push_back(t);
    };
    for (std::size_t i = ch * kChunk; i < end; ++i) {
      const auto& tri = triangles[i];
      ScreenTriangle t;
      t.id = static_cast<int32_t>(i);
      if (view[tri[0]].z >= near && view[tri[1]].z >= near && view[tri[2]].z >= near) {
        if (Box(verts[tri[0]], verts[tri[1]], verts[tri[2]], wd, hd, t)) {
          t.v[0] = tri[0];
          t.v[1] = tri[1];
          t.v[2] = tri[2];
          keep(t);
        }
        continue;
      }
      ClipVertex in[3];
      for (int k = 0; k < 3; ++k) {
        in[k].view = view[tri[k]];
        for (int c = 0; c < 3; ++c)
          in[k].rgb[c] = vertex_rgb[3 * static_cast<std::size_t>(tri[k]) + c];
      }
      ClipVertex cv[4];
      const int n = ClipNear(in, near, cv);
      if (n < 3) continue;
      ScreenVertex sv[4];
      for (int k = 0; k < n; ++k) sv[k] = Project(cam, cv[k].view, cv[k].rgb.data());
      const int fan[2][3] = {{0, 1, 2}, {0, 2, 3}};
      for (int f = 0; f + 2 < n; ++f) {
        if (!Box(sv[fan[f][0]], sv[fan[f][1]], sv[fan[f][2]], wd, hd, t)) continue;
        for (int k = 0; k < 3; ++k) {
          t.v[k] = static_cast<uint32_t>(nv + out.extra.size());
          out.extra.push_back(sv[fan[f][k]]);
        }
        keep(t);
      }
    }
  };
  tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t ch) { Run(simd, clip_and_count, ch); });

  // Join the chunks' clipped vertices to the vertex array; lay the tiles' lists out tile by
  // tile, chunk by chunk inside a tile (so triangle order), then fill them in parallel.
  std::vector<uint32_t> extra_base(chunks + 1, 0), tile_start(tiles + 1, 0);
  {
    std::size_t extra = 0;
    for (std::size_t ch = 0; ch < chunks; ++ch) {
      extra_base[ch] = static_cast<uint32_t>(nv + extra);
      extra += chunk[ch].extra.size();
    }
    if (extra > 0) {
      verts.reserve(nv + extra);
      for (std::size_t ch = 0; ch < chunks; ++ch)
        verts.insert(verts.end(), chunk[ch].extra.begin(), chunk[ch].extra.end());
    }
    uint32_t at = 0;
    for (std::size_t t = 0; t < tiles; ++t) {
      tile_start[t] = at;
      for (std::size_t ch = 0; ch < chunks; ++ch) {
        Chunk& c = chunk[ch];
        const uint32_t count = c.tile_count[t];
        c.tile_count[t] = at;
        at += count;
      }
    }
    tile_start[tiles] = at;
  }
  std::vector<ScreenTriangle>& binned = scratch.binned;
  binned.resize(tile_start[tiles]);
  tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t ch) {
    Chunk& c = chunk[ch];
    for (ScreenTriangle b : c.tris) {
      for (uint32_t& v : b.v)
        if (v >= nv) v = static_cast<uint32_t>(v - nv + extra_base[ch]);
      const ScreenTriangle& t = b;
      for (int ty = t.ymin / kTileH; ty <= t.ymax / kTileH; ++ty)
        for (int tx = t.xmin / kTileW; tx <= t.xmax / kTileW; ++tx)
          binned[c.tile_count[static_cast<std::size_t>(ty) * tiles_x + tx]++] = b;
    }
  });

  RasterImage img;
  img.width = width;
  img.height = height;
  const std::size_t pixels = static_cast<std::size_t>(width) * height;
  img.rgb.assign(3 * pixels, 0.0f);
  img.depth.assign(pixels, std::numeric_limits<float>::max());
  img.triangle.assign(pixels, -1);

  // Pass 3: the tiles. A tile's first non-finite background pixel (row-major) is kept, and the
  // image's first one reported after all tiles, whatever the thread count.
  constexpr std::size_t kNone = std::numeric_limits<std::size_t>::max();
  std::vector<std::size_t> bad_background(tiles, kNone);
  const auto draw_tile = [&](std::size_t tile) __attribute__((always_inline)) {
    const int x0 = static_cast<int>(tile % tiles_x) * kTileW;
    const int y0 = static_cast<int>(tile / tiles_x) * kTileH;
    const int x1 = std::min(width, x0 + kTileW) - 1, y1 = std::min(height, y0 + kTileH) - 1;
    for (uint32_t k = tile_start[tile]; k < tile_start[tile + 1]; ++k)
      DrawTriangle(binned[k], verts.data(), x0, x1, y0, y1, width, simd, img);
    if (!options.background) return;
    Vec3 dirs[kTileW];
    Rgb out[kTileW];
    int xs[kTileW];
    for (int y = y0; y <= y1; ++y) {
      int n = 0;
      for (int x = x0; x <= x1; ++x) {
        const std::size_t p = static_cast<std::size_t>(y) * width + x;
        if (img.triangle[p] >= 0) continue;
        dirs[n] = cam.PixelDirection(x + 0.5, y + 0.5);
        xs[n++] = x;
      }
      if (n == 0) continue;
      options.background(std::span<const Vec3>(dirs, n), std::span<Rgb>(out, n));
      for (int k = 0; k < n; ++k) {
        const std::size_t p = static_cast<std::size_t>(y) * width + xs[k];
        const Rgb& c = out[k];
        // The library's backgrounds are finite (EnvironmentLookup and CubemapBackground check
        // their data); any other function's NaN/Inf is an error, never a black pixel.
        if (!std::isfinite(c[0]) || !std::isfinite(c[1]) || !std::isfinite(c[2])) {
          bad_background[tile] = std::min(bad_background[tile], p);
          continue;
        }
        for (int ch = 0; ch < 3; ++ch) img.rgb[3 * p + ch] = c[ch];
      }
    }
  };
  tbb::parallel_for(std::size_t{0}, tiles, [&](std::size_t tile) { Run(simd, draw_tile, tile); });
  const std::size_t bad = *std::min_element(bad_background.begin(), bad_background.end());
  if (bad != kNone)
    throw NumericalError(
        "RasterizeTriangles: the background of pixel (x=" + std::to_string(bad % width) +
        ", y=" + std::to_string(bad / width) + ") is not finite");
  return img;
}

BackgroundFunction CubemapBackground(const CubemapRgb& cube) {
  const CubemapLayout layout(cube.n);
  for (int c = 0; c < 3; ++c) {
    if (cube.Channel(c).size() != layout.texel_count()) {
      throw std::invalid_argument("CubemapBackground: channel " + std::to_string(c) + " has " +
                                  std::to_string(cube.Channel(c).size()) + " texels, expected " +
                                  std::to_string(layout.texel_count()));
    }
    for (std::size_t j = 0; j < layout.texel_count(); ++j)
      if (!std::isfinite(cube.Channel(c)[j]))
        throw NumericalError("CubemapBackground: texel " + std::to_string(j) + " (channel " +
                             std::to_string(c) + ") is not finite");
  }
  return [layout, cube](const Vec3& d) {
    const std::size_t t = layout.TexelOf(d);
    return Rgb{cube.r[t], cube.g[t], cube.b[t]};
  };
}

}  // namespace prt
