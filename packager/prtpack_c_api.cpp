// The C interface of prtpack.h over PackReader: every entry point catches every exception and
// turns it into PRTPACK_ERROR (or NULL) plus a thread-local message.
#include <cstring>
#include <exception>
#include <memory>
#include <new>
#include <optional>
#include <string>
#include <vector>

#include "formats/cpca_transport.h"
#include "packager/prtpack.h"
#include "packager/prtpack_reader.h"

namespace {

// A CPCA transport with its dequantised arrays, built once per handle.
struct CpcaArrays {
  prt::CpcaTransport t;
  std::vector<float> coefficients;  // rows × S
  // Per cluster k: its mean's values at [k·(S + 1)], basis vector i's at [k·(S + 1) + 1 + i].
  std::vector<std::vector<float>> values;

  explicit CpcaArrays(prt::CpcaTransport transport) : t(std::move(transport)) {
    const std::size_t S = t.bases();
    coefficients.resize(t.row_count() * S);
    for (std::size_t r = 0; r < t.row_count(); ++r)
      for (std::size_t i = 0; i < S; ++i) coefficients[r * S + i] = t.Coefficient(r, i);
    values.reserve(t.clusters.size() * (S + 1));
    auto dequantise = [&](const prt::CpcaVector& v) {
      std::vector<float> out(v.term_count());
      for (std::size_t k = 0; k < out.size(); ++k) out[k] = t.Value(v, k);
      values.push_back(std::move(out));
    };
    for (const prt::CpcaCluster& c : t.clusters) {
      dequantise(c.mean);
      for (const prt::CpcaVector& v : c.basis) dequantise(v);
    }
  }
};

}  // namespace

struct prtpack {
  explicit prtpack(prt::pack::PackReader r) : reader(std::move(r)) {}
  prt::pack::PackReader reader;
  std::vector<std::unique_ptr<prt::pack::UnpackedMesh>> meshes;
  std::optional<std::string> metadata;
  std::optional<prt::pack::TransportIndex> transport;
  std::optional<prt::ImageSamplesInfo> image;
  std::unique_ptr<CpcaArrays> cpca;
};

namespace {

thread_local std::string g_last_error;

int Fail(const std::string& message) {
  g_last_error = message.empty() ? "unknown error" : message;
  return PRTPACK_ERROR;
}

// Runs f, mapping any exception to PRTPACK_ERROR with its message.
template <typename F>
int Guard(F&& f) {
  g_last_error.clear();
  try {
    return f();
  } catch (const std::bad_alloc&) {
    return Fail("out of memory");
  } catch (const std::exception& e) {
    return Fail(e.what());
  } catch (...) {
    return Fail("unknown error");
  }
}

const prt::pack::TransportIndex& Transport(prtpack* p) {
  if (!p->transport) p->transport = p->reader.ReadTransportIndex();
  return *p->transport;
}

const CpcaArrays& Cpca(prtpack* p) {
  if (!p->cpca) p->cpca = std::make_unique<CpcaArrays>(p->reader.ReadCpcaTransport());
  return *p->cpca;
}

// Vector `v` (0 the mean, 1 + i basis vector i) of cluster `cluster`, range-checked.
int CpcaVectorOf(prtpack* pack, size_t cluster, size_t v, prtpack_cpca_vector* out,
                 const char* function) {
  if (pack == nullptr || out == nullptr) return Fail(std::string(function) + ": NULL argument");
  const CpcaArrays& a = Cpca(pack);
  if (cluster >= a.t.clusters.size()) {
    return Fail(pack->reader.name() + ": CPCA cluster " + std::to_string(cluster) +
                " out of range (" + std::to_string(a.t.clusters.size()) + " clusters)");
  }
  const std::size_t S = a.t.bases();
  const prt::CpcaCluster& c = a.t.clusters[cluster];
  const prt::CpcaVector& vec = v == 0 ? c.mean : c.basis[v - 1];
  const std::vector<float>& values = a.values[cluster * (S + 1) + v];
  out->term_count = vec.term_count();
  out->index = vec.index.empty() ? nullptr : vec.index.data();
  out->value = values.empty() ? nullptr : values.data();
  return PRTPACK_OK;
}

}  // namespace

extern "C" {

const char* prtpack_last_error(void) {
  return g_last_error.c_str();
}

prtpack* prtpack_open_file(const char* path) {
  prtpack* out = nullptr;
  Guard([&] {
    if (path == nullptr) return Fail("prtpack_open_file: path is NULL");
    out = new prtpack(prt::pack::PackReader::OpenFile(path));
    return PRTPACK_OK;
  });
  return out;
}

prtpack* prtpack_open_memory(const void* data, size_t size) {
  prtpack* out = nullptr;
  Guard([&] {
    if (data == nullptr && size > 0) return Fail("prtpack_open_memory: data is NULL");
    out = new prtpack(prt::pack::PackReader::OpenMemory(data, size));
    return PRTPACK_OK;
  });
  return out;
}

void prtpack_close(prtpack* pack) {
  delete pack;
}

int prtpack_version(const prtpack* pack, uint32_t* major, uint32_t* minor) {
  return Guard([&] {
    if (pack == nullptr) return Fail("prtpack_version: pack is NULL");
    if (major) *major = pack->reader.version_major();
    if (minor) *minor = pack->reader.version_minor();
    return PRTPACK_OK;
  });
}

size_t prtpack_section_count(const prtpack* pack) {
  return pack == nullptr ? 0 : pack->reader.sections().size();
}

int prtpack_get_section_info(const prtpack* pack, size_t index, prtpack_section_info* out) {
  return Guard([&] {
    if (pack == nullptr || out == nullptr) return Fail("prtpack_get_section_info: NULL argument");
    const auto& sections = pack->reader.sections();
    if (index >= sections.size()) {
      return Fail(pack->reader.name() + ": section " + std::to_string(index) + " out of range");
    }
    const prt::pack::SectionInfo& s = sections[index];
    std::memcpy(out->type, s.type.c_str(), 4);
    out->type[4] = '\0';
    out->flags = s.flags;
    out->codec = s.codec;
    out->id = s.id;
    out->offset = s.offset;
    out->stored_size = s.stored_size;
    out->raw_size = s.raw_size;
    out->checksum = s.checksum;
    out->known = s.known ? 1 : 0;
    return PRTPACK_OK;
  });
}

size_t prtpack_mesh_count(const prtpack* pack) {
  return pack == nullptr ? 0 : pack->reader.mesh_count();
}

int prtpack_get_mesh(prtpack* pack, size_t index, prtpack_mesh* out) {
  return Guard([&] {
    if (pack == nullptr || out == nullptr) return Fail("prtpack_get_mesh: NULL argument");
    if (index >= pack->reader.mesh_count()) {
      return Fail(pack->reader.name() + ": mesh " + std::to_string(index) + " out of range");
    }
    if (pack->meshes.size() < pack->reader.mesh_count()) {
      pack->meshes.resize(pack->reader.mesh_count());
    }
    auto& slot = pack->meshes[index];
    if (!slot) slot = std::make_unique<prt::pack::UnpackedMesh>(pack->reader.ReadMesh(index));
    const prt::pack::UnpackedMesh& m = *slot;
    out->name = m.name.c_str();
    out->vertex_count = m.vertex_count();
    out->triangle_count = m.triangle_count();
    out->positions = m.positions.data();
    out->normals = m.normals.data();
    out->triangles = m.triangles.data();
    for (int c = 0; c < 3; ++c) out->albedo[c] = m.albedo[static_cast<std::size_t>(c)];
    out->is_ground = m.is_ground ? 1 : 0;
    out->grid_resolution = m.grid_resolution;
    return PRTPACK_OK;
  });
}

int prtpack_get_albedo(prtpack* pack, size_t index, float rgb[3]) {
  return Guard([&] {
    if (pack == nullptr || rgb == nullptr) return Fail("prtpack_get_albedo: NULL argument");
    const prt::pack::MeshMaterial m = pack->reader.ReadMaterial(index);
    for (int c = 0; c < 3; ++c) rgb[c] = m.albedo[static_cast<std::size_t>(c)];
    return PRTPACK_OK;
  });
}

int prtpack_get_metadata(prtpack* pack, const char** json, size_t* length) {
  return Guard([&] {
    if (pack == nullptr || json == nullptr) return Fail("prtpack_get_metadata: NULL argument");
    if (!pack->metadata) pack->metadata = pack->reader.ReadMetadata();
    *json = pack->metadata->c_str();
    if (length) *length = pack->metadata->size();
    return PRTPACK_OK;
  });
}

int prtpack_has_image(const prtpack* pack) {
  return pack != nullptr && pack->reader.has_image() ? 1 : 0;
}

int prtpack_get_image(prtpack* pack, prtpack_image_info* out) {
  return Guard([&] {
    if (pack == nullptr || out == nullptr) return Fail("prtpack_get_image: NULL argument");
    if (!pack->image) pack->image = pack->reader.ReadImage();
    const prt::ImageSamplesInfo& im = *pack->image;
    out->width = static_cast<uint32_t>(im.camera.width);
    out->height = static_cast<uint32_t>(im.camera.height);
    for (int i = 0; i < 3; ++i) {
      out->eye[i] = im.camera.eye[i];
      out->target[i] = im.camera.target[i];
      out->up[i] = im.camera.up[i];
    }
    out->fov_deg = im.camera.fov_deg;
    out->pixel_mesh = im.pixel_mesh.data();
    return PRTPACK_OK;
  });
}

int prtpack_get_image_weight(prtpack* pack, size_t mesh, int* glossy, float rgb[3]) {
  return Guard([&] {
    if (pack == nullptr || glossy == nullptr || rgb == nullptr)
      return Fail("prtpack_get_image_weight: NULL argument");
    if (!pack->image) pack->image = pack->reader.ReadImage();
    const prt::ImageSamplesInfo& im = *pack->image;
    if (mesh < im.glossy_mesh.size() && im.glossy_mesh[mesh]) {
      *glossy = 1;
      for (int c = 0; c < 3; ++c) rgb[c] = im.glossy_weight[mesh][static_cast<std::size_t>(c)];
      return PRTPACK_OK;
    }
    const prt::pack::MeshMaterial m = pack->reader.ReadMaterial(mesh);
    *glossy = 0;
    for (int c = 0; c < 3; ++c) rgb[c] = m.albedo[static_cast<std::size_t>(c)];
    return PRTPACK_OK;
  });
}

int prtpack_get_image_supersample(prtpack* pack, int* supersample) {
  return Guard([&] {
    if (pack == nullptr || supersample == nullptr)
      return Fail("prtpack_get_image_supersample: NULL argument");
    if (!pack->image) pack->image = pack->reader.ReadImage();
    *supersample = pack->image->supersample;
    return PRTPACK_OK;
  });
}

int prtpack_get_image_pixel(prtpack* pack, size_t pixel, float rgb[3], float* coverage) {
  return Guard([&] {
    if (pack == nullptr || rgb == nullptr || coverage == nullptr)
      return Fail("prtpack_get_image_pixel: NULL argument");
    if (!pack->image) pack->image = pack->reader.ReadImage();
    const prt::ImageSamplesInfo& im = *pack->image;
    if (pixel >= im.pixel_mesh.size())
      return Fail("prtpack_get_image_pixel: pixel " + std::to_string(pixel) + " of " +
                  std::to_string(im.pixel_mesh.size()));
    if (im.supersample > 1) {
      *coverage = im.coverage[pixel];
      for (int c = 0; c < 3; ++c) rgb[c] = im.pixel_weight[pixel][static_cast<std::size_t>(c)];
      return PRTPACK_OK;
    }
    const uint32_t m = im.pixel_mesh[pixel];
    if (m == prt::kImageBackground) {
      *coverage = 0.f;
      for (int c = 0; c < 3; ++c) rgb[c] = 0.f;
      return PRTPACK_OK;
    }
    *coverage = 1.f;
    int glossy = 0;
    return prtpack_get_image_weight(pack, m, &glossy, rgb);
  });
}

int prtpack_get_transport_info(prtpack* pack, prtpack_transport_info* out) {
  return Guard([&] {
    if (pack == nullptr || out == nullptr) return Fail("prtpack_get_transport_info: NULL argument");
    const prt::pack::TransportIndex& t = Transport(pack);
    out->encoding = t.encoding;
    out->row_count = t.row_count;
    out->column_count = t.column_count;
    out->block_count = t.blocks.size();
    out->params = t.params.data();
    out->params_size = t.params.size();
    out->channels = t.channels;
    return PRTPACK_OK;
  });
}

int prtpack_get_block_info(prtpack* pack, size_t block, prtpack_block_info* out) {
  return Guard([&] {
    if (pack == nullptr || out == nullptr) return Fail("prtpack_get_block_info: NULL argument");
    const prt::pack::TransportIndex& t = Transport(pack);
    if (block >= t.blocks.size()) {
      return Fail(pack->reader.name() + ": transport block " + std::to_string(block) +
                  " out of range");
    }
    out->first_column = t.blocks[block].first_column;
    out->column_count = t.blocks[block].column_count;
    out->raw_size = t.blocks[block].raw_size;
    return PRTPACK_OK;
  });
}

int prtpack_get_transport_block(prtpack* pack, size_t block, void* dst, size_t dst_size) {
  return Guard([&] {
    if (pack == nullptr || (dst == nullptr && dst_size > 0)) {
      return Fail("prtpack_get_transport_block: NULL argument");
    }
    pack->reader.ReadTransportBlockInto(Transport(pack), block, dst, dst_size);
    return PRTPACK_OK;
  });
}

int prtpack_transport_kind(const prtpack* pack) {
  if (pack == nullptr) return PRTPACK_TRANSPORT_NONE;
  if (pack->reader.has_cpca()) return PRTPACK_TRANSPORT_CPCA;
  return pack->reader.has_transport() ? PRTPACK_TRANSPORT_COLUMNS : PRTPACK_TRANSPORT_NONE;
}

int prtpack_get_cpca_info(prtpack* pack, prtpack_cpca_info* out) {
  return Guard([&] {
    if (pack == nullptr || out == nullptr) return Fail("prtpack_get_cpca_info: NULL argument");
    const CpcaArrays& a = Cpca(pack);
    const prt::CompressedTransportHeader& h = a.t.header;
    out->row_count = h.sample_count;
    out->channels = h.channels;
    out->cubemap_n = h.cubemap_n;
    out->column_count = h.column_count();
    out->row_wavelet = static_cast<uint32_t>(h.row_wavelet);
    out->cluster_count = h.cpca_clusters;
    out->basis_count = h.cpca_bases;
    out->term_count = a.t.term_count();
    out->cluster_of = a.t.cluster_of.data();
    out->coefficients = a.coefficients.empty() ? nullptr : a.coefficients.data();
    return PRTPACK_OK;
  });
}

int prtpack_get_cpca_mean(prtpack* pack, size_t cluster, prtpack_cpca_vector* out) {
  return Guard([&] { return CpcaVectorOf(pack, cluster, 0, out, "prtpack_get_cpca_mean"); });
}

int prtpack_get_cpca_basis(prtpack* pack, size_t cluster, size_t basis, prtpack_cpca_vector* out) {
  return Guard([&] {
    if (pack == nullptr || out == nullptr) return Fail("prtpack_get_cpca_basis: NULL argument");
    const std::size_t S = Cpca(pack).t.bases();
    if (basis >= S) {
      return Fail(pack->reader.name() + ": CPCA basis vector " + std::to_string(basis) +
                  " out of range (" + std::to_string(S) + " per cluster)");
    }
    return CpcaVectorOf(pack, cluster, 1 + basis, out, "prtpack_get_cpca_basis");
  });
}

int prtpack_verify(prtpack* pack) {
  return Guard([&] {
    if (pack == nullptr) return Fail("prtpack_verify: pack is NULL");
    pack->reader.VerifyAll();
    return PRTPACK_OK;
  });
}

}  // extern "C"
