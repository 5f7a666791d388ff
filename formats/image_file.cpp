// run/image.prti (see image_file.h and docs/transport-format.md, "image.prti").
#include "formats/image_file.h"

#include <cmath>
#include <cstring>
#include <stdexcept>

#include "vocabulary/bytes.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/errors.h"
#include "vocabulary/hash.h"

namespace prt {

namespace {

constexpr char kImageMagic[8] = {'P', 'R', 'T', 'I', 'M', 'G', '0', '1'};
// Glossy pixels: the same, then u32 mesh_count and per mesh u32 flags (1 = glossy), f32[3] weight.
constexpr char kImageMagicGlossy[8] = {'P', 'R', 'T', 'I', 'M', 'G', '0', '2'};
// Supersampled pixels: PRTIMG02's layout (the mesh table always present), then u32 k, f32
// coverage[pixels], f32[3] weight[pixels].
constexpr char kImageMagicSupersampled[8] = {'P', 'R', 'T', 'I', 'M', 'G', '0', '3'};

}  // namespace

std::string SerializeImageSamples(const ImageSamplesInfo& info) {
  ByteWriter w;
  const bool supersampled = info.supersample > 1;
  const bool glossy = info.has_glossy_pixels() || supersampled;
  w.PutBytes(supersampled ? kImageMagicSupersampled : glossy ? kImageMagicGlossy : kImageMagic, 8);
  w.Put<uint32_t>(static_cast<uint32_t>(info.camera.width));
  w.Put<uint32_t>(static_cast<uint32_t>(info.camera.height));
  for (const Vec3& v : {info.camera.eye, info.camera.target, info.camera.up}) {
    w.Put(v.x);
    w.Put(v.y);
    w.Put(v.z);
  }
  w.Put(info.camera.fov_deg);
  w.PutBytes(info.pixel_mesh.data(), info.pixel_mesh.size() * sizeof(uint32_t));
  if (glossy) {
    w.Put<uint32_t>(static_cast<uint32_t>(info.glossy_mesh.size()));
    for (std::size_t m = 0; m < info.glossy_mesh.size(); ++m) {
      w.Put<uint32_t>(info.glossy_mesh[m]);
      for (int c = 0; c < 3; ++c) w.Put<float>(info.glossy_weight[m][c]);
    }
  }
  if (supersampled) {
    if (info.coverage.size() != info.pixels() || info.pixel_weight.size() != info.pixels())
      throw std::invalid_argument("SerializeImageSamples: coverage or weights not per pixel (" + std::to_string(info.coverage.size()) + ", " + std::to_string(info.pixel_weight.size()) + " for " + std::to_string(info.pixels()) + ")");
    w.Put<uint32_t>(static_cast<uint32_t>(info.supersample));
    for (float c : info.coverage) w.Put<float>(c);
    for (const Rgb& a : info.pixel_weight)
      for (int c = 0; c < 3; ++c) w.Put<float>(a[c]);
  }
  std::string& out = w.bytes();
  w.Put<uint64_t>(Checksum64(out.data(), out.size()));
  return std::move(out);
}

ImageSamplesInfo ParseImageSamples(std::string_view bytes, const std::string& name,
                                   uint32_t mesh_count) {
  if (bytes.size() < 16 || (std::memcmp(bytes.data(), kImageMagic, 8) != 0 &&
                            std::memcmp(bytes.data(), kImageMagicGlossy, 8) != 0 &&
                            std::memcmp(bytes.data(), kImageMagicSupersampled, 8) != 0))
    throw InputError(name, "not a prtfarm image file (bad magic)");
  const bool supersampled = std::memcmp(bytes.data(), kImageMagicSupersampled, 8) == 0;
  const bool glossy = supersampled || std::memcmp(bytes.data(), kImageMagicGlossy, 8) == 0;
  const std::size_t body = bytes.size() - 8;
  if (Checksum64(bytes.data(), body) != LoadAt<uint64_t>(bytes, body))
    throw InputError(name, "image file checksum mismatch: the file is damaged");
  ByteReader in(bytes.substr(0, body), [&name](const char* what, std::size_t) {
    throw InputError(name, std::string("truncated image file in ") + what);
  });
  in.Take(8, "magic");
  ImageSamplesInfo info;
  const auto w = in.Get<uint32_t>("size"), h = in.Get<uint32_t>("size");
  if (w == 0 || h == 0 || w > kMaxImageSide || h > kMaxImageSide)
    throw InputError(name, "image size " + std::to_string(w) + "×" + std::to_string(h) +
                               " is outside 1…" + std::to_string(kMaxImageSide));
  info.camera.width = static_cast<int>(w);
  info.camera.height = static_cast<int>(h);
  for (Vec3* v : {&info.camera.eye, &info.camera.target, &info.camera.up}) {
    v->x = in.Get<double>("camera");
    v->y = in.Get<double>("camera");
    v->z = in.Get<double>("camera");
    if (!IsFinite(*v)) throw InputError(name, "non-finite camera vector");
  }
  info.camera.fov_deg = in.Get<double>("camera");
  if (!(info.camera.fov_deg > 0 && info.camera.fov_deg < 180))
    throw InputError(name, "camera fov outside (0, 180) degrees");
  // PRTIMG03 may carry an empty mesh table (every pixel diffuse).
  const std::size_t extra = supersampled ? 4 + std::size_t{16} * info.pixels() : 0;
  const std::size_t table = (glossy ? 4 + std::size_t{16} * mesh_count : 0) + extra;
  const std::size_t fixed = info.pixels() * sizeof(uint32_t);
  const bool empty_table = supersampled && in.remaining() == fixed + 4 + extra;
  if (in.remaining() != fixed + table && !empty_table)
    throw InputError(name, "holds " + std::to_string(in.remaining()) + " bytes of pixels" +
                               (glossy ? " and mesh table" : "") +
                               (supersampled ? " and supersampling" : "") + " for a " +
                               std::to_string(w) + "×" + std::to_string(h) + " image" +
                               (glossy ? " of " + std::to_string(mesh_count) + " meshes" : ""));
  info.pixel_mesh.resize(info.pixels());
  std::memcpy(info.pixel_mesh.data(), in.Take(info.pixels() * sizeof(uint32_t), "pixels").data(),
              info.pixel_mesh.size() * sizeof(uint32_t));
  if (empty_table) {
    if (in.Get<uint32_t>("mesh table") != 0)
      throw InputError(name, "glossy-pixel table size does not match the file size");
  } else if (glossy) {
    if (in.Get<uint32_t>("mesh table") != mesh_count)
      throw InputError(name, "glossy-pixel table does not have one entry per mesh (" +
                                 std::to_string(mesh_count) + ")");
    info.glossy_mesh.resize(mesh_count);
    info.glossy_weight.resize(mesh_count);
    for (uint32_t m = 0; m < mesh_count; ++m) {
      const auto flags = in.Get<uint32_t>("mesh table");
      if (flags > 1)
        throw InputError(name, "mesh " + std::to_string(m) + " has glossy flags " +
                                   std::to_string(flags) + " (0 or 1)");
      info.glossy_mesh[m] = static_cast<uint8_t>(flags);
      for (int c = 0; c < 3; ++c) {
        const float x = in.Get<float>("mesh table");
        if (!(x >= 0.f && x <= 1.f))
          throw InputError(name,
                           "mesh " + std::to_string(m) + " has a glossy weight outside [0, 1]");
        info.glossy_weight[m][c] = x;
      }
    }
  }
  if (supersampled) {
    const auto k = in.Get<uint32_t>("supersampling");
    if (k < 2 || k > 16)
      throw InputError(name, "supersample " + std::to_string(k) + " outside 2…16");
    info.supersample = static_cast<int>(k);
    info.camera.supersample = info.supersample;
    info.coverage.resize(info.pixels());
    info.pixel_weight.resize(info.pixels());
    for (std::size_t p = 0; p < info.pixels(); ++p) {
      const float c = in.Get<float>("coverage");
      const bool bg = info.pixel_mesh[p] == kImageBackground;
      if (!(c >= 0.f && c <= 1.f) || (c == 0.f) != bg)
        throw InputError(name, "pixel " + std::to_string(p) +
                                   " has a coverage outside [0, 1] or not matching its mesh");
      info.coverage[p] = c;
    }
    for (std::size_t p = 0; p < info.pixels(); ++p) {
      for (int c = 0; c < 3; ++c) {
        const float x = in.Get<float>("pixel weights");
        if (!(x >= 0.f && x <= 1.f))
          throw InputError(name, "pixel " + std::to_string(p) + " has a weight outside [0, 1]");
        info.pixel_weight[p][c] = x;
      }
    }
    // A supersampled image writes its mesh table whatever the meshes: all-diffuse reads back
    // as no glossy pixels.
    if (!info.has_glossy_pixels()) {
      info.glossy_mesh.clear();
      info.glossy_weight.clear();
    }
  }
  for (std::size_t p = 0; p < info.pixel_mesh.size(); ++p) {
    const uint32_t m = info.pixel_mesh[p];
    if (m != kImageBackground && m >= mesh_count)
      throw InputError(name, "pixel " + std::to_string(p) + " names mesh " + std::to_string(m) +
                                 " of " + std::to_string(mesh_count));
  }
  return info;
}

void WriteImageSamplesFile(const std::string& path, const ImageSamplesInfo& info) {
  WriteFileDurably(path, SerializeImageSamples(info));
}

ImageSamplesInfo ReadImageSamplesFile(const std::string& path, uint32_t mesh_count) {
  return ParseImageSamples(ReadWholeFile(path), path, mesh_count);
}

}  // namespace prt
