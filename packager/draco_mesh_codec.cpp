// Order-preserving Draco mesh coding for .prtpack MESH sections (docs/prtpack-format.md).
// Draco's sequential mesh encoder (MESH_SEQUENTIAL_ENCODING) writes the points in their index
// order through a linear sequencer and the faces in their index order; since the draco::Mesh is
// built with one attribute value per point and never deduplicated, the decoded point i is the
// input vertex i (Draco bitstream spec, "Sequential Connectivity Decoder").
#include "packager/draco_mesh_codec.h"

#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <optional>
#include <span>

#include "draco/compression/decode.h"
#include "draco/compression/expert_encode.h"
#include "draco/core/decoder_buffer.h"
#include "draco/core/encoder_buffer.h"
#include "draco/mesh/mesh.h"
#include "vocabulary/bytes.h"
#include "vocabulary/errors.h"

namespace prt::pack {
namespace {

constexpr uint32_t kMaxPoints = (1u << 31) - 1;

int AddFloatAttribute(draco::Mesh& mesh, draco::GeometryAttribute::Type type,
                      const std::vector<Vec3>& values) {
  draco::GeometryAttribute ga;
  ga.Init(type, nullptr, 3, draco::DT_FLOAT32, false, sizeof(float) * 3, 0);
  const int id =
      mesh.AddAttribute(ga, /*identity_mapping=*/true, static_cast<uint32_t>(values.size()));
  draco::PointAttribute* att = mesh.attribute(id);
  for (std::size_t i = 0; i < values.size(); ++i) {
    const float v[3] = {static_cast<float>(values[i].x), static_cast<float>(values[i].y),
                        static_cast<float>(values[i].z)};
    att->SetAttributeValue(draco::AttributeValueIndex(static_cast<uint32_t>(i)), v);
  }
  return id;
}

void ExtractAttribute(const draco::Mesh& mesh, draco::GeometryAttribute::Type type,
                      const char* what, std::vector<float>& out, const std::string& where) {
  const draco::PointAttribute* att = mesh.GetNamedAttribute(type);
  if (att == nullptr || att->num_components() != 3) {
    throw InputError(where, std::string("MESH has no 3-component ") + what + " attribute");
  }
  const uint32_t n = mesh.num_points();
  out.resize(std::size_t(n) * 3);
  for (uint32_t i = 0; i < n; ++i) {
    const draco::AttributeValueIndex vi = att->mapped_index(draco::PointIndex(i));
    if (vi.value() >= att->size()) {
      throw InputError(where, std::string("MESH ") + what + " index out of range");
    }
    float v[3];
    if (!att->ConvertValue<float, 3>(vi, v)) {
      throw InputError(where, std::string("MESH ") + what + " cannot be read as float");
    }
    for (int c = 0; c < 3; ++c) {
      if (!std::isfinite(v[c])) {
        throw InputError(where, std::string("MESH ") + what + " of vertex " + std::to_string(i) +
                                    " is not finite");
      }
      out[std::size_t(i) * 3 + std::size_t(c)] = v[c];
    }
  }
}

}  // namespace

std::vector<uint8_t> EncodeMeshDraco(const TriangleMesh& mesh, int position_bits, int normal_bits,
                                     const std::string& name) {
  const std::size_t nv = mesh.positions.size();
  if (nv == 0) throw InputError(name, "mesh has no vertices");
  if (nv > kMaxPoints) throw InputError(name, "mesh has more than 2^31 vertices");
  if (mesh.normals.size() != nv) {
    throw InputError(name, "mesh has " + std::to_string(mesh.normals.size()) + " normals for " +
                               std::to_string(nv) + " vertices");
  }
  if (mesh.triangles.size() > std::numeric_limits<uint32_t>::max() / 3) {
    throw InputError(name, "mesh has too many triangles");
  }
  if (position_bits < 1 || position_bits > 30 || normal_bits < 2 || normal_bits > 30) {
    throw InputError(name, "quantisation bits out of range (positions 1..30, normals 2..30)");
  }
  for (std::size_t i = 0; i < nv; ++i) {
    if (!IsFinite(mesh.positions[i]) || !IsFinite(mesh.normals[i])) {
      throw InputError(name, "vertex " + std::to_string(i) + " is not finite");
    }
  }
  draco::Mesh dm;
  dm.set_num_points(static_cast<uint32_t>(nv));
  const int pos_id = AddFloatAttribute(dm, draco::GeometryAttribute::POSITION, mesh.positions);
  const int nrm_id = AddFloatAttribute(dm, draco::GeometryAttribute::NORMAL, mesh.normals);
  dm.SetNumFaces(mesh.triangles.size());
  for (std::size_t f = 0; f < mesh.triangles.size(); ++f) {
    draco::Mesh::Face face;
    for (int c = 0; c < 3; ++c) {
      const uint32_t idx = mesh.triangles[f][static_cast<std::size_t>(c)];
      if (idx >= nv) {
        throw InputError(name, "triangle " + std::to_string(f) + " refers to vertex " +
                                   std::to_string(idx) + " of " + std::to_string(nv));
      }
      face[c] = draco::PointIndex(idx);
    }
    dm.SetFace(draco::FaceIndex(static_cast<uint32_t>(f)), face);
  }
  draco::ExpertEncoder encoder(dm);
  encoder.SetEncodingMethod(draco::MESH_SEQUENTIAL_ENCODING);
  encoder.SetSpeedOptions(5, 5);
  encoder.SetAttributeQuantization(pos_id, position_bits);
  encoder.SetAttributeQuantization(nrm_id, normal_bits);
  draco::EncoderBuffer buffer;
  const draco::Status status = encoder.EncodeToBuffer(&buffer);
  if (!status.ok()) throw InputError(name, "Draco encoding failed: " + status.error_msg_string());
  return std::vector<uint8_t>(buffer.data(), buffer.data() + buffer.size());
}

DracoMeshCounts PeekDracoMeshCounts(const uint8_t* data, std::size_t size,
                                    const std::string& where) {
  // Draco header: "DRACO", major, minor, encoder type (1 = mesh), method (0 = sequential),
  // u16 flags; then varint num_faces, varint num_points (bitstream 2.2).
  if (size < 11 || std::memcmp(data, "DRACO", 5) != 0) {
    throw InputError(where, "MESH payload is not a Draco bitstream");
  }
  if (data[5] != 2 || data[6] != 2) {
    throw InputError(where, "MESH Draco bitstream version " + std::to_string(data[5]) + "." +
                                std::to_string(data[6]) + " is not 2.2");
  }
  if (data[7] != 1 || data[8] != 0) {
    throw InputError(where, "MESH is not a sequentially encoded Draco triangle mesh");
  }
  if (data[9] != 0 || data[10] != 0) throw InputError(where, "MESH Draco flags must be 0");
  const auto truncated = [&where] {
    return InputError(where, "MESH Draco connectivity header is truncated");
  };
  ByteReader in(
      std::span<const uint8_t>(data, size), [&](const char*, std::size_t) { throw truncated(); },
      11);
  const std::optional<uint32_t> faces = in.GetVarint<uint32_t>("faces");
  const std::optional<uint32_t> points = faces ? in.GetVarint<uint32_t>("points") : std::nullopt;
  if (!faces || !points) throw truncated();  // a varint longer than 5 bytes or ≥ 2^32
  DracoMeshCounts counts;
  counts.faces = *faces;
  counts.points = *points;
  if (counts.points == 0 || counts.points > kMaxPoints) {
    throw InputError(where, "MESH declares " + std::to_string(counts.points) + " vertices");
  }
  return counts;
}

MeshArrays DecodeMeshDraco(const uint8_t* data, std::size_t size, const DracoMeshCounts& expected,
                           const std::string& where) {
  draco::DecoderBuffer buffer;
  buffer.Init(reinterpret_cast<const char*>(data), size);
  draco::Decoder decoder;
  auto result = decoder.DecodeMeshFromBuffer(&buffer);
  if (!result.ok()) {
    throw InputError(where, "MESH Draco decoding failed: " + result.status().error_msg_string());
  }
  const std::unique_ptr<draco::Mesh> dm = std::move(result).value();
  if (dm == nullptr || dm->num_points() != expected.points || dm->num_faces() != expected.faces) {
    throw InputError(where, "MESH decoded counts differ from its header");
  }
  MeshArrays out;
  ExtractAttribute(*dm, draco::GeometryAttribute::POSITION, "position", out.positions, where);
  ExtractAttribute(*dm, draco::GeometryAttribute::NORMAL, "normal", out.normals, where);
  out.triangles.resize(std::size_t(expected.faces) * 3);
  for (uint32_t f = 0; f < expected.faces; ++f) {
    const draco::Mesh::Face& face = dm->face(draco::FaceIndex(f));
    for (int c = 0; c < 3; ++c) {
      const uint32_t idx = face[c].value();
      if (idx >= expected.points) {
        throw InputError(where, "MESH triangle " + std::to_string(f) + " index out of range");
      }
      out.triangles[std::size_t(f) * 3 + std::size_t(c)] = idx;
    }
  }
  return out;
}

}  // namespace prt::pack
