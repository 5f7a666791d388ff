// A .prtpack opened for relighting: what the runtime's C API (runtime/prt_runtime.h), prt-view
// (viewer/viewer_session.h adds rasterising) and the benchmarks share: meshes, per-sample albedo,
// the scene's camera, the compressed transport behind a TransportOperator, shading
// B = albedo ⊙ (T·L̂).
//
// Relighting runs straight from the pack's adaptively compressed columns (Cheslack-Postava et
// al. 2008 §4.5, Eq. 8) through CompressedRelighter; the pack's transport is never decompressed
// to a dense matrix. "Exact" lighting means every non-zero Haar coefficient of L through that
// same compressed T, so the lighting and image errors reported here measure the lighting
// approximation alone. A pack whose transport is clustered PCA (a CPCA section, docs/cpca.md)
// relights through CpcaRelighter (Overbeck et al. 2006 §6.3) instead, in the pack's order.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "formats/glossy_factors.h"
#include "formats/image_file.h"
#include "runtime/camera_metadata.h"
#include "runtime/compressed_relight.h"
#include "runtime/cpca_relight.h"
#include "runtime/lighting.h"
#include "runtime/relight.h"
#include "vocabulary/scene.h"
#include "vocabulary/vec3.h"

namespace prt {

namespace pack {
class PackReader;
}  // namespace pack

enum class LightingMode { kNwa, kBi, kPbi };
// "nwa" | "bi" | "pbi" (throws std::invalid_argument otherwise), and back.
LightingMode ParseLightingMode(const std::string& s);
const char* ToString(LightingMode mode);

// A pack opened for relighting. Not copyable or movable (the operator refers to the relighter).
//
// Sample order. Everything the session computes per spatial sample — the SampleRadiance of
// transport(), RelightExact and the incremental relighters built on transport(), Shade's
// colours, Render's input — is in the session's order: the compressed transport's depth-0
// coefficient layout (SampleOrder::kCoefficients of runtime/compressed_relight.h; each mesh
// along its Hilbert order), the order the Eq. 8 inverse steps leave the frame in, so a frame
// needs no gather through the permutation (a CPCA pack: the pack's order, pack_sample() the
// identity). The per-sample arrays albedo() and positions() are
// moved to that order once at Open, and triangles() index them there. pack_sample(p) names the
// pack sample at position p; ToPackOrder turns per-sample values back into the pack's order
// (meshes in pack order, each mesh's vertices in order), as --radiance-out writes them.
class RelightSession {
 public:
  // Reads meshes, materials, metadata and the whole compressed transport. Throws
  // prt::InputError naming the file on: an unreadable or corrupt pack (PackReader's errors), no
  // transport, a transport whose row count differs from its channel count (1 or 3) times the
  // meshes' vertex count, a row wavelet other than Haar (the lighting basis of
  // runtime/lighting.h). A 3-channel transport relights colour channel c of vertex v from row
  // c·V + v with lighting channel c; everything per sample stays per vertex (V samples).
  static std::unique_ptr<RelightSession> Open(const std::string& pack_path);
  // The same from a pack the caller already opened (`pack_path` names it in errors).
  static std::unique_ptr<RelightSession> FromReader(const pack::PackReader& reader,
                                                    const std::string& pack_path);
  //
  // Image packs (an IMGE section, docs/image-relighting.md): the samples are the pixels of the
  // pack's camera (camera() is it), albedo() is each pixel's mesh's (0 for background), there
  // are no positions or triangles, and Render writes the relit image straight from the pixel
  // rows (no rasteriser) at the pack's fixed view.

  RelightSession(const RelightSession&) = delete;
  RelightSession& operator=(const RelightSession&) = delete;
  virtual ~RelightSession();

  const std::string& path() const { return path_; }
  int cubemap_n() const { return static_cast<int>(transport_header().cubemap_n); }
  std::size_t sample_count() const { return albedo_.size(); }
  // The scene's [camera] from the pack's metadata ("scene" → "camera"), else Camera{}.
  const Camera& camera() const { return camera_; }
  bool camera_from_metadata() const { return camera_from_metadata_; }
  // The image of an image pack (nullptr for a vertex pack).
  const ImageSamplesInfo* image() const { return image_ ? &*image_ : nullptr; }
  const CompressedTransportHeader& transport_header() const;
  std::size_t transport_terms() const { return transport_terms_; }
  // The adaptive 4D / 2D relighter; a CPCA pack has none (cpca() instead): throws
  // std::logic_error there.
  const CompressedRelighter& relighter() const;
  // A CPCA pack (docs/cpca.md): its relighter (Overbeck 2006 §6.3), else nullptr. The session's
  // order is then the pack's.
  const CpcaRelighter* cpca() const { return cpca_relighter_.get(); }
  const TransportOperator& transport() const { return *transport_op_; }
  // Glossy vertex packs (a GLSY section, docs/glossy-transport.md): the BRDF factor table, else
  // nullptr. transport() then has terms × sample_count() samples (term t of session sample p at
  // t·sample_count() + p, the session's order in every term), and Shade combines them with the
  // view: B(x) = w ⊙ Σ_t g_t(ω_o(x))·(T_t·L)(x), ω_o = eye − x in x's factor frame (Eq. 3).
  const GlossyFactorTable* glossy() const { return glossy_ ? &*glossy_ : nullptr; }
  // Rows of the transport per sample and channel: the BRDF terms of a glossy pack, else 1.
  std::size_t terms() const { return glossy_ ? static_cast<std::size_t>(glossy_->terms) : 1; }
  // Σ_t g_t(ω_o)·radiance[t·V + p] per sample p (the identity for a pack without terms; a
  // diffuse mesh's vertex takes its term 0): radiance of terms() × sample_count() samples.
  SampleRadiance CombineTerms(const SampleRadiance& radiance, const Vec3& eye) const;
  // Albedo and position per spatial sample, and the triangles over them, in the session's order.
  const std::vector<Rgb>& albedo() const { return albedo_; }
  std::span<const Vec3> positions() const { return positions_; }
  std::span<const std::array<uint32_t, 3>> triangles() const { return triangles_; }
  // The pack sample at position p of the session's order (a permutation of 0..samples−1).
  std::span<const uint32_t> pack_sample() const { return pack_sample_; }
  // The inverse: the session position of pack sample v.
  std::span<const uint32_t> session_position() const { return session_position_; }
  // Bytes the session holds: the decoded transport and its relighter, per-sample arrays.
  std::size_t memory_bytes() const;
  // Per-sample values in the session's order (k values per sample, interleaved) → pack order.
  std::vector<float> ToPackOrder(std::span<const float> values, std::size_t k = 3) const;

  // T·L with every coefficient of L (Eq. 8 with dense lighting: one inverse column transform),
  // in the session's order. Throws NumericalError naming the pack when a coefficient of L is
  // outside the float range or T·L overflows the relighter (docs/viewer.md, "NaN and Inf").
  SampleRadiance RelightExact(const WaveletLighting& lighting) const;
  // albedo ⊙ radiance, interleaved RGB per sample (ShadeSamples), in the session's order.
  // Throws NumericalError naming the pack and the pack's sample number when a colour is not a
  // finite float.
  std::vector<float> Shade(const SampleRadiance& radiance) const;
  // The same with a glossy pack's terms combined for `eye` instead of the camera's eye.
  std::vector<float> Shade(const SampleRadiance& radiance, const Vec3& eye) const;

 protected:
  RelightSession() = default;
  // Reads the pack into this session (Open's work; ViewerSession's Open calls it too).
  // `scene_toml_camera`: CameraFromMetadata's TOML fallback (runtime/camera_metadata.h).
  void Load(const pack::PackReader& reader, const std::string& pack_path,
            const SceneTomlCameraFn& scene_toml_camera = {});

 private:
  std::string path_;
  Camera camera_;
  bool camera_from_metadata_ = false;
  std::unique_ptr<CompressedTransport> compressed_;
  std::size_t transport_terms_ = 0;
  std::unique_ptr<CompressedRelighter> relighter_;
  std::unique_ptr<CpcaTransport> cpca_transport_;
  std::unique_ptr<CpcaRelighter> cpca_relighter_;
  std::unique_ptr<CompressedTransportOperator> operator_;
  const TransportOperator* transport_op_ = nullptr;
  std::vector<Rgb> albedo_;
  std::optional<GlossyFactorTable> glossy_;
  std::vector<uint32_t> sample_factor_;  // glossy packs: per session sample, factors or diffuse
  std::vector<FactorFrame> frames_;      // glossy packs: per session sample
  std::vector<Vec3> positions_;
  std::vector<std::array<uint32_t, 3>> triangles_;
  std::vector<uint32_t> pack_sample_;       // session position → pack sample
  std::vector<uint32_t> session_position_;  // pack sample → session position
  std::optional<ImageSamplesInfo> image_;
};

// ‖b − ref‖ / ‖ref‖ over all entries (double); 0 when both are zero, 1 when only ref is.
double RelativeRmsError(std::span<const float> b, std::span<const float> ref);

// A lighting approximation of `terms` terms from zero: NWA directly; BI or PBI as the first
// frame of an incremental run started from L̃ = 0 (Clear, one Update).
SampleRadiance RelightApproximate(const TransportOperator& transport, const WaveletLighting& l,
                                  LightingMode mode, std::size_t terms);

}  // namespace prt
