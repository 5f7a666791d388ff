// A pack with visibility opened for glossy triple-product relighting (see
// glossy_relight_session.h).
#include "runtime/glossy_relight_session.h"

#include <cmath>
#include <nlohmann/json.hpp>
#include <stdexcept>

#include "packager/prtpack_reader.h"
#include "runtime/camera_metadata.h"
#include "vocabulary/errors.h"

namespace prt {

Material MaterialFromSettings(const GlossyMaterialSettings& g, const Rgb& albedo) {
  if (g.brdf == "ggx")
    throw std::invalid_argument(
        "brdf \"ggx\" is not evaluated by triple products (visibility packs): bake it as glossy "
        "pixels of an image run ([scene] samples = \"camera\", docs/image-relighting.md) or "
        "use brdf = \"phong\" for a visibility pack");
  return MaterialOfSettings(g, albedo);
}

std::vector<Material> GlossyMaterialsFromMetadata(const std::string& metadata_json,
                                                  const std::vector<Rgb>& albedo,
                                                  const std::string& name) {
  std::vector<Material> out;
  for (const Rgb& a : albedo) out.push_back(MaterialFromSettings({}, a));
  const nlohmann::json meta = nlohmann::json::parse(metadata_json, nullptr, false);
  if (!meta.is_object() || !meta.contains("materials")) return out;
  const nlohmann::json& list = meta["materials"];
  if (!list.is_array()) throw InputError(name, "metadata materials is not an array");
  for (std::size_t i = 0; i < list.size() && i < out.size(); ++i) {
    const nlohmann::json& j = list[i];
    const std::string where = "metadata materials[" + std::to_string(i) + "]";
    if (!j.is_object()) throw InputError(name, where + " is not an object");
    auto colour = [&](const char* key, const Rgb& def) {
      if (!j.contains(key)) return def;
      const nlohmann::json& v = j[key];
      if (!v.is_array() || v.size() != 3) throw InputError(name, where + "." + key + " is not RGB");
      Rgb c;
      for (int k = 0; k < 3; ++k) {
        if (!v[k].is_number()) throw InputError(name, where + "." + key + " is not numeric");
        const double x = v[k].get<double>();
        if (!(x >= 0 && x <= 1)) throw InputError(name, where + "." + key + " is outside [0, 1]");
        c[k] = static_cast<float>(x);
      }
      return c;
    };
    auto number = [&](const char* key, double def) {
      if (!j.contains(key)) return def;
      if (!j[key].is_number()) throw InputError(name, where + "." + key + " is not numeric");
      const double x = j[key].get<double>();
      if (!(x > 0 && x <= 1e6)) throw InputError(name, where + "." + key + " is outside (0, 1e6]");
      return x;
    };
    GlossyMaterialSettings g;
    if (j.contains("brdf")) {
      if (!j["brdf"].is_string()) throw InputError(name, where + ".brdf is not a string");
      g.brdf = j["brdf"].get<std::string>();
    }
    g.specular = colour("specular", g.specular);
    g.exponent = number("exponent", g.exponent);
    g.exponent_v = number("exponent_v", g.exponent);
    if (j.contains("roughness")) {
      g.roughness = number("roughness", g.roughness);
      if (g.roughness > 1) throw InputError(name, where + ".roughness is outside (0, 1]");
    }
    try {
      out[i] = MaterialFromSettings(g, colour("diffuse", albedo[i]));
    } catch (const std::invalid_argument& e) {
      throw InputError(name, where + ": " + e.what());
    }
  }
  return out;
}

GlossyRelightSession::~GlossyRelightSession() = default;

std::unique_ptr<GlossyRelightSession> GlossyRelightSession::Open(const std::string& pack_path) {
  return FromReader(pack::PackReader::OpenFile(pack_path), pack_path);
}

std::unique_ptr<GlossyRelightSession> GlossyRelightSession::FromReader(
    const pack::PackReader& reader, const std::string& pack_path) {
  std::unique_ptr<GlossyRelightSession> s(new GlossyRelightSession());
  s->Load(reader, pack_path);
  return s;
}

void GlossyRelightSession::Load(const pack::PackReader& reader, const std::string& pack_path,
                                const SceneTomlCameraFn& scene_toml_camera) {
  GlossyRelightSession* s = this;
  if (!reader.has_visibility()) {
    throw InputError(pack_path,
                     "the pack has no visibility (VISB) sections; farm it with [sampling] job = "
                     "\"visibility\" for glossy relighting");
  }
  s->path_ = pack_path;
  const std::string meta = reader.ReadMetadata();
  CameraFromMetadata(meta, pack_path, s->camera_, scene_toml_camera);
  std::vector<Rgb> albedo;
  std::size_t offset = 0;
  for (std::size_t m = 0; m < reader.mesh_count(); ++m) {
    const pack::UnpackedMesh mesh = reader.ReadMesh(m);
    const std::size_t nv = mesh.vertex_count();
    s->mesh_names_.push_back(mesh.name);
    albedo.push_back(mesh.albedo);
    for (std::size_t v = 0; v < nv; ++v) {
      s->positions_.push_back(
          {mesh.positions[3 * v], mesh.positions[3 * v + 1], mesh.positions[3 * v + 2]});
      Vec3 n{mesh.normals[3 * v], mesh.normals[3 * v + 1], mesh.normals[3 * v + 2]};
      const double len = Length(n);
      s->normals_.push_back(len > 0 ? n / len : Vec3{0, 1, 0});
      s->material_index_.push_back(static_cast<uint16_t>(m));
    }
    for (std::size_t t = 0; t < mesh.triangle_count(); ++t)
      s->triangles_.push_back({static_cast<uint32_t>(offset + mesh.triangles[3 * t]),
                               static_cast<uint32_t>(offset + mesh.triangles[3 * t + 1]),
                               static_cast<uint32_t>(offset + mesh.triangles[3 * t + 2])});
    offset += nv;
  }
  if (reader.mesh_count() > 65535) throw InputError(pack_path, "more than 65535 meshes");
  s->visibility_ = reader.ReadAllVisibility();
  s->blocks_ = std::make_unique<CubemapBlocks>(s->visibility_.n);
  s->materials_ = GlossyMaterialsFromMetadata(meta, albedo, pack_path);
}

GlossyScene GlossyRelightSession::Scene() const {
  return GlossyScene{positions_, normals_, material_index_, materials_, &visibility_};
}

BlockLighting GlossyRelightSession::Lighting(const CubemapRgb& cube) const {
  return ComputeBlockLighting(cube, *blocks_);
}

// The triple products' outputs are finite floats or a NumericalError naming the vertex
// (triple_product.h); the session adds the pack's name to it.
TripleProductStats GlossyRelightSession::Relight(const BlockLighting& light, const Vec3& eye,
                                                 std::span<float> rgb,
                                                 const TripleProductOptions& options) const {
  try {
    return RelightTripleProduct(Scene(), *blocks_, light, eye, rgb, options);
  } catch (const NumericalError& e) {
    throw NumericalError(path_ + ": " + e.what());
  }
}

TripleProductStats GlossyRelightSession::RelightRange(const BlockLighting& light, const Vec3& eye,
                                                      std::size_t first, std::size_t count,
                                                      std::span<float> rgb,
                                                      const TripleProductOptions& options) const {
  try {
    return RelightTripleProductRange(Scene(), *blocks_, light, eye, first, count, rgb, options);
  } catch (const NumericalError& e) {
    throw NumericalError(path_ + ": " + e.what());
  }
}

void GlossyRelightSession::RelightReference(const BlockLighting& light, const Vec3& eye,
                                            std::span<float> rgb) const {
  try {
    RelightPixelBasisReference(Scene(), *blocks_, light, eye, rgb);
  } catch (const NumericalError& e) {
    throw NumericalError(path_ + ": " + e.what());
  }
}

}  // namespace prt
