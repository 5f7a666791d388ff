#include "viewer/glossy_session.h"

#include "packager/prtpack_reader.h"
#include "viewer/viewer_session.h"
#include "vocabulary/tbb_parallel.h"

namespace prt {

std::unique_ptr<GlossySession> GlossySession::Open(const std::string& pack_path) {
  return FromReader(pack::PackReader::OpenFile(pack_path), pack_path);
}

std::unique_ptr<GlossySession> GlossySession::FromReader(const pack::PackReader& reader,
                                                         const std::string& pack_path) {
  UseTbbParallelism();  // the runtime's triple products run on TBB in prt-view
  std::unique_ptr<GlossySession> s(new GlossySession());
  s->Load(reader, pack_path, SceneTomlCamera);
  return s;
}

ImageRgb GlossySession::Render(const Camera& camera, std::span<const float> vertex_rgb,
                               const CubemapRgb* background) const {
  return Render(camera, vertex_rgb,
                background != nullptr ? CubemapBackground(*background) : BackgroundFunction{});
}

ImageRgb GlossySession::Render(const Camera& camera, std::span<const float> vertex_rgb,
                               const BackgroundFunction& background) const {
  RasterOptions options;
  options.background = background;
  const RasterImage r = RasterizeTriangles(camera, positions(), triangles(), vertex_rgb, options);
  ImageRgb image(r.width, r.height);
  image.pixels = r.rgb;
  return image;
}

}  // namespace prt
