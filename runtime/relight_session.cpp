#include "runtime/relight_session.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <utility>

#include "packager/prtpack_reader.h"
#include "packager/prtpack_transport.h"
#include "runtime/camera_metadata.h"
#include "runtime/per_band_incremental.h"
#include "vocabulary/errors.h"
#include "vocabulary/parallel.h"

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

std::unique_ptr<RelightSession> RelightSession::Open(const std::string& pack_path) {
  return FromReader(pack::PackReader::OpenFile(pack_path), pack_path);
}

std::unique_ptr<RelightSession> RelightSession::FromReader(const pack::PackReader& reader,
                                                           const std::string& pack_path) {
  std::unique_ptr<RelightSession> s(new RelightSession());
  s->Load(reader, pack_path);
  return s;
}

void RelightSession::Load(const pack::PackReader& reader, const std::string& pack_path,
                          const SceneTomlCameraFn& scene_toml_camera) {
  RelightSession* s = this;
  s->path_ = pack_path;
  if (!reader.has_transport() && !reader.has_cpca())
    throw InputError(pack_path,
                     "the pack has no transport (TRNS or CPCA) section; nothing to relight");
  s->camera_from_metadata_ =
      CameraFromMetadata(reader.ReadMetadata(), pack_path, s->camera_, scene_toml_camera);

  if (reader.has_image()) {
    // Image relighting: the samples are the pixels, each with its mesh's albedo (a glossy
    // pixel: its weight, docs/image-relighting.md "Glossy pixels").
    s->image_ = reader.ReadImage();
    s->camera_ = s->image_->camera;
    s->camera_from_metadata_ = true;
    std::vector<Rgb> mesh_albedo;
    for (std::size_t m = 0; m < reader.mesh_count(); ++m)
      mesh_albedo.push_back(reader.ReadMaterial(m).albedo);
    s->albedo_ = PixelAlbedo(*s->image_, mesh_albedo);
  }
  // Glossy vertex packs: each vertex's factors, frame and weight w (docs/glossy-transport.md).
  if (reader.has_glossy()) s->glossy_ = reader.ReadGlossy();
  std::size_t offset = 0;
  for (std::size_t m = 0; !s->image_ && m < reader.mesh_count(); ++m) {
    const pack::UnpackedMesh mesh = reader.ReadMesh(m);
    const std::size_t nv = mesh.vertex_count();
    for (std::size_t v = 0; v < nv; ++v) {
      s->positions_.push_back(
          {mesh.positions[3 * v], mesh.positions[3 * v + 1], mesh.positions[3 * v + 2]});
      s->albedo_.push_back(s->glossy_ ? s->glossy_->mesh_weight[m] : mesh.albedo);
      if (s->glossy_) {
        s->sample_factor_.push_back(s->glossy_->mesh_factor[m]);
        s->frames_.push_back(MakeFactorFrame(
            {mesh.normals[3 * v], mesh.normals[3 * v + 1], mesh.normals[3 * v + 2]}));
      }
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
  // channels × V rows, channel-major (formats/compressed_transport.h); a glossy pack's terms
  // × V (one channel).
  if (s->glossy_ && h.channels != 1)
    throw InputError(pack_path, "a glossy pack's transport has " + std::to_string(h.channels) +
                                    " colour channels (terms need one)");
  if (static_cast<uint64_t>(h.sample_count) !=
      uint64_t{h.channels} * s->terms() * s->albedo_.size())
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
    s->session_position_ = s->pack_sample_;
    return;
  }
  s->transport_terms_ = s->compressed_->term_count();
  s->relighter_ = std::make_unique<CompressedRelighter>(*s->compressed_, pack_path);
  s->compressed_.reset();  // the relighter holds its own (dequantised) copy of every term
  s->operator_ =
      std::make_unique<CompressedTransportOperator>(*s->relighter_, SampleOrder::kCoefficients);
  s->transport_op_ = s->operator_.get();
  // The session's order (viewer_session.h): position p holds the pack sample whose coefficient
  // is p. The per-sample arrays move to it once, and the triangles follow their vertices.
  const std::span<const uint32_t> coefficient = s->relighter_->coefficient_of_sample();
  const std::size_t ns = s->albedo_.size();
  // Every term's samples keep term 0's order (each term is its own copy of the segments).
  for (std::size_t t = 1; t < s->terms(); ++t)
    for (std::size_t v = 0; v < ns; ++v)
      if (coefficient[t * ns + v] != t * ns + coefficient[v])
        throw InputError(pack_path, "the transport's term " + std::to_string(t) +
                                        " is not laid out as its first term");
  s->pack_sample_.resize(ns);
  for (std::size_t v = 0; v < ns; ++v) s->pack_sample_[coefficient[v]] = static_cast<uint32_t>(v);
  s->session_position_.assign(coefficient.begin(), coefficient.end());
  const auto to_session = [&](auto& values) {
    const auto pack_order = std::move(values);
    values.resize(ns);
    for (std::size_t p = 0; p < ns; ++p) values[p] = pack_order[s->pack_sample_[p]];
  };
  to_session(s->albedo_);
  if (s->glossy_) {
    to_session(s->sample_factor_);
    to_session(s->frames_);
  }
  if (!s->image_) to_session(s->positions_);
  for (auto& t : s->triangles_)
    for (uint32_t& v : t) v = coefficient[v];
}

std::vector<float> RelightSession::ToPackOrder(std::span<const float> values, std::size_t k) const {
  const std::size_t ns = pack_sample_.size();
  if (k == 0 || values.size() != k * ns)
    throw std::invalid_argument("RelightSession::ToPackOrder: " + std::to_string(values.size()) +
                                " values for " + std::to_string(ns) + " samples × " +
                                std::to_string(k));
  std::vector<float> out(values.size());
  for (std::size_t p = 0; p < ns; ++p)
    std::copy_n(values.data() + k * p, k, out.data() + k * pack_sample_[p]);
  return out;
}

RelightSession::~RelightSession() = default;

std::size_t RelightSession::memory_bytes() const {
  std::size_t b = sizeof(Rgb) * albedo_.size() + sizeof(Vec3) * positions_.size() +
                  sizeof(triangles_[0]) * triangles_.size() +
                  sizeof(uint32_t) * (pack_sample_.size() + session_position_.size());
  if (relighter_) b += relighter_->memory_bytes();
  if (cpca_relighter_) b += cpca_relighter_->memory_bytes();
  return b;
}

const CompressedTransportHeader& RelightSession::transport_header() const {
  return cpca_transport_ ? cpca_transport_->header : relighter_->header();
}

const CompressedRelighter& RelightSession::relighter() const {
  if (!relighter_)
    throw std::logic_error(path_ + " holds a CPCA transport: it has no column relighter");
  return *relighter_;
}

SampleRadiance RelightSession::RelightExact(const WaveletLighting& lighting) const {
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
  const std::size_t ns = sample_count() * terms();
  std::vector<float> b(3 * ns);
  // Finite: the relighter throws NumericalError naming the pack and the sample when its float
  // accumulation overflows (compressed_relight.h), and its inputs are finite floats.
  relighter_->Relight(l, 3, b, SampleOrder::kCoefficients);
  SampleRadiance out(ns);
  for (int c = 0; c < 3; ++c)
    for (std::size_t s = 0; s < ns; ++s) out.channel[c][s] = b[c * ns + s];
  return out;
}

std::vector<float> RelightSession::Shade(const SampleRadiance& radiance) const {
  return Shade(radiance, camera_.eye);
}

std::vector<float> RelightSession::Shade(const SampleRadiance& radiance, const Vec3& eye) const {
  if (glossy_) return ShadeSamples(CombineTerms(radiance, eye), albedo_, path_, pack_sample_);
  return ShadeSamples(radiance, albedo_, path_, pack_sample_);
}

// Huang & Ramamoorthi 2010 Eq. 3: B(x, ω_o) = Σ_i g_i(ω_o) Σ_j T_i(x, ω_j) L(ω_j), the inner sums
// already in `radiance` (term-major); here the outer sum with each vertex's view in its frame.
SampleRadiance RelightSession::CombineTerms(const SampleRadiance& radiance, const Vec3& eye) const {
  const std::size_t ns = sample_count(), m = terms();
  if (radiance.size() != m * ns)
    throw std::invalid_argument("CombineTerms: " + std::to_string(radiance.size()) +
                                " samples for " + std::to_string(m) + " terms × " +
                                std::to_string(ns));
  if (!glossy_) return radiance;
  SampleRadiance out(ns);
  constexpr std::size_t kPart = 1024;
  ParallelFor((ns + kPart - 1) / kPart, [&](std::size_t part) {
    float g[16];
    for (std::size_t p = part * kPart; p < std::min(ns, (part + 1) * kPart); ++p) {
      const uint32_t f = sample_factor_[p];
      if (f == GlossyFactorTable::kDiffuseMesh) {
        for (int c = 0; c < 3; ++c) out.channel[c][p] = radiance.channel[c][p];
        continue;
      }
      glossy_->factors[f].GAll(frames_[p].ToLocal(eye - positions_[p]), g);
      for (int c = 0; c < 3; ++c) {
        double b = 0;
        for (std::size_t t = 0; t < m; ++t) b += g[t] * radiance.channel[c][t * ns + p];
        out.channel[c][p] = b;
      }
    }
  });
  return out;
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

}  // namespace prt
