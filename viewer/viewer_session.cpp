#include "viewer/viewer_session.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <stdexcept>
#include <utility>

#include "packager/prtpack_reader.h"
#include "packager/prtpack_transport.h"
#include "runtime/camera_metadata.h"
#include "runtime/per_band_incremental.h"
#include "viewer/rasterizer.h"
#include "vocabulary/cubemap_resample.h"
#include "vocabulary/errors.h"
#include "vocabulary/tbb_parallel.h"

namespace prt {

bool SceneTomlCamera(const std::string& toml, const std::string& name, Camera& camera) {
  try {
    camera = ParseScene(toml, name + ":scene.toml", "").camera;
    return true;
  } catch (const InputError&) {
    return false;
  }
}

std::unique_ptr<ViewerSession> ViewerSession::Open(const std::string& pack_path) {
  return FromReader(pack::PackReader::OpenFile(pack_path), pack_path);
}

std::unique_ptr<ViewerSession> ViewerSession::FromReader(const pack::PackReader& reader,
                                                         const std::string& pack_path) {
  UseTbbParallelism();
  std::unique_ptr<ViewerSession> s(new ViewerSession());
  s->Load(reader, pack_path, SceneTomlCamera);
  return s;
}

ImageRgb ViewerSession::Render(const Camera& camera, std::span<const float> sample_rgb,
                               const CubemapRgb* background) const {
  return Render(camera, sample_rgb,
                background != nullptr ? CubemapBackground(*background) : BackgroundFunction{});
}

ImageRgb ViewerSession::Render(const Camera& camera, std::span<const float> sample_rgb,
                               const BackgroundFunction& background) const {
  if (image()) {
    const Camera& k = this->image()->camera;
    if (camera.width != k.width || camera.height != k.height || !(camera.eye == k.eye) ||
        !(camera.target == k.target) || !(camera.up == k.up) || camera.fov_deg != k.fov_deg)
      throw std::invalid_argument("ViewerSession::Render: an image pack's view is fixed (" +
                                  path() + ")");
    return RenderImage(sample_rgb, background);
  }
  RasterOptions options;
  options.background = background;
  RasterImage r = RasterizeTriangles(camera, positions(), triangles(), sample_rgb, options);
  ImageRgb image(r.width, r.height);
  image.pixels = std::move(r.rgb);
  return image;
}

ImageRgb ViewerSession::RenderImage(std::span<const float> sample_rgb,
                                    const BackgroundFunction& background) const {
  const std::size_t ns = sample_count();
  if (sample_rgb.size() != 3 * ns)
    throw std::invalid_argument("ViewerSession::Render: " + std::to_string(sample_rgb.size()) +
                                " colour values for " + std::to_string(ns) + " pixels");
  const Camera& k = this->image()->camera;
  const CameraProjection cam(k);
  ImageRgb image(k.width, k.height);
  const std::span<const uint32_t> coefficient = relighter().coefficient_of_sample();
  const std::vector<float> share = PixelEnvironmentShare(*this->image());
  tbb::parallel_for(0, k.height, [&](int y) {
    for (int x = 0; x < k.width; ++x) {
      const std::size_t p = static_cast<std::size_t>(y) * k.width + x;
      float* out = image.pixels.data() + 3 * p;
      // A supersampled pixel partly on a surface: its shaded value (w(p)·T·L) plus its share
      // (1 − coverage) of the environment along its ray (docs/image-relighting.md).
      if (share[p] > 0.f && share[p] < 1.f) {
        const Rgb c = background ? background(cam.PixelDirection(x + 0.5, y + 0.5)) : Rgb{};
        const float* shaded = sample_rgb.data() + 3 * static_cast<std::size_t>(coefficient[p]);
        for (int i = 0; i < 3; ++i) {
          if (!std::isfinite(c[i]))
            throw NumericalError("background of pixel (" + std::to_string(x) + ", " +
                                 std::to_string(y) + ") is not finite");
          out[i] = shaded[i] + share[p] * c[i];
        }
        continue;
      }
      if (this->image()->pixel_mesh[p] == kImageBackground) {
        const Rgb c = background ? background(cam.PixelDirection(x + 0.5, y + 0.5)) : Rgb{};
        for (int i = 0; i < 3; ++i) {
          if (!std::isfinite(c[i]))
            throw NumericalError("background pixel (" + std::to_string(x) + ", " +
                                 std::to_string(y) + ") is not finite");
          out[i] = c[i];
        }
        continue;
      }
      std::copy_n(sample_rgb.data() + 3 * static_cast<std::size_t>(coefficient[p]), 3, out);
    }
  });
  return image;
}

std::vector<RotationFrame> RunRotation(
    const ViewerSession& session, const EnvironmentImage& env, const RotationOptions& options,
    const std::function<void(const RotationFrameView&)>& on_frame) {
  if (options.rotate_frames < 0 || options.hold_frames < 0 || options.terms == 0 ||
      !std::isfinite(options.degrees_per_frame))
    throw std::invalid_argument("RunRotation: frames ≥ 0, terms ≥ 1, finite rotation");
  const int n = session.cubemap_n();
  const TransportOperator& t = session.transport();
  const HaarLightingBasis basis(n);
  BasicIncrementalRelighter bi(t, n, options.terms);
  PerBandIncrementalRelighter pbi(t, n, options.terms);
  // A CPCA pack: the PBI column is Overbeck §6.3's fully incremental CPCA (PBI on the lighting,
  // Eq. 10 with S/4 basis terms per cluster).
  std::unique_ptr<CpcaIncrementalRelighter> cpca_pbi;
  if (session.cpca())
    cpca_pbi = std::make_unique<CpcaIncrementalRelighter>(*session.cpca(), n, options.terms);
  std::vector<RotationFrame> frames;
  CubemapRgb cube;
  WaveletLighting lighting;
  double last_angle = std::nan("");
  const int total = options.rotate_frames + options.hold_frames;
  for (int f = 0; f <= total; ++f) {
    const double angle_deg = std::min(f, options.rotate_frames) * options.degrees_per_frame;
    const double rotation_y = angle_deg * 3.14159265358979323846 / 180.0;
    if (!(angle_deg == last_angle)) {
      cube = ResampleToCubemap(env, n, rotation_y);
      lighting = ProjectLighting(cube);
      last_angle = angle_deg;
    }
    const std::vector<float> exact = session.Shade(session.RelightExact(lighting));
    const std::vector<LightingTerm> nwa_terms =
        NonlinearLightingApproximation(lighting, basis, options.terms);
    const std::vector<float> nwa = session.Shade(t.Apply(nwa_terms));
    RotationFrame r;
    if (f == 0) {
      bi.Initialize(lighting);
      if (cpca_pbi)
        cpca_pbi->Initialize(lighting);
      else
        pbi.Initialize(lighting);
    } else {
      bi.Update(lighting);
      for (uint8_t reset :
           (cpca_pbi ? cpca_pbi->Update(lighting) : pbi.Update(lighting)).band_reset)
        r.pbi_reset_bands += reset ? '1' : '0';
    }
    const std::vector<float> bi_rgb = session.Shade(bi.Radiance());
    const std::vector<float> pbi_rgb =
        session.Shade(cpca_pbi ? cpca_pbi->Radiance() : pbi.Radiance());
    r.frame = f;
    r.angle_deg = angle_deg;
    r.lighting_error = {
        RelativeLightingError(lighting, nwa_terms),
        RelativeLightingError(lighting, ExactLightingTerms(bi.Represented())),
        RelativeLightingError(
            lighting, ExactLightingTerms(cpca_pbi ? cpca_pbi->Represented() : pbi.Represented()))};
    r.image_error = {RelativeRmsError(nwa, exact), RelativeRmsError(bi_rgb, exact),
                     RelativeRmsError(pbi_rgb, exact)};
    frames.push_back(r);
    if (on_frame)
      on_frame(RotationFrameView{frames.back(), cube, rotation_y, exact, {nwa, bi_rgb, pbi_rgb}});
  }
  return frames;
}

void WriteRotationCsv(const std::vector<RotationFrame>& frames, std::size_t terms,
                      const std::string& path) {
  std::ofstream out(path);
  if (!out) throw InputError(path, "cannot be written");
  out << "# terms per frame: " << terms << "; errors relative to exact lighting\n";
  out << "frame,angle_deg,lighting_error_nwa,lighting_error_bi,lighting_error_pbi,"
         "image_error_nwa,image_error_bi,image_error_pbi,pbi_reset_bands\n";
  char line[512];
  for (const RotationFrame& f : frames) {
    std::snprintf(line, sizeof line, "%d,%.6f,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,", f.frame, f.angle_deg,
                  f.lighting_error[0], f.lighting_error[1], f.lighting_error[2], f.image_error[0],
                  f.image_error[1], f.image_error[2]);
    out << line << f.pbi_reset_bands << '\n';
  }
  if (!out) throw InputError(path, "write failed");
}

int FramesToConverge(const std::vector<RotationFrame>& frames, const RotationOptions& options,
                     int index, double threshold) {
  for (const RotationFrame& f : frames)
    if (f.frame > options.rotate_frames &&
        f.image_error[static_cast<std::size_t>(index)] < threshold)
      return f.frame - options.rotate_frames;
  return -1;
}

}  // namespace prt
