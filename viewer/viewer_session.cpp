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
#include "viewer/camera_metadata.h"
#include "viewer/per_band_incremental.h"
#include "viewer/rasterizer.h"
#include "vocabulary/cubemap_resample.h"
#include "vocabulary/errors.h"

namespace prt {

LightingMode ParseLightingMode(const std::string& s) {
  if (s == "nwa") return LightingMode::kNwa;
  if (s == "bi") return LightingMode::kBi;
  if (s == "pbi") return LightingMode::kPbi;
  throw std::invalid_argument("unknown lighting mode '" + s + "' (nwa, bi or pbi)");
}

const char* ToString(LightingMode mode) {
  switch (mode) {
    case LightingMode::kNwa:
      return "nwa";
    case LightingMode::kBi:
      return "bi";
    case LightingMode::kPbi:
      return "pbi";
  }
  return "?";
}

std::unique_ptr<ViewerSession> ViewerSession::Open(const std::string& pack_path) {
  return FromReader(pack::PackReader::OpenFile(pack_path), pack_path);
}

std::unique_ptr<ViewerSession> ViewerSession::FromReader(const pack::PackReader& reader,
                                                         const std::string& pack_path) {
  std::unique_ptr<ViewerSession> s(new ViewerSession());
  s->path_ = pack_path;
  if (!reader.has_transport() && !reader.has_cpca())
    throw InputError(pack_path,
                     "the pack has no transport (TRNS or CPCA) section; nothing to relight");
  s->camera_from_metadata_ = CameraFromMetadata(reader.ReadMetadata(), pack_path, s->camera_);

  if (reader.has_image()) {
    // Image relighting: the samples are the pixels, each with its mesh's albedo.
    s->image_ = reader.ReadImage();
    s->camera_ = s->image_->camera;
    s->camera_from_metadata_ = true;
    std::vector<Rgb> mesh_albedo;
    for (std::size_t m = 0; m < reader.mesh_count(); ++m)
      mesh_albedo.push_back(reader.ReadMaterial(m).albedo);
    s->albedo_ = PixelAlbedo(*s->image_, mesh_albedo);
  }
  std::size_t offset = 0;
  for (std::size_t m = 0; !s->image_ && m < reader.mesh_count(); ++m) {
    const pack::UnpackedMesh mesh = reader.ReadMesh(m);
    const std::size_t nv = mesh.vertex_count();
    for (std::size_t v = 0; v < nv; ++v) {
      s->positions_.push_back(
          {mesh.positions[3 * v], mesh.positions[3 * v + 1], mesh.positions[3 * v + 2]});
      s->albedo_.push_back(mesh.albedo);
    }
    for (std::size_t t = 0; t < mesh.triangle_count(); ++t)
      s->triangles_.push_back({static_cast<uint32_t>(offset + mesh.triangles[3 * t]),
                               static_cast<uint32_t>(offset + mesh.triangles[3 * t + 1]),
                               static_cast<uint32_t>(offset + mesh.triangles[3 * t + 2])});
    offset += nv;
  }
  if (reader.has_cpca()) {
    s->cpca_transport_ = std::make_unique<CpcaTransport>(pack::ReadCpcaTransport(reader));
  } else {
    s->compressed_ = std::make_unique<CompressedTransport>(pack::ReadCompressedTransport(reader));
  }
  const CompressedTransportHeader& h =
      s->cpca_transport_ ? s->cpca_transport_->header : s->compressed_->header;
  // channels × V rows, channel-major (formats/compressed_transport.h).
  if (static_cast<uint64_t>(h.sample_count) != uint64_t{h.channels} * s->albedo_.size())
    throw InputError(pack_path, "the transport has " + std::to_string(h.sample_count) + " rows (" +
                                    std::to_string(h.channels) + " colour channel(s) × " +
                                    std::to_string(h.spatial_count()) + " samples) but the " +
                                    (s->image_ ? "image has " : "meshes have ") +
                                    std::to_string(s->albedo_.size()) +
                                    (s->image_ ? " pixels" : " vertices"));
  if (h.row_wavelet != RowWavelet::kHaar)
    throw InputError(pack_path, std::string("the transport's row wavelet is ") +
                                    ToString(h.row_wavelet) +
                                    "; the viewer's lighting basis is Haar");
  if (s->cpca_transport_) {
    // CPCA (docs/cpca.md): rows in the pack's order, relit by Eq. 7–8.
    s->transport_terms_ =
        s->cpca_transport_->term_count() + s->cpca_transport_->coefficients.size();
    s->cpca_relighter_ = std::make_unique<CpcaRelighter>(*s->cpca_transport_, pack_path);
    s->transport_op_ = s->cpca_relighter_.get();
    s->pack_sample_.resize(s->albedo_.size());
    for (std::size_t v = 0; v < s->pack_sample_.size(); ++v)
      s->pack_sample_[v] = static_cast<uint32_t>(v);
    return s;
  }
  s->transport_terms_ = s->compressed_->term_count();
  s->relighter_ = std::make_unique<CompressedRelighter>(*s->compressed_, pack_path);
  s->operator_ =
      std::make_unique<CompressedTransportOperator>(*s->relighter_, SampleOrder::kCoefficients);
  s->transport_op_ = s->operator_.get();
  // The session's order (viewer_session.h): position p holds the pack sample whose coefficient
  // is p. The per-sample arrays move to it once, and the triangles follow their vertices.
  const std::span<const uint32_t> coefficient = s->relighter_->coefficient_of_sample();
  const std::size_t ns = s->albedo_.size();
  s->pack_sample_.resize(ns);
  for (std::size_t v = 0; v < ns; ++v) s->pack_sample_[coefficient[v]] = static_cast<uint32_t>(v);
  const auto to_session = [&](auto& values) {
    const auto pack_order = std::move(values);
    values.resize(ns);
    for (std::size_t p = 0; p < ns; ++p) values[p] = pack_order[s->pack_sample_[p]];
  };
  to_session(s->albedo_);
  if (!s->image_) to_session(s->positions_);
  for (auto& t : s->triangles_)
    for (uint32_t& v : t) v = coefficient[v];
  return s;
}

std::vector<float> ViewerSession::ToPackOrder(std::span<const float> values, std::size_t k) const {
  const std::size_t ns = pack_sample_.size();
  if (k == 0 || values.size() != k * ns)
    throw std::invalid_argument("ViewerSession::ToPackOrder: " + std::to_string(values.size()) +
                                " values for " + std::to_string(ns) + " samples × " +
                                std::to_string(k));
  std::vector<float> out(values.size());
  for (std::size_t p = 0; p < ns; ++p)
    std::copy_n(values.data() + k * p, k, out.data() + k * pack_sample_[p]);
  return out;
}

ViewerSession::~ViewerSession() = default;

const CompressedTransportHeader& ViewerSession::transport_header() const {
  return cpca_transport_ ? cpca_transport_->header : compressed_->header;
}

const CompressedRelighter& ViewerSession::relighter() const {
  if (!relighter_)
    throw std::logic_error(path_ + " holds a CPCA transport: it has no column relighter");
  return *relighter_;
}

SampleRadiance ViewerSession::RelightExact(const WaveletLighting& lighting) const {
  if (cpca_relighter_) {
    if (lighting.size() != cpca_relighter_->coefficient_count())
      throw std::invalid_argument("RelightExact: lighting has " + std::to_string(lighting.size()) +
                                  " coefficients, the transport " +
                                  std::to_string(cpca_relighter_->coefficient_count()));
    for (int c = 0; c < 3; ++c)
      for (std::size_t j = 0; j < lighting.size(); ++j)
        CheckFloatLighting(lighting.coefficient[c][j], j, c, path_);
    return cpca_relighter_->Apply(ExactLightingTerms(lighting));
  }
  const std::size_t cols = relighter_->column_count();
  if (lighting.size() != cols)
    throw std::invalid_argument("RelightExact: lighting has " + std::to_string(lighting.size()) +
                                " coefficients, the transport " + std::to_string(cols));
  std::vector<float> l(3 * cols);
  for (int c = 0; c < 3; ++c)
    for (std::size_t j = 0; j < cols; ++j) {
      const double v = lighting.coefficient[c][j];
      CheckFloatLighting(v, j, c, path_);  // the relighter's lighting is float
      l[c * cols + j] = static_cast<float>(v);
    }
  const std::size_t ns = sample_count();
  std::vector<float> b(3 * ns);
  // Finite: the relighter throws NumericalError naming the pack and the sample when its float
  // accumulation overflows (compressed_relight.h), and its inputs are finite floats.
  relighter_->Relight(l, 3, b, SampleOrder::kCoefficients);
  SampleRadiance out(ns);
  for (int c = 0; c < 3; ++c)
    for (std::size_t s = 0; s < ns; ++s) out.channel[c][s] = b[c * ns + s];
  return out;
}

std::vector<float> ViewerSession::Shade(const SampleRadiance& radiance) const {
  return ShadeSamples(radiance, albedo_, path_, pack_sample_);
}

ImageRgb ViewerSession::Render(const Camera& camera, std::span<const float> sample_rgb,
                               const CubemapRgb* background) const {
  return Render(camera, sample_rgb,
                background != nullptr ? CubemapBackground(*background) : BackgroundFunction{});
}

ImageRgb ViewerSession::Render(const Camera& camera, std::span<const float> sample_rgb,
                               const BackgroundFunction& background) const {
  if (image_) {
    const Camera& k = image_->camera;
    if (camera.width != k.width || camera.height != k.height || !(camera.eye == k.eye) ||
        !(camera.target == k.target) || !(camera.up == k.up) || camera.fov_deg != k.fov_deg)
      throw std::invalid_argument("ViewerSession::Render: an image pack's view is fixed (" + path_ +
                                  ")");
    return RenderImage(sample_rgb, background);
  }
  RasterOptions options;
  options.background = background;
  RasterImage r = RasterizeTriangles(camera, positions_, triangles_, sample_rgb, options);
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
  const Camera& k = image_->camera;
  const CameraProjection cam(k);
  ImageRgb image(k.width, k.height);
  const std::span<const uint32_t> coefficient = relighter_->coefficient_of_sample();
  tbb::parallel_for(0, k.height, [&](int y) {
    for (int x = 0; x < k.width; ++x) {
      const std::size_t p = static_cast<std::size_t>(y) * k.width + x;
      float* out = image.pixels.data() + 3 * p;
      if (image_->pixel_mesh[p] == kImageBackground) {
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

double RelativeRmsError(std::span<const float> b, std::span<const float> ref) {
  if (b.size() != ref.size()) throw std::invalid_argument("RelativeRmsError: sizes differ");
  double num = 0, den = 0;
  for (std::size_t i = 0; i < b.size(); ++i) {
    const double d = static_cast<double>(b[i]) - ref[i];
    num += d * d;
    den += static_cast<double>(ref[i]) * ref[i];
  }
  if (den == 0) return num == 0 ? 0.0 : 1.0;
  return std::sqrt(num / den);
}

SampleRadiance RelightApproximate(const TransportOperator& transport, const WaveletLighting& l,
                                  LightingMode mode, std::size_t terms) {
  switch (mode) {
    case LightingMode::kNwa:
      return transport.Apply(NonlinearLightingApproximation(l, HaarLightingBasis(l.n), terms));
    case LightingMode::kBi: {
      BasicIncrementalRelighter r(transport, l.n, terms);
      r.Clear();
      r.Update(l);
      return r.Radiance();
    }
    case LightingMode::kPbi: {
      PerBandIncrementalRelighter r(transport, l.n, terms);
      r.Clear();
      r.Update(l);
      return r.Radiance();
    }
  }
  return {};
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
