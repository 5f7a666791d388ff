// prt-view: relights a .prtpack under an environment map and writes the frame (docs/viewer.md).
// Exit codes: 0 success, 1 usage error, 2 bad input (unreadable or invalid pack/environment,
// unwritable output).
#include <CLI/CLI.hpp>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <iostream>
#include <memory>
#include <stdexcept>
#include <string>

#include "packager/prtpack_reader.h"
#include "runtime/camera_metadata.h"
#include "viewer/environment_background.h"
#include "viewer/glossy_session.h"
#include "viewer/npy_writer.h"
#include "viewer/rotation_plot.h"
#include "viewer/viewer_session.h"
#include "vocabulary/cubemap_resample.h"
#include "vocabulary/environment_io.h"
#include "vocabulary/envmap.h"
#include "vocabulary/errors.h"
#include "vocabulary/image_io.h"

#ifdef PRT_VIEW_HAS_SDL2
int RunViewerWindow(const prt::ViewerSession& session,
                    const std::shared_ptr<const prt::EnvironmentLookup>& env,
                    const prt::Camera& camera, std::size_t terms, prt::LightingMode mode,
                    double exposure, int max_frames, const std::string& screenshot,
                    bool exact);  // view_window_main.cpp
int RunGlossyWindow(prt::GlossySession& session,
                    const std::shared_ptr<const prt::EnvironmentLookup>& env,
                    const prt::Camera& camera, double exposure, int max_frames,
                    const std::string& screenshot, bool exact_cosine);  // view_window_main.cpp
#endif

namespace {

constexpr int kExitUsage = 1;
constexpr int kExitInput = 2;

double Seconds(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// The environment, read once: the lighting is resampled from it, and the frames' background
// shows it at its own resolution (environment_background.h), shared rather than copied.
std::shared_ptr<const prt::EnvironmentLookup> LoadEnvironment(const std::string& path) {
  return std::make_shared<const prt::EnvironmentLookup>(prt::ReadEnvironment(path), path);
}

struct Options {
  std::string pack, env, out, exr, out_dir, radiance_out, camera, lighting = "pbi", clusters_out;
  std::size_t terms = 100;
  bool exact = false, window = false, quiet = false;
  // The exact diffuse cosine is the default: the paper's one sample per block (Inger et al.
  // Appendix A) caps images near 28 dB (docs/glossy-accuracy.md); --paper-cosine restores it.
  bool glossy = false, reference = false, exact_cosine = true, paper_cosine = false;
  int width = 0, height = 0, frames = 0, hold = 0, window_frames = 0;
  std::string screenshot;
  double exposure = 1.0, rotate = 0.0;
};

// A pack with visibility through the triple-product renderer (docs/viewer.md, "Glossy assets").
int RunGlossy(const Options& o, const prt::pack::PackReader& reader,
              std::chrono::steady_clock::time_point t_open) {
  if (o.frames > 0 || o.hold > 0)
    throw std::invalid_argument("--frames/--hold: not available for glossy assets");
  const auto session = prt::GlossySession::FromReader(reader, o.pack);
  prt::Camera camera = session->camera();
  if (!o.camera.empty()) camera = prt::ParseCameraSpec(o.camera, camera);
  if (o.width > 0) camera.width = o.width;
  if (o.height > 0) camera.height = o.height;
  const auto lookup = LoadEnvironment(o.env);
  const prt::EnvironmentImage& env = lookup->image();
  const int n = session->cubemap_n();
  if (!o.quiet)
    std::printf(
        "%s: %zu vertices, glossy (visibility n = %d, %d bit(s)), %zu meshes, opened in "
        "%.2f s\n",
        o.pack.c_str(), session->sample_count(), n, session->visibility().bits,
        session->mesh_count(), Seconds(t_open));
  if (o.window) {
#ifdef PRT_VIEW_HAS_SDL2
    return RunGlossyWindow(*session, lookup, camera, o.exposure, o.window_frames, o.screenshot,
                           o.exact_cosine);
#else
    throw std::invalid_argument("--window: prt-view was built without SDL2");
#endif
  }
  if (o.out.empty() && o.exr.empty() && o.radiance_out.empty())
    throw std::invalid_argument("nothing to write: give --out, --exr or --radiance-out");
  const prt::CubemapRgb cube = prt::ResampleToCubemap(env, n);
  const auto t_light = std::chrono::steady_clock::now();
  const prt::BlockLighting light = session->Lighting(cube);
  const double light_s = Seconds(t_light);
  std::vector<float> rgb(3 * session->sample_count());
  const auto t_relight = std::chrono::steady_clock::now();
  prt::TripleProductStats st;
  if (o.reference) {
    session->RelightReference(light, camera.eye, rgb);
  } else {
    st = session->Relight(light, camera.eye, rgb, {.exact_cosine = o.exact_cosine});
  }
  const double relight_s = Seconds(t_relight);
  if (!o.radiance_out.empty())
    prt::WriteNpyFloat32(o.radiance_out, rgb, session->sample_count(), 3);
  const auto t_raster = std::chrono::steady_clock::now();
  const prt::ImageRgb image = session->Render(camera, rgb, prt::EnvironmentBackground(lookup));
  const double raster_s = Seconds(t_raster);
  const prt::ToneMapOptions tone{o.exposure, prt::ToneMap::kClamp};
  if (!o.out.empty()) prt::WritePng(image, o.out, tone);
  if (!o.exr.empty()) prt::WriteExr(image, o.exr);
  if (!o.quiet) {
    std::printf("%s: lighting blocks in %.2f ms, relit in %.2f ms, rasterised %dx%d in %.2f ms\n",
                o.reference ? "pixel-basis reference" : "triple products (Algorithm 1)",
                1e3 * light_s, 1e3 * relight_s, image.width, image.height, 1e3 * raster_s);
    if (!o.reference) {
      const double nz = double(st.blocks_line6 + st.blocks_line9 + st.blocks_line11);
      const double all = nz + double(st.blocks_zero);
      std::printf(
          "blocks: %.1f%% zero, %.1f%% all-one, %.1f%% mixed+constant BRDF, %.1f%% mixed "
          "(pixel basis); BRDF samples 1/4/16/256: %.1f/%.1f/%.1f/%.1f%%\n",
          100 * double(st.blocks_zero) / all, 100 * double(st.blocks_line6) / all,
          100 * double(st.blocks_line9) / all, 100 * double(st.blocks_line11) / all,
          100 * double(st.brdf_rate[0]) / nz, 100 * double(st.brdf_rate[1]) / nz,
          100 * double(st.brdf_rate[2]) / nz, 100 * double(st.brdf_rate[3]) / nz);
    }
  }
  return 0;
}

int Run(const Options& o) {
  // The pack is opened (and its sections indexed and checked) once, for either renderer.
  const auto t_open = std::chrono::steady_clock::now();
  std::unique_ptr<prt::ViewerSession> session;
  {
    const prt::pack::PackReader reader = prt::pack::PackReader::OpenFile(o.pack);
    // Glossy when asked, or when the pack has visibility but no transport.
    if (o.glossy || (!reader.has_transport() && !reader.has_cpca() && reader.has_visibility()))
      return RunGlossy(o, reader, t_open);
    if (o.reference || o.paper_cosine)
      throw std::invalid_argument("--reference/--paper-cosine apply to glossy assets only");
    session = prt::ViewerSession::FromReader(reader, o.pack);
  }
  if (session->image() != nullptr && (!o.camera.empty() || o.width > 0 || o.height > 0))
    throw std::invalid_argument(
        "--camera/--width/--height: " + o.pack +
        " is an image pack (its rows are the pixels of a fixed camera, docs/image-relighting.md)");
  prt::Camera camera = session->camera();
  if (!o.camera.empty()) camera = prt::ParseCameraSpec(o.camera, camera);
  if (o.width > 0) camera.width = o.width;
  if (o.height > 0) camera.height = o.height;
  const auto lookup = LoadEnvironment(o.env);
  const prt::EnvironmentImage& env = lookup->image();
  const int n = session->cubemap_n();
  const prt::ToneMapOptions tone{o.exposure, prt::ToneMap::kClamp};
  const prt::LightingMode mode = prt::ParseLightingMode(o.lighting);
  if (!o.quiet)
    std::printf("%s: %zu samples, n = %d, %zu transport terms (%s), opened in %.2f s\n",
                o.pack.c_str(), session->sample_count(), n, session->transport_terms(),
                prt::ToString(session->transport_header().scheme), Seconds(t_open));

  if (o.window) {
#ifdef PRT_VIEW_HAS_SDL2
    return RunViewerWindow(*session, lookup, camera, o.terms, mode, o.exposure, o.window_frames,
                           o.screenshot, o.exact);
#else
    throw std::invalid_argument("--window: prt-view was built without SDL2");
#endif
  }

  if (o.frames > 0 || o.hold > 0) {
    if (o.out_dir.empty()) throw std::invalid_argument("--frames/--hold need --out-dir");
    std::filesystem::create_directories(o.out_dir);
    prt::RotationOptions ro;
    ro.degrees_per_frame = o.rotate;
    ro.rotate_frames = o.frames;
    ro.hold_frames = o.hold;
    ro.terms = o.terms;
    const int index =
        mode == prt::LightingMode::kNwa ? 0 : (mode == prt::LightingMode::kBi ? 1 : 2);
    const auto t0 = std::chrono::steady_clock::now();
    const auto frames = prt::RunRotation(*session, env, ro, [&](const prt::RotationFrameView& v) {
      // The background rotates with the lighting of the frame (v.rotation_y).
      const prt::ImageRgb img =
          session->Render(camera, v.approx_rgb[static_cast<std::size_t>(index)],
                          prt::EnvironmentBackground(lookup, v.rotation_y));
      char name[64];
      std::snprintf(name, sizeof name, "frame_%04d.png", v.errors.frame);
      prt::WritePng(img, (std::filesystem::path(o.out_dir) / name).string(), tone);
    });
    const std::string csv = (std::filesystem::path(o.out_dir) / "rotation_errors.csv").string();
    const std::string png = (std::filesystem::path(o.out_dir) / "rotation_errors.png").string();
    prt::WriteRotationCsv(frames, o.terms, csv);
    const bool plotted = prt::PlotRotationErrors(csv, png, ro);
    if (!plotted) std::fprintf(stderr, "warning: gnuplot not available or failed; no plot\n");
    double mean[3] = {0, 0, 0};
    for (const auto& f : frames)
      for (int k = 0; k < 3; ++k) mean[k] += f.image_error[static_cast<std::size_t>(k)];
    if (!o.quiet) {
      std::printf(
          "%zu frames (%s frames written) in %.2f s; mean image error NWA %.4g, BI %.4g, "
          "PBI %.4g at %zu terms\n",
          frames.size(), o.lighting.c_str(), Seconds(t0), mean[0] / double(frames.size()),
          mean[1] / double(frames.size()), mean[2] / double(frames.size()), o.terms);
      std::printf("PBI reaches relative RMS < 1e-3 %d frames after the rotation stops\n",
                  prt::FramesToConverge(frames, ro, 2, 1e-3));
      std::printf("wrote %s%s\n", csv.c_str(), plotted ? (" and " + png).c_str() : "");
    }
    if (o.out.empty()) return 0;
  }

  if (!o.clusters_out.empty()) {
    // Overbeck et al. 2006 Figure 12: every vertex in its cluster's colour.
    if (!session->cpca())
      throw std::invalid_argument("--clusters-out: " + o.pack + " holds no CPCA transport");
    if (session->image())
      throw std::invalid_argument("--clusters-out: " + o.pack + " is an image pack");
    const prt::ImageRgb clusters =
        session->Render(camera, prt::ClusterColours(*session->cpca()), nullptr);
    prt::WritePng(clusters, o.clusters_out, prt::ToneMapOptions{1.0, prt::ToneMap::kClamp});
    if (!o.quiet)
      std::printf("wrote %s: %u clusters of %u bases\n", o.clusters_out.c_str(),
                  session->cpca()->clusters(), session->cpca()->bases());
    if (o.out.empty() && o.exr.empty() && o.radiance_out.empty()) return 0;
  }
  if (o.out.empty() && o.exr.empty() && o.radiance_out.empty())
    throw std::invalid_argument(
        "nothing to write: give --out, --exr, --radiance-out, --clusters-out or --frames");
  const prt::CubemapRgb cube = prt::ResampleToCubemap(env, n);
  const prt::WaveletLighting lighting = prt::ProjectLighting(cube);
  const auto t_relight = std::chrono::steady_clock::now();
  const prt::SampleRadiance radiance =
      o.exact ? session->RelightExact(lighting)
              : prt::RelightApproximate(session->transport(), lighting, mode, o.terms);
  const double relight_s = Seconds(t_relight);
  const std::vector<float> rgb = session->Shade(radiance, camera.eye);
  if (!o.radiance_out.empty())  // the session's order → the pack's (viewer_session.h)
    prt::WriteNpyFloat32(o.radiance_out, session->ToPackOrder(rgb), session->sample_count(), 3);
  const auto t_raster = std::chrono::steady_clock::now();
  const prt::ImageRgb image = session->Render(camera, rgb, prt::EnvironmentBackground(lookup));
  const double raster_s = Seconds(t_raster);
  if (!o.out.empty()) prt::WritePng(image, o.out, tone);
  if (!o.exr.empty()) prt::WriteExr(image, o.exr);
  if (!o.quiet)
    std::printf("%s lighting%s: relit in %.2f ms, rasterised %dx%d in %.2f ms\n",
                o.exact ? "exact" : o.lighting.c_str(),
                o.exact ? "" : (" (" + std::to_string(o.terms) + " terms)").c_str(),
                1e3 * relight_s, image.width, image.height, 1e3 * raster_s);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"prt-view: relight a .prtpack under an environment map (docs/viewer.md)"};
  app.set_version_flag("--version", std::string("prt-view ") + PRT_VERSION);
  Options o;
  app.add_option("pack", o.pack, "scene.prtpack")->required();
  app.add_option("--env", o.env, "environment map (.exr lat-long or cube, .hdr)")->required();
  app.add_option("--out", o.out, "output PNG (8-bit sRGB)");
  app.add_option("--exr", o.exr, "output linear float OpenEXR");
  auto* terms = app.add_option("--terms", o.terms, "lighting terms per frame (default 100)")
                    ->check(CLI::Range(std::size_t{1}, std::size_t{1} << 24));
  app.add_flag("--exact", o.exact, "every lighting coefficient (no approximation)")
      ->excludes(terms);
  app.add_option("--lighting", o.lighting, "nwa | bi | pbi (default pbi)")
      ->check(CLI::IsMember({"nwa", "bi", "pbi"}));
  app.add_option("--camera", o.camera,
                 "eye_x,eye_y,eye_z,target_x,target_y,target_z[,up_x,up_y,up_z[,fov]]");
  app.add_option("--width", o.width, "image width (default: the scene's camera)")
      ->check(CLI::Range(1, 16384));
  app.add_option("--height", o.height, "image height (default: the scene's camera)")
      ->check(CLI::Range(1, 16384));
  app.add_option("--exposure", o.exposure, "linear exposure multiplier (default 1)")
      ->check(CLI::PositiveNumber);
  app.add_option("--clusters-out", o.clusters_out,
                 "CPCA pack: PNG of the clusters colour-coded on the mesh (docs/cpca.md)");
  app.add_option("--radiance-out", o.radiance_out,
                 "shaded radiance per sample, float32 samples×3 .npy");
  app.add_option("--rotate", o.rotate, "environment rotation about +Y, degrees per frame");
  app.add_option("--frames", o.frames, "rotating frames K")->check(CLI::Range(0, 100000));
  app.add_option("--hold", o.hold, "still frames S after the rotation")
      ->check(CLI::Range(0, 100000));
  app.add_option("--out-dir", o.out_dir, "folder for frames, CSV and plot");
  app.add_flag("--window", o.window, "interactive SDL2 window");
  app.add_option("--window-frames", o.window_frames,
                 "--window: close after this many frames (0: run until closed)")
      ->check(CLI::Range(0, 1000000));
  app.add_option(
      "--screenshot", o.screenshot,
      "--window: the last frame as the window shows it: PNG, or .npy of its 8-bit codes");
  app.add_flag("--glossy", o.glossy,
               "render the pack's visibility with per-block triple products and the scene's "
               "materials (default for a pack with visibility and no transport)");
  app.add_flag("--reference", o.reference,
               "glossy: the pixel-basis reference over all 6n^2 texels instead of Algorithm 1");
  app.add_flag("--paper-cosine", o.paper_cosine,
               "glossy: the paper's diffuse term (one cosine sample per block, Appendix A) "
               "instead of the exact cosine integral (TripleProductOptions::exact_cosine)");
  app.add_flag("--quiet", o.quiet, "no progress output");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);
    return rc == 0 ? 0 : kExitUsage;
  }
  if (o.paper_cosine) o.exact_cosine = false;
  try {
    if (!std::isfinite(o.rotate)) throw std::invalid_argument("--rotate must be finite");
    if (!std::isfinite(o.exposure))  // CLI::PositiveNumber lets NaN and Inf through
      throw std::invalid_argument("--exposure must be a finite positive number");
    return Run(o);
  } catch (const std::invalid_argument& e) {
    std::fprintf(stderr, "prt-view: %s\n", e.what());
    return kExitUsage;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "prt-view: %s\n", e.what());
    return kExitInput;
  }
}
