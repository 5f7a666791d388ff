// prt-runtime-bench: the C API (runtime/prt_runtime.h) against prt-view's relighter on one pack,
// in one run (docs/runtime.md, "Speed"): exact lighting and PBI frames of N = 30 / 100 / 300
// terms under a rotating environment, each as
//   prt-view      ViewerSession (TBB, every core): what prt-view does per frame;
//   C 1 thread    prt_runtime_relight with no task runner (the default);
//   C runner ×2   prt_runtime_relight with a 2-thread host pool as the task runner;
//   C ranges ×2   prt_runtime_prepare + 2 × prt_runtime_relight_range on 2 host threads;
//                 and the same ranges timed one after the other on one thread: the frame ÷
//                 (prepare + the slower range) is the split's speed-up on two free cores, and
//                 (prepare + both ranges) ÷ the frame what splitting adds to the work.
// Medians over the frames; ratios against "C 1 thread" of the same run. Also: the lighting per
// frame (set_rotation: resample + projection), open time, prt_runtime_memory_bytes and the
// process's peak RSS.
//
// A glossy pack (prt_runtime_is_glossy: visibility, Algorithm 1 per frame towards the eye;
// docs/runtime.md, "Glossy packs") is measured instead as the frames a viewer makes: an orbit
// step (prt_runtime_set_eye 0.02 rad further about the camera's target, then relight) and a
// lighting rotation step (set_rotation_y 0.01 rad further, with and without the preview, then
// relight), each through the C API on 1 thread, with the 2-thread task runner and as 2 ranges on
// 2 host threads, against prt-view's GlossySession on TBB.
//
// Usage: prt-runtime-bench PACK ENV.exr [frames]
#include <sys/resource.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "runtime/lighting.h"
#include "runtime/prt_runtime.h"
#include "viewer/glossy_session.h"
#include "viewer/viewer_session.h"
#include "vocabulary/cubemap_resample.h"
#include "vocabulary/environment_io.h"
#include "vocabulary/tbb_parallel.h"

namespace {

using Clock = std::chrono::steady_clock;

double Ms(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

// A host's job system: `threads` − 1 workers plus the calling thread share each run's indices.
class Pool {
 public:
  explicit Pool(unsigned threads) {
    for (unsigned i = 1; i < threads; ++i) workers_.emplace_back([this] { Work(); });
  }
  ~Pool() {
    {
      std::lock_guard<std::mutex> lock(m_);
      stop_ = true;
    }
    cv_.notify_all();
    for (std::thread& t : workers_) t.join();
  }
  static void Run(void* user, size_t count, void (*task)(void*, size_t), void* data) {
    static_cast<Pool*>(user)->RunAll(count, task, data);
  }

 private:
  void RunAll(size_t count, void (*task)(void*, size_t), void* data) {
    {
      std::lock_guard<std::mutex> lock(m_);
      task_ = task;
      data_ = data;
      count_ = count;
      next_.store(0);
      done_.store(0);
      ++generation_;
    }
    cv_.notify_all();
    Drain();
    while (done_.load() < count) std::this_thread::yield();
  }
  void Drain() {
    for (size_t i; (i = next_.fetch_add(1)) < count_;) {
      task_(data_, i);
      done_.fetch_add(1);
    }
  }
  void Work() {
    uint64_t seen = 0;
    for (;;) {
      {
        std::unique_lock<std::mutex> lock(m_);
        cv_.wait(lock, [&] { return stop_ || generation_ != seen; });
        if (stop_) return;
        seen = generation_;
      }
      Drain();
    }
  }
  std::vector<std::thread> workers_;
  std::mutex m_;
  std::condition_variable cv_;
  bool stop_ = false;
  uint64_t generation_ = 0;
  void (*task_)(void*, size_t) = nullptr;
  void* data_ = nullptr;
  size_t count_ = 0;
  std::atomic<size_t> next_{0}, done_{0};
};

std::vector<float> Interleaved(const prt::EnvironmentImage& e) {
  std::vector<float> rgb(3 * e.PixelCount());
  for (std::size_t i = 0; i < e.PixelCount(); ++i) {
    rgb[3 * i] = e.r[i];
    rgb[3 * i + 1] = e.g[i];
    rgb[3 * i + 2] = e.b[i];
  }
  return rgb;
}

void Check(int status) {
  if (status != PRT_RUNTIME_OK) {
    std::fprintf(stderr, "prt-runtime-bench: %s\n", prt_runtime_last_error());
    std::exit(1);
  }
}

double PeakRssMiB() {
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  return static_cast<double>(ru.ru_maxrss) / 1024.0;
}

// A glossy pack's frames (see the header comment). `rt` has the environment set.
int RunGlossy(prt_runtime* rt, const std::string& pack, const prt::EnvironmentImage& env,
              int frames, double open_ms, double env_ms) {
  const std::size_t n = prt_runtime_sample_count(rt);
  std::vector<float> rgb(3 * n);
  float eye0[3], target[3];
  Check(prt_runtime_get_camera(rt, eye0, target, nullptr, nullptr, nullptr, nullptr));
  // The eye turned by `a` about the vertical through the target (prt-view's window orbit).
  const auto orbit = [&](double a, float out[3]) {
    const double x = eye0[0] - target[0], z = eye0[2] - target[2];
    out[0] = static_cast<float>(target[0] + x * std::cos(a) + z * std::sin(a));
    out[1] = eye0[1];
    out[2] = static_cast<float>(target[2] - x * std::sin(a) + z * std::cos(a));
  };
  std::vector<double> rotation_ms, preview_ms;
  for (int f = 0; f < frames; ++f) {
    auto t0 = Clock::now();
    Check(prt_runtime_set_rotation_y(rt, 0.01 * f));
    rotation_ms.push_back(Ms(t0));
  }
  Check(prt_runtime_set_preview(rt, 1));
  for (int f = 0; f < frames; ++f) {
    auto t0 = Clock::now();
    Check(prt_runtime_set_rotation_y(rt, 0.01 * f));
    preview_ms.push_back(Ms(t0));
  }
  Check(prt_runtime_set_preview(rt, 0));
  std::printf(
      "%s: glossy, %zu vertices, n = %u; open %.0f ms, environment %dx%d %.1f ms, lighting per "
      "rotation (set_rotation_y: resample + block lighting) %.2f ms, with prt_runtime_set_preview "
      "%.2f ms\n",
      pack.c_str(), n, prt_runtime_cubemap_size(rt), open_ms, env.width, env.height, env_ms,
      Median(rotation_ms), Median(preview_ms));

  // Three kinds of step, each: change the view or the lighting, then relight (timed together).
  const auto steps = [&](const std::function<void()>& relight) {
    std::vector<double> med;
    for (int kind = 0; kind < 3; ++kind) {  // orbit, rotation with preview, rotation exact
      Check(prt_runtime_set_preview(rt, kind == 1 ? 1 : 0));
      Check(prt_runtime_set_rotation_y(rt, 0.0));
      float e[3];
      orbit(0.0, e);
      Check(prt_runtime_set_eye(rt, e));
      std::vector<double> t;
      for (int f = 0; f < frames + 2; ++f) {
        const auto s = Clock::now();
        if (kind == 0) {
          orbit(0.02 * f, e);
          Check(prt_runtime_set_eye(rt, e));
        } else {
          Check(prt_runtime_set_rotation_y(rt, 0.01 * f));
        }
        relight();
        if (f >= 2) t.push_back(Ms(s));
      }
      med.push_back(Median(t));
    }
    Check(prt_runtime_set_preview(rt, 0));
    return med;
  };
  const auto whole = [&] { Check(prt_runtime_relight(rt, 0, rgb.data(), n)); };
  const std::vector<double> c1 = steps(whole);
  const std::size_t mem = prt_runtime_memory_bytes(rt);
  Pool pool(2);
  prt_runtime_set_task_runner(&Pool::Run, &pool, 2);
  const std::vector<double> runner = steps(whole);
  prt_runtime_set_task_runner(nullptr, nullptr, 1);
  const std::vector<double> ranges = steps([&] {
    Check(prt_runtime_prepare(rt, 0));
    int s1 = PRT_RUNTIME_OK;
    std::thread other([&] { s1 = prt_runtime_relight_range(rt, n / 2, n - n / 2, rgb.data(), n); });
    Check(prt_runtime_relight_range(rt, 0, n / 2, rgb.data(), n));
    other.join();
    Check(s1);
  });
  prt_runtime_close(rt);

  // prt-view's GlossySession on TBB (every core): the same steps as prt-view's window makes them
  // (without its rasteriser).
  prt::UseTbbParallelism();
  const auto session = prt::GlossySession::Open(pack);
  const int cn = session->cubemap_n();
  std::vector<double> view;
  for (int kind = 0; kind < 3; ++kind) {
    prt::BlockLighting light = session->Lighting(prt::ResampleToCubemap(env, cn, 0.0));
    std::vector<double> t;
    for (int f = 0; f < frames + 2; ++f) {
      float e[3];
      orbit(kind == 0 ? 0.02 * f : 0.0, e);
      const auto s = Clock::now();
      if (kind == 2) light = session->Lighting(prt::ResampleToCubemap(env, cn, 0.01 * f));
      session->Relight(light, prt::Vec3{e[0], e[1], e[2]}, rgb, {.exact_cosine = true});
      if (f >= 2) t.push_back(Ms(s));
    }
    view.push_back(kind == 1 ? std::nan("") : Median(t));
  }

  std::printf("\n%-22s %12s %12s %12s\n", "median ms per frame", "orbit step", "rot. preview",
              "rot. exact");
  const auto row = [&](const char* name, const std::vector<double>& v) {
    std::printf("%-22s", name);
    for (double x : v) std::isnan(x) ? std::printf(" %12s", "-") : std::printf(" %12.2f", x);
    std::printf("\n");
  };
  row("prt-view (TBB)", view);
  row("C API, 1 thread", c1);
  row("C API, runner x2", runner);
  row("C API, 2 ranges x2", ranges);
  std::printf("\n%-22s %12s %12s %12s\n", "speed-up vs 1 thread", "orbit step", "rot. preview",
              "rot. exact");
  const auto ratio = [&](const char* name, const std::vector<double>& v) {
    std::printf("%-22s", name);
    for (std::size_t i = 0; i < v.size(); ++i)
      std::isnan(v[i]) ? std::printf(" %12s", "-") : std::printf(" %11.2fx", c1[i] / v[i]);
    std::printf("\n");
  };
  ratio("prt-view (TBB)", view);
  ratio("C API, runner x2", runner);
  ratio("C API, 2 ranges x2", ranges);
  std::printf(
      "\nprt_runtime_memory_bytes %.1f MiB (pack file %.1f MiB); peak RSS of this process "
      "%.1f MiB\n",
      static_cast<double>(mem) / (1 << 20),
      static_cast<double>(std::filesystem::file_size(pack)) / (1 << 20), PeakRssMiB());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: prt-runtime-bench PACK ENV.exr [frames]\n");
    return 1;
  }
  const std::string pack = argv[1];
  const int frames = argc > 3 ? std::max(3, std::atoi(argv[3])) : 30;
  const prt::EnvironmentImage env = prt::ReadEnvironment(argv[2]);
  const std::vector<float> map = Interleaved(env);
  const unsigned budgets[] = {0, 30, 100, 300};  // 0: exact

  // The C API, one thread: open, lighting, then the frames.
  auto t0 = Clock::now();
  prt_runtime* rt = prt_runtime_open_file(pack.c_str());
  if (rt == nullptr) {
    std::fprintf(stderr, "prt-runtime-bench: %s\n", prt_runtime_last_error());
    return 1;
  }
  const double open_ms = Ms(t0);
  const std::size_t n = prt_runtime_sample_count(rt);
  std::vector<float> rgb(3 * n);
  t0 = Clock::now();
  Check(prt_runtime_set_environment_latlong(rt, map.data(), env.width, env.height));
  const double env_ms = Ms(t0);
  if (prt_runtime_is_glossy(rt) == 1) return RunGlossy(rt, pack, env, frames, open_ms, env_ms);
  std::vector<double> rotation_ms;
  for (int f = 0; f < frames; ++f) {
    t0 = Clock::now();
    Check(prt_runtime_set_rotation_y(rt, 0.01 * f));
    rotation_ms.push_back(Ms(t0));
  }
  Check(prt_runtime_set_preview(rt, 1));
  std::vector<double> preview_ms;
  for (int f = 0; f < frames; ++f) {
    t0 = Clock::now();
    Check(prt_runtime_set_rotation_y(rt, 0.01 * f));
    preview_ms.push_back(Ms(t0));
  }
  Check(prt_runtime_set_preview(rt, 0));
  std::printf(
      "%s: %zu samples, n = %u; open %.0f ms, environment %dx%d %.1f ms, lighting per frame "
      "(set_rotation: resample + projection) %.2f ms, with prt_runtime_set_preview %.2f ms\n",
      pack.c_str(), n, prt_runtime_cubemap_size(rt), open_ms, env.width, env.height, env_ms,
      Median(rotation_ms), Median(preview_ms));

  // One configuration's frame times per budget: rotate a little, relight (PBI for N > 0).
  const auto run_c = [&](const std::function<void(unsigned)>& relight) {
    std::vector<double> med;
    for (unsigned terms : budgets) {
      Check(prt_runtime_set_lighting_mode(rt, PRT_RUNTIME_LIGHTING_NWA));  // restarts PBI
      Check(prt_runtime_set_lighting_mode(rt, PRT_RUNTIME_LIGHTING_PBI));
      std::vector<double> t;
      for (int f = 0; f < frames + 2; ++f) {
        Check(prt_runtime_set_rotation_y(rt, 0.01 * f));
        const auto s = Clock::now();
        relight(terms);
        if (f >= 2) t.push_back(Ms(s));  // the first frames warm the buffers
      }
      med.push_back(Median(t));
    }
    return med;
  };
  const auto whole = [&](unsigned terms) { Check(prt_runtime_relight(rt, terms, rgb.data(), n)); };
  const std::vector<double> c1 = run_c(whole);
  const std::size_t mem = prt_runtime_memory_bytes(rt);

  Pool pool(2);
  prt_runtime_set_task_runner(&Pool::Run, &pool, 2);
  const std::vector<double> runner = run_c(whole);
  prt_runtime_set_task_runner(nullptr, nullptr, 1);

  // Two host threads, one range each (the runtime's order: contiguous regions of interest).
  Check(prt_runtime_set_sample_order(rt, PRT_RUNTIME_ORDER_RUNTIME));
  const std::vector<double> ranges = run_c([&](unsigned terms) {
    Check(prt_runtime_prepare(rt, terms));
    int s1 = PRT_RUNTIME_OK;
    std::thread other([&] { s1 = prt_runtime_relight_range(rt, n / 2, n - n / 2, rgb.data(), n); });
    Check(prt_runtime_relight_range(rt, 0, n / 2, rgb.data(), n));
    other.join();
    Check(s1);
  });
  // The same two ranges one after the other on this thread, each timed: the split's speed-up
  // where the host has two free cores, whole frame ÷ the slower range (on a shared 2-core
  // machine the two-thread row above also measures whoever else holds a core).
  std::vector<double> split_bound, split_overhead;
  for (std::size_t b = 0; b < std::size(budgets); ++b) {
    Check(prt_runtime_set_lighting_mode(rt, PRT_RUNTIME_LIGHTING_NWA));
    Check(prt_runtime_set_lighting_mode(rt, PRT_RUNTIME_LIGHTING_PBI));
    std::vector<double> slower, both;
    for (int f = 0; f < frames + 2; ++f) {
      Check(prt_runtime_set_rotation_y(rt, 0.01 * f));
      const auto s0 = Clock::now();
      Check(prt_runtime_prepare(rt, budgets[b]));
      const double prep = Ms(s0);
      const auto s1 = Clock::now();
      Check(prt_runtime_relight_range(rt, 0, n / 2, rgb.data(), n));
      const double a = Ms(s1);
      const auto s2 = Clock::now();
      Check(prt_runtime_relight_range(rt, n / 2, n - n / 2, rgb.data(), n));
      const double c = Ms(s2);
      if (f >= 2) {
        slower.push_back(prep + std::max(a, c));
        both.push_back(prep + a + c);
      }
    }
    split_bound.push_back(c1[b] / Median(slower));
    split_overhead.push_back(Median(both) / c1[b]);
  }
  prt_runtime_close(rt);

  // prt-view's relighter: ViewerSession on TBB, as prt-view runs a frame.
  prt::UseTbbParallelism();
  const auto session = prt::ViewerSession::Open(pack);
  std::vector<double> view;
  for (unsigned terms : budgets) {
    std::unique_ptr<prt::PerBandIncrementalRelighter> pbi;
    if (terms > 0)
      pbi = std::make_unique<prt::PerBandIncrementalRelighter>(session->transport(),
                                                               session->cubemap_n(), terms);
    std::vector<double> t;
    for (int f = 0; f < frames + 2; ++f) {
      const prt::WaveletLighting l =
          prt::ProjectLighting(prt::ResampleToCubemap(env, session->cubemap_n(), 0.01 * f));
      const auto s = Clock::now();
      const std::vector<float> shaded =
          session->Shade(terms == 0 ? session->RelightExact(l) : (pbi->Update(l), pbi->Radiance()));
      const std::vector<float> packed = session->ToPackOrder(shaded);
      if (f >= 2) t.push_back(Ms(s));
    }
    view.push_back(Median(t));
  }

  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  std::printf("\n%-22s %10s %10s %10s %10s\n", "median ms per frame", "exact", "PBI-30", "PBI-100",
              "PBI-300");
  const auto row = [&](const char* name, const std::vector<double>& v) {
    std::printf("%-22s", name);
    for (double x : v) std::printf(" %10.3f", x);
    std::printf("\n");
  };
  row("prt-view (TBB)", view);
  row("C API, 1 thread", c1);
  row("C API, runner x2", runner);
  row("C API, 2 ranges x2", ranges);
  std::printf("\n%-22s %10s %10s %10s %10s\n", "speed-up vs 1 thread", "exact", "PBI-30", "PBI-100",
              "PBI-300");
  const auto ratio = [&](const char* name, const std::vector<double>& v) {
    std::printf("%-22s", name);
    for (std::size_t i = 0; i < v.size(); ++i) std::printf(" %9.2fx", c1[i] / v[i]);
    std::printf("\n");
  };
  ratio("prt-view (TBB)", view);
  ratio("C API, runner x2", runner);
  ratio("C API, 2 ranges x2", ranges);
  std::printf("%-22s", "2 ranges, free cores");
  for (double x : split_bound) std::printf(" %9.2fx", x);
  std::printf("\n%-22s", "2 ranges' work / frame");
  for (double x : split_overhead) std::printf(" %9.2fx", x);
  std::printf("\n");
  std::printf(
      "\nprt_runtime_memory_bytes %.1f MiB (pack file %.1f MiB); peak RSS of this "
      "process %.1f MiB\n",
      static_cast<double>(mem) / (1 << 20),
      static_cast<double>(std::filesystem::file_size(pack)) / (1 << 20),
      static_cast<double>(ru.ru_maxrss) / 1024.0);
  return 0;
}
