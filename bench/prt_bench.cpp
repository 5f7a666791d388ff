// prt-bench: what each setting buys, run time against error (issue 9, docs/benchmarks.md).
//
// For each scene (the default scene and real meshes on its ground plane, bench/bench_scenes.h)
// at cubemap resolution n it traces the brute-force transport T (the exact reference) and sweeps
//   - sparse precomputation (Huang & Ramamoorthi 2010) at several dense budgets, feature counts
//     and radii (worker/sparse_precomputation.h);
//   - 2D (Ng et al. 2003), full 4D and adaptive 4D (Cheslack-Postava et al. 2008) compression of
//     the brute-force T at several keep budgets and bit depths (worker/transport_compressor.h),
//     relit by Eq. 8 from the compressed columns;
//   - NWA and PBI lighting (Overbeck et al. 2006) at several term counts, through T compressed
//     with the scene's [compression] settings as prt-view relights it, while each environment
//     rotates about +Y;
// and records for each point: wall and CPU time of the stage, rays traced, bytes stored, one
// relighting's time, the relative Frobenius error of T against the brute-force T, and the relative
// RMS error of relit radiance B = albedo ⊙ (T·L) against the brute-force exact result under each
// real environment (all samples, model and ground).
//
// Outputs in --out: prt_bench.csv (one row per point), prt_bench.md (every point, the Pareto
// fronts per scene: precomputation time, bytes and relighting time against error, the cheapest
// setting under error targets, and the papers' operating points next to ours) and, with gnuplot,
// plots/<scene>_{time,size,relight}_error.png with the papers' operating points marked.
//
// Under `mpirun -np K prt-bench` the ranks trace the brute-force rows in K slices (gathered on
// every rank), then split the sweep points round-robin; rank 0 gathers the rows and writes the
// outputs. Every number but the timings is identical to a 1-rank run (--compare checks that).
//
// Usage: prt-bench [--scenes default,armadillo,dragon] [--envs sunrise,city,studio,interior]
//                  [--n 16] [--rays 0] [--ground 0] [--out bench-out/prt-bench] [--quick]
//                  [--self-check]
//                  [--threads 0] [--dense-budgets ..] [--feature-scales ..] [--radius-scales ..]
//                  [--schemes ..] [--keeps ..] [--bits ..] [--terms ..] [--frames 24] [--deg 1]
//        prt-bench --check DIR           (sanity checks on DIR's CSV and summary, exit 1 if not)
//        prt-bench --compare DIR1 DIR2   (every non-timing column equal, exit 1 if not)
//
// The sweep: prt_bench_sweep.h; the records and their CSV: prt_bench_records.h; the summary,
// plots and checks: prt_bench_report.h. This file is the command line and the MPI split.
#include <tbb/global_control.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "bench/prt_bench_records.h"
#include "bench/prt_bench_report.h"
#include "bench/prt_bench_sweep.h"
#include "farm/mpi_session.h"
#include "vocabulary/tbb_parallel.h"

using namespace prt;
using namespace prt::bench;
namespace fs = std::filesystem;

int main(int argc, char** argv) {
  prt::UseTbbParallelism();  // the core vocabulary's and the runtime's loops on TBB
  Options o;
  std::string scenes = "default,armadillo,dragon", envs = "sunrise,city,studio,interior";
  std::string out_dir = "bench-out/prt-bench", check_dir;
  std::vector<std::string> compare_dirs, merge_dirs;
  std::string budgets = "0.25,0.1", fscales = "1,0.5", rscales = "1,2";
  std::string schemes = "2d,4d,adaptive4d", keeps = "0.01,0.03,0.1", bits = "9,6,12";
  std::string terms = "10,30,90,300";
  bool quick = false, self_check = false;
  int threads = 0;
  CLI::App app{"prt-bench: run time against error for every setting (docs/benchmarks.md)"};
  app.add_option("--scenes", scenes, "comma-separated: default, armadillo, dragon, camel");
  app.add_option("--envs", envs, "environment maps (data folder envmaps/NAME.exr)");
  app.add_option("--n", o.n, "cubemap resolution");
  app.add_option("--rays", o.rays, "rays per texel (0: the scene's)");
  app.add_option("--ground", o.ground, "ground grid vertices per side (0: the scene's 64)");
  app.add_option("--out", out_dir, "output folder (CSV, summary, plots)");
  app.add_option("--threads", threads, "TBB threads per rank (0: cores / ranks)");
  app.add_option("--dense-budgets", budgets, "sparse: dense-vertex fractions (first: the centre)");
  app.add_option("--feature-scales", fscales, "sparse: feature counts × the scene's");
  app.add_option("--radius-scales", rscales, "sparse: radius × the scene's");
  app.add_option("--schemes", schemes, "compression schemes: 2d, 4d, adaptive4d");
  app.add_option("--keeps", keeps, "compression keep fractions");
  app.add_option("--bits", bits, "quantisation bit depths (first: the centre)");
  app.add_option("--terms", terms, "NWA/PBI terms per frame");
  app.add_option("--frames", o.frames, "NWA/PBI: rotating frames");
  app.add_option("--deg", o.deg, "NWA/PBI: rotation per frame, degrees");
  app.add_flag("--quick", quick,
               "CI size: the dragon on a 16×16 ground, n = 8, 1 ray/texel, sunrise and city, one "
               "sparse point, 2D/4D/adaptive 4D at three budgets, NWA and PBI at 30 and 90 terms");
  app.add_flag("--self-check", self_check, "check the outputs after writing them (as --check)");
  app.add_option("--check", check_dir, "only check an output folder");
  app.add_option("--compare", compare_dirs, "only compare two output folders")->expected(2);
  app.add_option("--merge", merge_dirs,
                 "only merge output folders' CSVs (same environments) into --out: CSV, summary, "
                 "plots")
      ->expected(1, 64);
  CLI11_PARSE(app, argc, argv);
  if (!check_dir.empty()) return Report(CheckOutputs(check_dir), "check " + check_dir);
  if (!compare_dirs.empty()) {
    try {
      return Report(CompareOutputs(compare_dirs[0], compare_dirs[1]),
                    "compare " + compare_dirs[0] + " " + compare_dirs[1]);
    } catch (const std::exception& e) {
      return Report({e.what()}, "compare");
    }
  }
  if (!merge_dirs.empty()) {
    try {
      std::vector<std::string> merged_envs, merged_scenes, lines;
      std::vector<Record> merged;
      for (const std::string& d : merge_dirs) {
        const CsvFile c = ReadCsv(d + "/prt_bench.csv");
        if (!merged_envs.empty() && c.envs != merged_envs)
          throw std::runtime_error(d + "/prt_bench.csv: other environments than " + merge_dirs[0]);
        merged_envs = c.envs;
        merged.insert(merged.end(), c.records.begin(), c.records.end());
        lines.insert(lines.end(), c.lines.begin(), c.lines.end());
        for (const Record& r : c.records)
          if (std::find(merged_scenes.begin(), merged_scenes.end(), r.scene) == merged_scenes.end())
            merged_scenes.push_back(r.scene);
      }
      fs::create_directories(out_dir + "/plots");
      std::ofstream csv(out_dir + "/prt_bench.csv");
      csv << CsvHeader(merged_envs) << '\n';
      for (const std::string& l : lines) csv << l << '\n';
      csv.close();
      std::string command = "prt-bench";
      for (int i = 1; i < argc; ++i) command += std::string(" ") + argv[i];
      std::ofstream(out_dir + "/prt_bench.md")
          << Summary(merged, merged_scenes, merged_envs, command);
      for (const std::string& sc : merged_scenes) Plot(merged, sc, out_dir + "/plots");
      return Report(CheckOutputs(out_dir), "merge into " + out_dir);
    } catch (const std::exception& e) {
      return Report({e.what()}, "merge");
    }
  }
  if (quick) {
    const auto set = [&](const char* opt, std::string& var, const char* value) {
      if (app.count(opt) == 0) var = value;
    };
    set("--scenes", scenes, "dragon");
    if (app.count("--ground") == 0) o.ground = 16;
    set("--envs", envs, "sunrise,city");
    if (app.count("--n") == 0) o.n = 8;
    if (app.count("--rays") == 0) o.rays = 1;
    if (app.count("--frames") == 0) o.frames = 8;
    if (app.count("--deg") == 0) o.deg = 2;
    set("--dense-budgets", budgets, "0.25");
    set("--feature-scales", fscales, "1");
    set("--radius-scales", rscales, "1");
    set("--keeps", keeps, "0.01,0.03,0.1");
    set("--bits", bits, "9");
    set("--terms", terms, "30,90");
  }
  o.scenes = SplitList(scenes);
  o.envs = SplitList(envs);
  o.dense_budgets = Numbers(budgets);
  o.feature_scales = Numbers(fscales);
  o.radius_scales = Numbers(rscales);
  o.schemes = SplitList(schemes);
  o.keeps = Numbers(keeps);
  o.bits = Numbers(bits);
  o.terms = Numbers(terms);
  o.eval_every = std::max(1, o.frames / 6);

  std::optional<MpiSession> session;
  try {
    session.emplace(&argc, &argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "prt-bench: %s\n", e.what());
    return 2;
  }
  const MpiSession& mpi = *session;
  const int rank = mpi.rank(), size = mpi.size();
  if (threads <= 0)
    threads = std::max(1, static_cast<int>(std::thread::hardware_concurrency()) / size);
  const tbb::global_control gc(tbb::global_control::max_allowed_parallelism, threads);
  std::string command = "prt-bench";
  for (int i = 1; i < argc; ++i) command += std::string(" ") + argv[i];
  if (size > 1) command = "mpirun -np " + std::to_string(size) + " " + command;

  int rc = 0;
  std::vector<Record> records;
  try {
    const std::vector<bench::NamedEnvironment> env_cubes = bench::BenchEnvironments(o.n, o.envs);
    const std::vector<Point> points = SweepPoints(o);
    // Outputs are rewritten after every scene, so that a long sweep cut short keeps its scenes.
    std::vector<std::pair<std::pair<std::size_t, std::size_t>, std::string>> rows;
    for (std::size_t si = 0; si < o.scenes.size(); ++si) {
      std::ostringstream mine;  // "scene index<TAB>csv" lines of this rank
      SceneBench sb(o.scenes[si], o, env_cubes);
      if (rank == 0)
        std::printf("== %s: %zu samples, n = %d, %d ray(s)/texel, %zu points on %d rank(s) ==\n",
                    o.scenes[si].c_str(), sb.samples(), o.n, sb.rays_per_texel(), points.size() + 1,
                    size);
      Record brute = sb.TraceBrute(mpi);
      Finish(brute);
      if (rank == 0) {
        mine << si << ' ' << 0 << '\t' << ToCsv(brute) << '\n';
        std::printf("  brute force: %.2f s wall, %.2f s CPU, %.3g rays\n", brute.wall_s,
                    brute.cpu_s, static_cast<double>(brute.rays));
        std::fflush(stdout);
      }
      for (std::size_t i = 0; i < points.size(); ++i) {
        if (static_cast<int>(i % static_cast<std::size_t>(size)) != rank) continue;
        Record r = sb.Run(points[i]);
        Finish(r);
        std::printf("  [rank %d] %-44s %8.2f s wall %8.2f s CPU %10.4g B %8.3f ms  err %.4g%%\n",
                    rank, r.label.c_str(), r.wall_s, r.cpu_s, static_cast<double>(r.bytes),
                    r.relight_ms, 100 * r.err_mean);
        std::fflush(stdout);
        mine << si << ' ' << i + 1 << '\t' << ToCsv(r) << '\n';
      }
      const std::string all = mpi.GatherText(mine.str());
      if (rank != 0) continue;
      for (const std::string& line : SplitList(all, '\n')) {
        if (line.empty()) continue;
        const auto tab = line.find('\t');
        std::size_t gsi = 0, pi = 0;
        std::sscanf(line.c_str(), "%zu %zu", &gsi, &pi);
        rows.push_back({{gsi, pi}, line.substr(tab + 1)});
      }
      std::sort(rows.begin(), rows.end());
      fs::create_directories(out_dir + "/plots");
      std::ofstream csv(out_dir + "/prt_bench.csv");
      csv << CsvHeader(o.envs) << '\n';
      records.clear();
      for (const auto& [key, line] : rows) {
        csv << line << '\n';
        records.push_back(FromCsv(line, o.envs.size(), "gathered row"));
      }
      csv.close();
      std::ofstream(out_dir + "/prt_bench.md") << Summary(records, o.scenes, o.envs, command);
      const bool plotted = Plot(records, o.scenes[si], out_dir + "/plots");
      std::printf("wrote %s/prt_bench.csv, %s/prt_bench.md%s\n", out_dir.c_str(), out_dir.c_str(),
                  plotted ? " and plots" : " (no plots: gnuplot failed)");
      std::fflush(stdout);
    }
    if (rank == 0 && self_check) rc = Report(CheckOutputs(out_dir), "check " + out_dir);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "prt-bench (rank %d): %s\n", rank, e.what());
    mpi.Abort(1);
  }
  return mpi.Broadcast(rc);
}
