// The rasteriser as it was before the tiled one (viewer/rasterizer.cpp, commit dd374b3): row
// bands of 16 rows, every edge function and interpolation in double per pixel, the background
// function called once per uncovered pixel. Kept, unchanged apart from its name, as the
// reference that rasterizer_test.cpp compares RasterizeTriangles against pixel for pixel and as
// the "old" column of bench/raster_bench.cpp; nothing else links it.
//
// Software z-buffer rasteriser: near-plane clipping (Sutherland–Hodgman against one plane), edge
// functions with the top-left fill rule, perspective-correct interpolation (attributes a/z and 1/z
// are affine in screen space; Heckbert & Moreton 1991), z-test on view depth.
#include "viewer/rasterizer_reference.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <string>

#include "vocabulary/errors.h"

namespace prt {

namespace {
constexpr double kFloatMax = static_cast<double>(std::numeric_limits<float>::max());
}  // namespace

namespace {

struct ClipVertex {
  Vec3 view;
  std::array<double, 3> rgb;
};

// A clipped triangle in screen space, ready for scan conversion.
struct ScreenTriangle {
  double px[3], py[3];
  double inv_z[3];
  double rgb_over_z[3][3];
  int32_t id = -1;  // −1: empty slot
  int ymin = 0, ymax = -1, xmin = 0, xmax = -1;
};

ClipVertex Lerp(const ClipVertex& a, const ClipVertex& b, double t) {
  ClipVertex r;
  r.view = a.view + (b.view - a.view) * t;
  for (int c = 0; c < 3; ++c) r.rgb[c] = a.rgb[c] + (b.rgb[c] - a.rgb[c]) * t;
  return r;
}

// Keeps the part of a triangle with view z ≥ near: 0, 3 or 4 vertices.
int ClipNear(const ClipVertex in[3], double near, ClipVertex out[4]) {
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

bool SetupTriangle(const CameraProjection& cam, const ClipVertex& a, const ClipVertex& b,
                   const ClipVertex& c, int32_t id, ScreenTriangle& t) {
  const ClipVertex* v[3] = {&a, &b, &c};
  double xmin = std::numeric_limits<double>::infinity(), xmax = -xmin, ymin = xmin, ymax = -xmin;
  for (int i = 0; i < 3; ++i) {
    cam.ViewToPixel(v[i]->view, t.px[i], t.py[i]);
    t.inv_z[i] = 1.0 / v[i]->view.z;
    for (int ch = 0; ch < 3; ++ch) t.rgb_over_z[i][ch] = v[i]->rgb[ch] * t.inv_z[i];
    xmin = std::min(xmin, t.px[i]);
    xmax = std::max(xmax, t.px[i]);
    ymin = std::min(ymin, t.py[i]);
    ymax = std::max(ymax, t.py[i]);
  }
  if (!std::isfinite(xmin + xmax + ymin + ymax)) return false;
  // Pixel centres x + ½ inside [xmin, xmax].
  // Clamped in double first so that a huge projected triangle cannot overflow an int.
  const double w = cam.width(), h = cam.height();
  t.xmin = static_cast<int>(std::ceil(std::clamp(xmin - 0.5, 0.0, w)));
  t.xmax = static_cast<int>(std::floor(std::clamp(xmax - 0.5, -1.0, w - 1.0)));
  t.ymin = static_cast<int>(std::ceil(std::clamp(ymin - 0.5, 0.0, h)));
  t.ymax = static_cast<int>(std::floor(std::clamp(ymax - 0.5, -1.0, h - 1.0)));
  t.id = id;
  return t.xmin <= t.xmax && t.ymin <= t.ymax;
}

// Edge function of the edge a→b at p: positive on one side, zero on the line. Evaluated with the
// endpoints in a canonical order and negated when swapped, so that the two triangles sharing an
// edge get bitwise opposite values and no pixel is lost or drawn twice along it.
inline double Edge(double ax, double ay, double bx, double by, double px, double py) {
  if (ax > bx || (ax == bx && ay > by)) {
    return -((ax - bx) * (py - by) - (ay - by) * (px - bx));
  }
  return (bx - ax) * (py - ay) - (by - ay) * (px - ax);
}

// Top-left rule: a pixel centre exactly on an edge belongs to the triangle whose interior lies to
// its right (+x) or, for a horizontal edge, below it (+y). `nx, ny` is the inward edge normal.
inline bool OwnsEdge(double nx, double ny) {
  return nx > 0.0 || (nx == 0.0 && ny > 0.0);
}

void DrawTriangle(const ScreenTriangle& t, int row0, int row1, int width, RasterImage& img) {
  const int y0 = std::max(row0, t.ymin), y1 = std::min(row1 - 1, t.ymax);
  if (y0 > y1) return;
  const double area = Edge(t.px[0], t.py[0], t.px[1], t.py[1], t.px[2], t.py[2]);
  if (area == 0.0 || !std::isfinite(area)) return;
  const double s = area > 0.0 ? 1.0 : -1.0;
  // Edge i is opposite vertex i: (1→2), (2→0), (0→1).
  const int ea[3] = {1, 2, 0}, eb[3] = {2, 0, 1};
  bool owns[3];
  for (int i = 0; i < 3; ++i) {
    const double dx = t.px[eb[i]] - t.px[ea[i]], dy = t.py[eb[i]] - t.py[ea[i]];
    owns[i] = OwnsEdge(-s * dy, s * dx);
  }
  // Each edge in the canonical endpoint order of Edge(): the per-pixel value below is the same
  // floating-point expression Edge() evaluates (bitwise), with the per-edge and per-row parts
  // hoisted out of the pixel loop.
  double ex0[3], ey0[3], edx[3], edy[3], esign[3];
  for (int i = 0; i < 3; ++i) {
    double ax = t.px[ea[i]], ay = t.py[ea[i]], bx = t.px[eb[i]], by = t.py[eb[i]];
    esign[i] = s;
    if (ax > bx || (ax == bx && ay > by)) {
      std::swap(ax, bx);
      std::swap(ay, by);
      esign[i] = -s;
    }
    ex0[i] = ax;
    ey0[i] = ay;
    edx[i] = bx - ax;
    edy[i] = by - ay;
  }
  const double inv_area = 1.0 / area;
  for (int y = y0; y <= y1; ++y) {
    const double py = y + 0.5;
    double row[3];
    for (int i = 0; i < 3; ++i) row[i] = edx[i] * (py - ey0[i]);
    for (int x = t.xmin; x <= t.xmax; ++x) {
      const double px = x + 0.5;
      double w[3];
      bool inside = true;
      for (int i = 0; i < 3; ++i) {
        w[i] = esign[i] * (row[i] - edy[i] * (px - ex0[i]));
        if (w[i] < 0.0 || (w[i] == 0.0 && !owns[i])) {
          inside = false;
          break;
        }
      }
      if (!inside) continue;
      // Screen-space barycentrics; 1/z and rgb/z are affine in screen space.
      double b[3];
      for (int i = 0; i < 3; ++i) b[i] = s * w[i] * inv_area;
      const double inv_z = b[0] * t.inv_z[0] + b[1] * t.inv_z[1] + b[2] * t.inv_z[2];
      if (!(inv_z > 0.0)) continue;
      const double z = 1.0 / inv_z;
      const std::size_t p = static_cast<std::size_t>(y) * width + x;
      if (!(z < img.depth[p])) continue;
      img.depth[p] = static_cast<float>(z);
      img.triangle[p] = t.id;
      for (int c = 0; c < 3; ++c) {
        // Perspective-correct interpolation is a convex combination of the three vertex colours
        // (weights b_i·(1/z_i)·z ≥ 0 summing to 1), which are finite floats (checked on entry):
        // v lies within their range up to double rounding (~1e-16 relative, far below half a
        // float ulp), so it converts to a finite float; the clamp states that bound.
        const double v =
            (b[0] * t.rgb_over_z[0][c] + b[1] * t.rgb_over_z[1][c] + b[2] * t.rgb_over_z[2][c]) * z;
        img.rgb[3 * p + c] = static_cast<float>(std::clamp(v, -kFloatMax, kFloatMax));
      }
    }
  }
}

}  // namespace

RasterImage RasterizeTrianglesReference(const Camera& camera, std::span<const Vec3> positions,
                                        std::span<const std::array<uint32_t, 3>> triangles,
                                        std::span<const float> vertex_rgb,
                                        const RasterOptions& options) {
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
  const double near = options.near > 0.0 ? options.near : 1e-3;
  // Clip and project every triangle (at most two screen triangles each), in parallel over chunks
  // of triangles; each chunk keeps only the screen triangles that cover a pixel centre, and the
  // chunks are concatenated in triangle order (tiny and off-screen triangles cost no memory).
  constexpr std::size_t kChunk = 4096;
  const std::size_t chunks = (triangles.size() + kChunk - 1) / kChunk;
  std::vector<std::vector<ScreenTriangle>> chunk_screen(chunks);
  tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t ch) {
    std::vector<ScreenTriangle>& out_tris = chunk_screen[ch];
    const std::size_t end = std::min(triangles.size(), (ch + 1) * kChunk);
    for (std::size_t i = ch * kChunk; i < end; ++i) {
      ClipVertex in[3];
      for (int k = 0; k < 3; ++k) {
        const uint32_t v = triangles[i][k];
        in[k].view = cam.ToView(positions[v]);
        for (int c = 0; c < 3; ++c) in[k].rgb[c] = vertex_rgb[3 * static_cast<std::size_t>(v) + c];
      }
      ClipVertex out[4];
      const int n = ClipNear(in, near, out);
      const auto id = static_cast<int32_t>(i);
      ScreenTriangle t;
      if (n >= 3 && SetupTriangle(cam, out[0], out[1], out[2], id, t)) out_tris.push_back(t);
      if (n == 4 && SetupTriangle(cam, out[0], out[2], out[3], id, t)) out_tris.push_back(t);
    }
  });
  std::vector<ScreenTriangle> screen;
  {
    std::size_t total = 0;
    for (const auto& c : chunk_screen) total += c.size();
    screen.reserve(total);
    for (auto& c : chunk_screen) {
      screen.insert(screen.end(), c.begin(), c.end());
      std::vector<ScreenTriangle>().swap(c);
    }
  }

  RasterImage img;
  img.width = camera.width;
  img.height = camera.height;
  const std::size_t pixels = static_cast<std::size_t>(img.width) * img.height;
  img.rgb.assign(3 * pixels, 0.0f);
  img.depth.assign(pixels, std::numeric_limits<float>::max());
  img.triangle.assign(pixels, -1);

  // Bin the screen triangles by row band (counting sort, triangles keep their order inside a
  // band so that depth ties resolve as in a sequential scan), then draw the bands in parallel:
  // each band touches only its own triangles instead of scanning all of them.
  constexpr int kBandRows = 16;
  const int bands = (img.height + kBandRows - 1) / kBandRows;
  std::vector<uint32_t> band_start(static_cast<std::size_t>(bands) + 1, 0);
  for (const ScreenTriangle& t : screen) {
    for (int b = t.ymin / kBandRows; b <= t.ymax / kBandRows; ++b) ++band_start[b + 1];
  }
  for (int b = 0; b < bands; ++b) band_start[b + 1] += band_start[b];
  std::vector<uint32_t> band_triangles(band_start[bands]);
  {
    std::vector<uint32_t> fill(band_start.begin(), band_start.end() - 1);
    for (std::size_t i = 0; i < screen.size(); ++i) {
      const ScreenTriangle& t = screen[i];
      for (int b = t.ymin / kBandRows; b <= t.ymax / kBandRows; ++b)
        band_triangles[fill[b]++] = static_cast<uint32_t>(i);
    }
  }
  tbb::parallel_for(0, bands, [&](int band) {
    const int row0 = band * kBandRows, row1 = std::min(img.height, row0 + kBandRows);
    for (uint32_t k = band_start[band]; k < band_start[band + 1]; ++k) {
      DrawTriangle(screen[band_triangles[k]], row0, row1, img.width, img);
    }
    if (options.background) {
      for (int y = row0; y < row1; ++y) {
        for (int x = 0; x < img.width; ++x) {
          const std::size_t p = static_cast<std::size_t>(y) * img.width + x;
          if (img.triangle[p] >= 0) continue;
          const Rgb c = options.background(cam.PixelDirection(x + 0.5, y + 0.5));
          // The library's backgrounds are finite (EnvironmentLookup and CubemapBackground check
          // their data); any other function's NaN/Inf is an error, never a black pixel.
          if (!std::isfinite(c[0]) || !std::isfinite(c[1]) || !std::isfinite(c[2]))
            throw NumericalError(
                "RasterizeTriangles: the background of pixel (x=" + std::to_string(x) +
                ", y=" + std::to_string(y) + ") is not finite");
          for (int k = 0; k < 3; ++k) img.rgb[3 * p + k] = c[k];
        }
      }
    }
  });
  return img;
}

}  // namespace prt
