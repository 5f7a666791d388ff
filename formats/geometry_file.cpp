// run/geometry.prtg (see geometry_file.h and docs/transport-format.md, "geometry.prtg").
#include "formats/geometry_file.h"

#include <bit>
#include <cmath>
#include <cstring>
#include <stdexcept>

#include "vocabulary/bytes.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/errors.h"
#include "vocabulary/hash.h"

namespace prt {

namespace {

constexpr char kGeometryMagic[8] = {'P', 'R', 'T', 'G', 'E', 'O', 'M', '1'};
constexpr uint32_t kGeometryVersion = 1;

}  // namespace

std::string SerializeSceneGeometry(const SceneGeometry& geometry) {
  ByteWriter w;
  w.PutBytes(kGeometryMagic, 8);
  w.Put<uint32_t>(kGeometryVersion);
  w.Put<uint32_t>(static_cast<uint32_t>(geometry.meshes.size()));
  for (const Vec3& v : {geometry.bounds_min, geometry.bounds_max}) {
    w.Put(v.x);
    w.Put(v.y);
    w.Put(v.z);
  }
  for (const SceneMesh& m : geometry.meshes) {
    w.Put<uint32_t>(static_cast<uint32_t>(m.name.size()));
    w.PutBytes(m.name.data(), m.name.size());
    for (float a : m.albedo) w.Put(a);
    w.Put<uint32_t>(m.is_ground ? 1u : 0u);
    w.Put<uint32_t>(static_cast<uint32_t>(m.grid_resolution));
    w.Put<uint64_t>(m.mesh.positions.size());
    w.Put<uint64_t>(m.mesh.triangles.size());
    for (const auto* list : {&m.mesh.positions, &m.mesh.normals}) {
      if (list->size() != m.mesh.positions.size()) {
        throw std::invalid_argument("SerializeSceneGeometry: mesh '" + m.name +
                                    "' has a normal count different from its vertex count");
      }
      for (const Vec3& v : *list) {
        w.Put(v.x);
        w.Put(v.y);
        w.Put(v.z);
      }
    }
    for (const auto& t : m.mesh.triangles) {
      for (uint32_t i : t) w.Put(i);
    }
  }
  std::string& out = w.bytes();
  w.Put<uint64_t>(Checksum64(out.data(), out.size()));
  return std::move(out);
}

namespace {

// The geometry file's reader: a truncated file is an InputError naming it and the field.
ByteReader GeometryReader(std::string_view bytes, const std::string& name) {
  return ByteReader(bytes, [&name](const char* what, std::size_t) {
    throw InputError(name, std::string("truncated geometry file in ") + what);
  });
}

Vec3 GetVec3(ByteReader& in, const std::string& name, const char* what) {
  Vec3 v;
  v.x = in.Get<double>(what);
  v.y = in.Get<double>(what);
  v.z = in.Get<double>(what);
  if (!IsFinite(v)) throw InputError(name, std::string("non-finite value in ") + what);
  return v;
}

}  // namespace

SceneGeometry ParseSceneGeometry(std::string_view bytes, const std::string& name) {
  if (bytes.size() < 16 || std::memcmp(bytes.data(), kGeometryMagic, 8) != 0) {
    throw InputError(name, "not a prtfarm geometry file (bad magic)");
  }
  const std::size_t body = bytes.size() - 8;
  if (Checksum64(bytes.data(), body) != LoadAt<uint64_t>(bytes, body)) {
    throw InputError(name, "geometry file checksum mismatch: the file is damaged");
  }
  ByteReader in = GeometryReader(bytes.substr(0, body), name);
  in.Take(8, "magic");
  const auto version = in.Get<uint32_t>("header");
  if (version != kGeometryVersion) {
    throw InputError(name,
                     "geometry file version " + std::to_string(version) + " is not supported");
  }
  const auto mesh_count = in.Get<uint32_t>("header");
  SceneGeometry g;
  g.bounds_min = GetVec3(in, name, "bounds");
  g.bounds_max = GetVec3(in, name, "bounds");
  for (uint32_t m = 0; m < mesh_count; ++m) {
    SceneMesh sm;
    const auto name_len = in.Get<uint32_t>("mesh name");
    sm.name = std::string(in.Take(name_len, "mesh name"));
    for (float& a : sm.albedo) {
      a = in.Get<float>("albedo");
      if (!std::isfinite(a)) throw InputError(name, "non-finite albedo in mesh " + sm.name);
    }
    sm.is_ground = in.Get<uint32_t>("mesh flags") != 0;
    sm.grid_resolution = static_cast<int>(in.Get<uint32_t>("mesh flags"));
    const auto vertices = in.Get<uint64_t>("mesh counts");
    const auto triangles = in.Get<uint64_t>("mesh counts");
    in.Need(vertices > in.remaining() / 48 ? in.remaining() + 1 : vertices * 48, "vertices");
    in.Need(triangles > in.remaining() / 12 ? in.remaining() + 1 : triangles * 12, "triangles");
    sm.mesh.source = name;
    sm.mesh.positions.resize(vertices);
    sm.mesh.normals.resize(vertices);
    for (Vec3& p : sm.mesh.positions) p = GetVec3(in, name, "positions");
    for (Vec3& n : sm.mesh.normals) n = GetVec3(in, name, "normals");
    sm.mesh.triangles.resize(triangles);
    for (auto& t : sm.mesh.triangles) {
      for (uint32_t& i : t) {
        i = in.Get<uint32_t>("triangles");
        if (i >= vertices) {
          throw InputError(
              name, "triangle index " + std::to_string(i) + " out of range in mesh " + sm.name);
        }
      }
    }
    g.meshes.push_back(std::move(sm));
  }
  if (in.remaining() != 0) throw InputError(name, "trailing bytes after the last mesh");
  return g;
}

void WriteSceneGeometryFile(const std::string& path, const SceneGeometry& geometry) {
  WriteFileDurably(path, SerializeSceneGeometry(geometry));
}

SceneGeometry ReadSceneGeometryFile(const std::string& path) {
  return ParseSceneGeometry(ReadWholeFile(path), path);
}

}  // namespace prt
