// A glossy pack (per-vertex visibility, runtime/glossy_relight_session.h) opened in prt-view: the
// runtime's triple-product session plus the rasteriser that draws its vertex colours.
#pragma once

#include <memory>
#include <span>
#include <string>

#include "runtime/glossy_relight_session.h"
#include "viewer/rasterizer.h"
#include "vocabulary/image_io.h"

namespace prt {

class GlossySession : public GlossyRelightSession {
 public:
  // GlossyRelightSession::Open with the TOML fallback for the camera (SceneTomlCamera).
  static std::unique_ptr<GlossySession> Open(const std::string& pack_path);
  static std::unique_ptr<GlossySession> FromReader(const pack::PackReader& reader,
                                                   const std::string& pack_path);

  // Rasterises the meshes with per-vertex colours from `camera`, over `background` (an empty
  // function: black; prt-view's is EnvironmentBackground, environment_background.h).
  ImageRgb Render(const Camera& camera, std::span<const float> vertex_rgb,
                  const BackgroundFunction& background) const;
  // The same over the lighting cubemap (nearest texel: blocky) if non-null, else black.
  ImageRgb Render(const Camera& camera, std::span<const float> vertex_rgb,
                  const CubemapRgb* background) const;

 private:
  GlossySession() = default;
};

}  // namespace prt
