// What `prt-view`, its tests and the viewer benchmark share: a .prtpack opened for relighting
// (meshes, per-sample albedo, the scene's camera, the compressed transport behind a
// TransportOperator), lighting from an environment map, shading B = albedo ⊙ (T·L̂), software
// rasterisation, and the rotating-environment experiment of Overbeck et al. 2006 §5/Figure 7
// (NWA, BI and PBI at the same term budget, each against exact lighting, frame by frame).
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
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "runtime/lighting.h"
#include "runtime/relight.h"
#include "runtime/relight_session.h"
#include "viewer/rasterizer.h"
#include "vocabulary/envmap.h"
#include "vocabulary/image_io.h"
#include "vocabulary/scene.h"
#include "vocabulary/vec3.h"

namespace prt {

// The camera of a scene.toml kept as text in a pack's metadata (CameraFromMetadata's fallback,
// runtime/camera_metadata.h), with the scene parser; false when the text does not parse.
bool SceneTomlCamera(const std::string& toml, const std::string& name, Camera& camera);

// A pack opened for relighting and drawing: RelightSession (runtime/relight_session.h) plus the
// software rasteriser. Opening one installs TBB as the parallel backend
// (vocabulary/tbb_parallel.h).
class ViewerSession final : public RelightSession {
 public:
  static std::unique_ptr<ViewerSession> Open(const std::string& pack_path);
  static std::unique_ptr<ViewerSession> FromReader(const pack::PackReader& reader,
                                                   const std::string& pack_path);

  // Rasterises the meshes with per-sample colours (3 floats per sample, the session's order)
  // from `camera`, over `background` (an empty function: black). An image pack's image instead:
  // pixel p shows its row's colour, a background pixel `background` along its camera ray; its
  // view is fixed, so `camera` must be the pack's (std::invalid_argument otherwise). prt-view's
  // background is the environment image at its own resolution (EnvironmentBackground,
  // environment_background.h).
  ImageRgb Render(const Camera& camera, std::span<const float> sample_rgb,
                  const BackgroundFunction& background) const;
  // The same over the lighting cubemap (nearest texel, 6·n² texels: blocky) when `background`
  // is non-null, else black: for callers that have no environment image (tests, benchmarks).
  ImageRgb Render(const Camera& camera, std::span<const float> sample_rgb,
                  const CubemapRgb* background) const;

 private:
  ViewerSession() = default;
  ImageRgb RenderImage(std::span<const float> sample_rgb,
                       const BackgroundFunction& background) const;
};

// ---- Rotating environment (Overbeck et al. 2006 §5, Figure 7) ----

struct RotationOptions {
  double degrees_per_frame = 1.0;  // about +Y (envmap.h RotateAboutY)
  int rotate_frames = 120;         // frames 1..K rotate; frame 0 is the unrotated start
  int hold_frames = 30;            // then S frames with the environment still
  std::size_t terms = 30;          // the per-frame budget N of NWA, BI and PBI alike
};

// One frame's errors, index 0 = NWA, 1 = BI, 2 = PBI, against exact lighting of that frame:
// lighting error ‖L − L̂‖/‖L‖ (L̂: the NWA terms, or the L̃ an incremental relighter
// represents) and image error RelativeRmsError of the shaded samples.
struct RotationFrame {
  int frame = 0;
  double angle_deg = 0;
  std::array<double, 3> lighting_error{};
  std::array<double, 3> image_error{};
  // PBI's band decisions this frame (Overbeck et al. 2006 Fig. 9): character b is '1' when band
  // b (0 = scaling and coarsest wavelets … finest) was reset, updated non-incrementally; empty
  // on frame 0 (Initialize).
  std::string pbi_reset_bands;
};

// What the callback may look at for each frame (valid during the call only).
struct RotationFrameView {
  const RotationFrame& errors;
  const CubemapRgb& cube;  // the rotated lighting
  double rotation_y;  // its rotation about +Y in radians (ResampleToCubemap's, for backgrounds)
  std::span<const float> exact_rgb;                  // shaded samples, exact lighting
  std::array<std::span<const float>, 3> approx_rgb;  // NWA, BI, PBI
};

// Runs frames 0..K+S: frame f's environment is rotated by min(f, K)·degrees_per_frame. BI and
// PBI start from the exact frame 0 (Initialize, the paper's full first multiply), then spend N
// terms per frame; NWA takes N terms of each frame's lighting afresh. The environment is
// resampled once per distinct angle. `on_frame` (optional) sees every frame as it is made.
std::vector<RotationFrame> RunRotation(
    const ViewerSession& session, const EnvironmentImage& env, const RotationOptions& options,
    const std::function<void(const RotationFrameView&)>& on_frame = {});

// Writes the frames as CSV: frame, angle_deg, then lighting and image error of nwa, bi, pbi.
void WriteRotationCsv(const std::vector<RotationFrame>& frames, std::size_t terms,
                      const std::string& path);
// First hold frame (counted from the frame the rotation stopped, 1 = the first still frame)
// whose image error for mode `index` (0 NWA, 1 BI, 2 PBI) is below `threshold`; -1 if none.
int FramesToConverge(const std::vector<RotationFrame>& frames, const RotationOptions& options,
                     int index, double threshold);

}  // namespace prt
