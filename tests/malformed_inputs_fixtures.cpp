// The malformed-input fixtures (malformed_inputs_fixtures.h). Each file below is a small valid
// file with one defect; the comment beside it names the defect the catalogue expects to be
// reported.
#include "tests/malformed_inputs_fixtures.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <stdexcept>
#include <vector>

#include "vocabulary/environment_io.h"
#include "vocabulary/envmap.h"

namespace prt::testing {
namespace {

namespace fs = std::filesystem;

void WriteBytes(const fs::path& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  if (!out) throw std::runtime_error("cannot write fixture " + path.string());
}

std::string ReadBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

template <typename T>
void Put(std::string& s, T v, bool big_endian = false) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  if (big_endian) std::reverse(b, b + sizeof(T));
  s.append(b, sizeof(T));
}

// A unit square: 4 vertices, 2 triangles, in every format.
constexpr float kSquare[4][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};

std::string PlyHeader(const std::string& format, int vertices, int faces) {
  return "ply\nformat " + format + " 1.0\nelement vertex " + std::to_string(vertices) +
         "\nproperty float x\nproperty float y\nproperty float z\nelement face " +
         std::to_string(faces) + "\nproperty list uchar int vertex_indices\nend_header\n";
}

// Binary PLY body of the square; `index` replaces the last face's last index.
std::string PlyBinaryBody(bool big_endian, int32_t last_index = 3) {
  std::string s;
  for (const auto& v : kSquare)
    for (float c : v) Put(s, c, big_endian);
  const int32_t faces[2][3] = {{0, 1, 2}, {0, 2, last_index}};
  for (const auto& f : faces) {
    Put<uint8_t>(s, 3);
    for (int32_t i : f) Put(s, i, big_endian);
  }
  return s;
}

// Binary STL of the square's two triangles (84 + 2·50 bytes); `count` overrides the header.
std::string BinaryStl(uint32_t count = 2, float first_x = 0.0f) {
  std::string s(80, ' ');
  s.replace(0, 14, "binary fixture");
  Put(s, count);
  const int tris[2][3] = {{0, 1, 2}, {0, 2, 3}};
  for (const auto& t : tris) {
    for (int k = 0; k < 3; ++k) Put(s, k == 2 ? 1.0f : 0.0f);  // facet normal
    for (int c : t)
      for (int k = 0; k < 3; ++k)
        Put(s, (&t == &tris[0] && c == 0 && k == 0) ? first_x : kSquare[c][k]);
    Put<uint16_t>(s, 0);
  }
  return s;
}

void WriteMeshes(const fs::path& d) {
  const std::string off = "OFF\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n";
  WriteBytes(d / "ok_square.off", off);
  // OFF
  WriteBytes(d / "off_truncated_vertices.off", "OFF\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n");
  WriteBytes(d / "off_truncated_faces.off", "OFF\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n");
  WriteBytes(d / "off_bad_keyword.off", "4OFF\n4 2 0\n0 0 0 1\n");
  WriteBytes(d / "off_index_out_of_range.off",
             "OFF\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 7\n");
  WriteBytes(d / "off_negative_count.off", "OFF\n-4 2 0\n0 0 0\n");
  WriteBytes(d / "off_huge_counts.off", "OFF\n2000000000 2000000000 0\n0 0 0\n");
  WriteBytes(d / "off_nan_vertex.off",
             "OFF\n4 2 0\n0 0 0\n1 0 0\nnan 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n");
  WriteBytes(d / "off_huge_face_arity.off",
             "OFF\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n1000000000 0 1 2\n");
  WriteBytes(d / "off_garbage_number.off",
             "OFF\n4 2 0\n0 0 0\n1 0x 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n");
  WriteBytes(d / "off_empty.off", "");
  // PLY ascii
  WriteBytes(d / "ply_ascii_truncated.ply", PlyHeader("ascii", 4, 2) + "0 0 0\n1 0 0\n");
  WriteBytes(d / "ply_ascii_bad_number.ply",
             PlyHeader("ascii", 4, 2) + "0 0 0\n1 zero 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n");
  WriteBytes(d / "ply_ascii_index_out_of_range.ply",
             PlyHeader("ascii", 4, 2) + "0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 9\n");
  WriteBytes(d / "ply_no_end_header.ply",
             "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\n");
  WriteBytes(d / "ply_unknown_format.ply",
             "ply\nformat binary_middle_endian 1.0\nelement vertex 0\nend_header\n");
  WriteBytes(d / "ply_no_xyz.ply",
             "ply\nformat ascii 1.0\nelement vertex 1\nproperty float a\nend_header\n0\n");
  WriteBytes(d / "ply_not_ply.ply", std::string("\x89PNG\r\n\x1a\n\0\0\0\rIHDR", 16));
  WriteBytes(d / "ply_empty.ply", "");
  // PLY binary
  const std::string le = PlyHeader("binary_little_endian", 4, 2);
  const std::string be = PlyHeader("binary_big_endian", 4, 2);
  WriteBytes(d / "plyb_truncated_vertices.ply", le + PlyBinaryBody(false).substr(0, 30));
  WriteBytes(d / "plyb_truncated_faces.ply",
             le + PlyBinaryBody(false).substr(0, PlyBinaryBody(false).size() - 5));
  WriteBytes(d / "plyb_index_out_of_range.ply", le + PlyBinaryBody(false, 1000));
  WriteBytes(d / "plyb_negative_index.ply", le + PlyBinaryBody(false, -2));
  WriteBytes(d / "plyb_huge_vertex_count.ply",
             PlyHeader("binary_little_endian", 2000000000, 2) + PlyBinaryBody(false));
  WriteBytes(d / "plyb_be_truncated.ply", be + PlyBinaryBody(true).substr(0, 47));
  {
    std::string body = PlyBinaryBody(false);
    body[48] = static_cast<char>(255);  // the first face's list count: 255 indices, 33 bytes left
    WriteBytes(d / "plyb_list_count_overflow.ply", le + body);
  }
  {
    std::string body = PlyBinaryBody(false);
    const float inf = std::numeric_limits<float>::infinity();
    std::memcpy(body.data() + 4, &inf, 4);  // vertex 0's y
    WriteBytes(d / "plyb_inf_vertex.ply", le + body);
  }
  // OBJ
  WriteBytes(d / "obj_short_vertex.obj", "v 0 0 0\nv 1 0\nv 1 1 0\nf 1 2 3\n");
  WriteBytes(d / "obj_index_out_of_range.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 9\n");
  WriteBytes(d / "obj_zero_index.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 0 1 2\n");
  WriteBytes(d / "obj_bad_index_token.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 x 3\n");
  WriteBytes(d / "obj_beyond_float32.obj", "v 0 0 0\nv 1e39 0 0\nv 1 1 0\nf 1 2 3\n");
  WriteBytes(d / "obj_no_faces.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\n");
  WriteBytes(d / "obj_truncated.obj", "v 0 0 0\nv 1 0 0\nv 1 1");
  WriteBytes(d / "obj_binary_garbage.obj", std::string("\0\x01\x02v\0f\xff\xfe", 9));
  // STL
  WriteBytes(d / "stlb_truncated.stl", BinaryStl().substr(0, 84 + 50 + 20));
  WriteBytes(d / "stlb_huge_count.stl", BinaryStl(0xFFFFFFFFu).substr(0, 84));
  WriteBytes(d / "stlb_short_header.stl", std::string(50, 'x'));
  WriteBytes(d / "stlb_nan_vertex.stl", BinaryStl(2, std::numeric_limits<float>::quiet_NaN()));
  const std::string stl_facet =
      "facet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 1 1 0\nendloop\n"
      "endfacet\n";
  WriteBytes(d / "stla_truncated.stl",
             "solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0");
  WriteBytes(d / "stla_bad_number.stl",
             "solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex a b c\nvertex 1 1 0\n"
             "endloop\nendfacet\nendsolid s\n");
  WriteBytes(d / "stla_missing_endloop.stl",
             "solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 1 1 0\n"
             "endfacet\nendsolid s\n");
  WriteBytes(d / "stla_no_endsolid.stl", "solid s\n" + stl_facet);
  // Neither format nor file.
  WriteBytes(d / "square.3ds", off);
  fs::create_directories(d / "folder.off");
}

EnvironmentImage SmallSky(int width, int height) {
  EnvironmentImage img = EnvironmentImage::Zero(EnvmapLayout::kLatLong, width, height);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      const std::size_t i = img.Index(x, y);
      img.r[i] = 0.5f + 0.5f * float(y) / float(height);
      img.g[i] = 0.6f;
      img.b[i] = 1.0f + 0.1f * float(x);
    }
  return img;
}

// The offset of the byte after a single-part scanline EXR header: magic and version (8 bytes),
// then attributes (name, NUL, type, NUL, int32 size, value) until an empty name.
std::size_t ExrHeaderEnd(const std::string& exr) {
  std::size_t at = 8;
  while (at < exr.size() && exr[at] != '\0') {
    at = exr.find('\0', at) + 1;  // name
    at = exr.find('\0', at) + 1;  // type
    int32_t size = 0;
    std::memcpy(&size, exr.data() + at, 4);
    at += 4 + static_cast<std::size_t>(size);
  }
  return at + 1;
}

void WriteEnvironments(const fs::path& d) {
  WriteEnvironmentExr(SmallSky(32, 16), (d / "ok_sky.exr").string());
  WriteRadianceHdr(SmallSky(32, 16), (d / "ok_sky.hdr").string(), true);
  const std::string exr = ReadBytes(d / "ok_sky.exr");
  const std::string hdr = ReadBytes(d / "ok_sky.hdr");
  // EXR
  WriteBytes(d / "exr_truncated_pixels.exr", exr.substr(0, exr.size() * 3 / 4));
  WriteBytes(d / "exr_truncated_header.exr", exr.substr(0, 40));
  {
    std::string bad = exr;
    bad[0] = 'X';  // magic 76 2f 31 01
    WriteBytes(d / "exr_bad_magic.exr", bad);
  }
  {
    // The line offset table follows the header: set its first 8 entries to 0xff… (offsets far
    // past the end of the file).
    std::string bad = exr;
    const std::size_t table = ExrHeaderEnd(exr);
    for (std::size_t i = table; i < table + 64 && i < bad.size(); ++i) bad[i] = '\xff';
    WriteBytes(d / "exr_corrupt_offsets.exr", bad);
  }
  {
    std::string bad = exr;
    const std::size_t table = ExrHeaderEnd(exr);
    for (std::size_t i = table + 200; i < bad.size(); i += 7) bad[i] = static_cast<char>(i * 131);
    WriteBytes(d / "exr_corrupt_pixels.exr", bad);
  }
  {
    EnvironmentImage nan = SmallSky(32, 16);
    nan.g[nan.Index(5, 3)] = std::numeric_limits<float>::quiet_NaN();
    WriteEnvironmentExr(nan, (d / "exr_nan_pixel.exr").string());
  }
  WriteRadianceHdr(SmallSky(30, 16), (d / "hdr_wrong_shape.hdr").string(), true);  // 15:8
  WriteBytes(d / "exr_empty.exr", "");
  // HDR
  WriteBytes(d / "hdr_truncated.hdr", hdr.substr(0, hdr.size() / 2));
  WriteBytes(d / "hdr_no_magic.hdr", "RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 16 +X 32\n");
  WriteBytes(d / "hdr_bad_format.hdr", "#?RADIANCE\nFORMAT=32-bit_rle_xyze\n\n-Y 16 +X 32\n");
  WriteBytes(d / "hdr_bad_resolution.hdr",
             "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y sixteen +X 32\n");
  WriteBytes(d / "hdr_no_resolution.hdr", "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n");
  WriteBytes(d / "hdr_huge_resolution.hdr",
             "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 1000000 +X 2000000\n\x02\x02\x80\x80");
  {
    // A new-RLE scanline whose first run claims 127 literal pixels of a 32-pixel line.
    std::string rle = "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 16 +X 32\n";
    rle += std::string("\x02\x02\x00\x20", 4);
    rle += std::string("\x7f", 1) + std::string(127, '\x40');
    WriteBytes(d / "hdr_rle_overflow.hdr", rle);
  }
  WriteBytes(d / "hdr_empty.hdr", "");
  WriteBytes(d / "not_an_image.png", "just text, not an environment\n");
}

}  // namespace

std::string TinySceneWith(const std::string& find, const std::string& replace) {
  std::string s =
      "[scene]\nname = \"tiny\"\nn = 8\n\n"
      "[[mesh]]\nname = \"box\"\npath = \"box.off\"\nalbedo = [0.5, 0.5, 0.5]\n\n"
      "[ground]\nenabled = true\nsize = 3.0\nresolution = 8\n\n"
      "[sampling]\nrays_per_texel = 4\nseed = 3\nmethod = \"brute\"\n";
  if (find.empty()) return s + replace;
  const std::size_t at = s.find(find);
  if (at == std::string::npos) throw std::logic_error("TinySceneWith: '" + find + "' not found");
  return s.replace(at, find.size(), replace);
}

void WriteMalformedFixtures(const fs::path& dir, const fs::path& box_off) {
  fs::create_directories(dir);
  fs::copy_file(box_off, dir / "box.off", fs::copy_options::overwrite_existing);
  WriteMeshes(dir);
  WriteEnvironments(dir);
}

}  // namespace prt::testing
