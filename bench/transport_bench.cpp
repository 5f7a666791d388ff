// transport_bench: how close does TransportSampler come to raw Embree occlusion throughput?
// DESIGN.md: "prtfarm against raw Embree throughput on the same rays". On a real mesh (the CGAL
// bunny, fitted to a unit box, on a 4×4 ground grid of 64×64 vertices: the default scene) it
// times, on one thread,
//   (1) TransportSampler::ComputeRows over a set of spatial samples (rays traced per second),
//   (2) a bare rtcOccluded1 loop (EmbreeScene::CountOccluded) over exactly the rays of (1),
//       pre-generated into an array by TransportSampler::AppendRowRays,
//   (4) the same rays through EmbreeScene::CountOccludedInPackets (packets of 16, as the sampler
//       traces them since 27 Nov 2026),
// and prints (1)/(2) (goal ≥ 0.8) and (1)/(4), plus (1) on all threads and (2) on the same rays
// shuffled (incoherent) and the cost of generating the rays without tracing them
// (ComputeUnoccludedTexels), for context. Each time is the best of several passes after a warm-up.
//
// Usage: transport_bench [mesh file] [cubemap n] [rays per texel] [samples] [passes]
#include <tbb/task_arena.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "vocabulary/mesh.h"
#include "vocabulary/mesh_io.h"
#include "vocabulary/scene.h"
#include "vocabulary/tbb_parallel.h"
#include "worker/embree_scene.h"
#include "worker/transport_sampler.h"

#ifndef PRT_DATA_DIR
#define PRT_DATA_DIR "data"
#endif

namespace {

using Clock = std::chrono::steady_clock;

// Wall-clock and calling-thread CPU seconds of one call. On a shared, loaded machine the thread
// CPU time is the fairer single-thread measure (it does not count time spent waiting for a core).
struct Timing {
  double wall = 1e300;
  double cpu = 1e300;
};

double ThreadCpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

template <class F>
void TimeOnce(Timing& best, F&& f) {
  const double c0 = ThreadCpuSeconds();
  const auto t0 = Clock::now();
  f();
  best.wall = std::min(best.wall, std::chrono::duration<double>(Clock::now() - t0).count());
  best.cpu = std::min(best.cpu, ThreadCpuSeconds() - c0);
}

// Fallback when the data folder lacks the mesh: a UV sphere of radius 0.5 resting on y = 0.
prt::TriangleMesh ProceduralSphere(int rings, int segments) {
  prt::TriangleMesh m;
  m.source = "procedural sphere";
  for (int r = 0; r <= rings; ++r) {
    const double th = std::numbers::pi * r / rings;
    for (int s = 0; s < segments; ++s) {
      const double ph = 2 * std::numbers::pi * s / segments;
      const prt::Vec3 n{std::sin(th) * std::cos(ph), std::cos(th), std::sin(th) * std::sin(ph)};
      m.positions.push_back(n * 0.5 + prt::Vec3{0, 0.5, 0});
      m.normals.push_back(n);
    }
  }
  for (int r = 0; r < rings; ++r) {
    for (int s = 0; s < segments; ++s) {
      const auto a = static_cast<uint32_t>(r * segments + s);
      const auto b = static_cast<uint32_t>(r * segments + (s + 1) % segments);
      m.triangles.push_back({a, b + segments, a + segments});
      m.triangles.push_back({a, b, b + segments});
    }
  }
  return m;
}

}  // namespace

int main(int argc, char** argv) {
  prt::UseTbbParallelism();  // the core vocabulary's and the runtime's loops on TBB
  std::string mesh_path = std::string(PRT_DATA_DIR) + "/meshes/bunny00.off";
  int n = 32, k = 4, wanted = 96, passes = 5;
  CLI::App app{"transport_bench: ComputeRows against raw Embree occlusion on the same rays"};
  app.add_option("mesh", mesh_path, "mesh fitted on a 64x64 ground (default: the CGAL bunny)");
  app.add_option("n", n, "cubemap resolution");
  app.add_option("rays_per_texel", k, "rays per texel");
  app.add_option("samples", wanted, "spatial samples traced");
  app.add_option("passes", passes, "timing passes (best is reported)");
  CLI11_PARSE(app, argc, argv);

  prt::SceneGeometry geometry;
  prt::SceneMesh object;
  object.name = "object";
  try {
    if (!std::filesystem::exists(mesh_path)) {
      std::printf("note: %s not found; using a procedural sphere\n", mesh_path.c_str());
      object.mesh = ProceduralSphere(200, 400);
    } else {
      object.mesh = prt::LoadMesh(mesh_path);
      prt::MeshInstance instance;
      instance.fit = prt::FitBox{};  // size 1, standing on y = 0 at the origin
      prt::TransformInstance(instance, object.mesh);
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "transport_bench: %s\n", e.what());
    return 1;
  }
  geometry.meshes.push_back(std::move(object));
  prt::GroundPlane ground;
  ground.enabled = true;
  prt::SceneMesh ground_mesh;
  ground_mesh.name = "ground";
  ground_mesh.mesh = prt::MakeGroundGrid(ground);
  ground_mesh.is_ground = true;
  ground_mesh.grid_resolution = ground.resolution;
  geometry.meshes.push_back(std::move(ground_mesh));

  const auto build0 = Clock::now();
  const prt::EmbreeScene scene(geometry);
  const double build_s = std::chrono::duration<double>(Clock::now() - build0).count();
  const prt::TransportSampler sampler(scene, n, {k, 1});

  // Samples spread evenly over the global order (object vertices, then ground vertices).
  const std::vector<prt::SpatialSample> all = prt::SpatialSamplesOf(geometry);
  std::vector<prt::SpatialSample> samples;
  const std::size_t count = std::min<std::size_t>(static_cast<std::size_t>(wanted), all.size());
  for (std::size_t i = 0; i < count; ++i) samples.push_back(all[i * all.size() / count]);
  const std::size_t m = sampler.layout().texel_count();
  std::vector<float> rows(samples.size() * m);

  std::vector<prt::OcclusionRay> rays;
  for (std::size_t i = 0; i < samples.size(); ++i) sampler.AppendRowRays(samples[i], i, rays);

  // The measurements are interleaved pass by pass (after one warm-up pass each), so that load
  // from other processes hits them alike; each keeps its best pass.
  prt::SampleStats stats;
  tbb::task_arena one(1);  // one slot: ComputeRows runs entirely on the calling thread
  std::vector<prt::OcclusionRay> shuffled = rays;
  std::shuffle(shuffled.begin(), shuffled.end(), std::mt19937_64(7));
  const int threads = tbb::this_task_arena::max_concurrency();
  Timing t_rows, t_raw, t_shuffled, t_rows_mt, t_generate, warm_up, t_packets;
  std::vector<uint32_t> all_texels(m);
  for (std::size_t j = 0; j < m; ++j) all_texels[j] = static_cast<uint32_t>(j);
  std::size_t occluded = 0, occluded_packets = 0;
  for (int p = 0; p <= passes; ++p) {  // pass 0 warms caches, page tables and TBB up
    TimeOnce(p == 0 ? warm_up : t_rows,
             [&] { one.execute([&] { stats = sampler.ComputeRows(samples, 0, rows.data()); }); });
    TimeOnce(p == 0 ? warm_up : t_raw, [&] { occluded = scene.CountOccluded(rays); });
    TimeOnce(p == 0 ? warm_up : t_shuffled, [&] { scene.CountOccluded(shuffled); });
    TimeOnce(p == 0 ? warm_up : t_packets,
             [&] { occluded_packets = scene.CountOccludedInPackets(rays); });
    TimeOnce(p == 0 ? warm_up : t_generate, [&] {
      for (std::size_t i = 0; i < samples.size(); ++i) {
        sampler.ComputeUnoccludedTexels(samples[i], i, all_texels, rows.data() + i * m);
      }
    });
  }
  for (int p = 0; p < passes; ++p) {
    TimeOnce(t_rows_mt, [&] { sampler.ComputeRows(samples, 0, rows.data()); });
  }

  if (occluded_packets != occluded) {
    std::fprintf(stderr, "transport_bench: packets found %zu occluded rays, rtcOccluded1 %zu\n",
                 occluded_packets, occluded);
    return 1;
  }
  if (stats.rays_traced != rays.size()) {
    std::fprintf(stderr, "transport_bench: ComputeRows traced %llu rays, AppendRowRays gave %zu\n",
                 static_cast<unsigned long long>(stats.rays_traced), rays.size());
    return 1;
  }
  const double r = static_cast<double>(rays.size());
  std::printf(
      "transport_bench: %s (%zu triangles incl. ground 64x64, %zu geometries), "
      "BVH build %.3f s\n",
      mesh_path.c_str(), scene.triangle_count(), scene.geometry_count(), build_s);
  std::printf(
      "  n = %d, k = %d rays/texel, %zu samples, %zu rays (%.1f%% occluded), "
      "%llu texels traced, %llu below horizon, best of %d passes\n\n",
      n, k, samples.size(), rays.size(), 100.0 * static_cast<double>(occluded) / r,
      static_cast<unsigned long long>(stats.texels_traced),
      static_cast<unsigned long long>(stats.texels_below_horizon), passes);
  auto line = [&](const char* what, double seconds, int nthreads) {
    std::printf("  %-44s %9.4f %9.3f %14.3f\n", what, seconds, r / seconds * 1e-6,
                r / seconds * 1e-6 / nthreads);
  };
  std::printf("  %-44s %9s %9s %14s\n", "measure (best pass)", "seconds", "Mrays/s",
              "Mrays/s/thread");
  line("(1) ComputeRows, 1 thread, thread CPU time", t_rows.cpu, 1);
  line("(2) bare rtcOccluded1 loop, same rays, CPU", t_raw.cpu, 1);
  std::printf("  %-44s %9s %9.3f\n", "(3) ratio (1)/(2), CPU time [goal >= 0.8]", "",
              t_raw.cpu / t_rows.cpu);
  line("(1) ComputeRows, 1 thread, wall clock", t_rows.wall, 1);
  line("(2) bare rtcOccluded1 loop, wall clock", t_raw.wall, 1);
  std::printf("  %-44s %9s %9.3f\n", "(3) ratio (1)/(2), wall clock", "", t_raw.wall / t_rows.wall);
  line("(4) same rays in packets of 16, CPU", t_packets.cpu, 1);
  std::printf("  %-44s %9s %9.3f\n", "(5) ratio (1)/(4), CPU time", "", t_packets.cpu / t_rows.cpu);
  line("bare loop, same rays shuffled (incoherent)", t_shuffled.cpu, 1);
  line("ray generation only (no tracing), CPU", t_generate.cpu, 1);
  const std::string mt = "ComputeRows, " + std::to_string(threads) + " threads, wall clock";
  line(mt.c_str(), t_rows_mt.wall, threads);
  return 0;
}
