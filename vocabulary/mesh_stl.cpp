// The STL reader (binary and ascii) (docs/mesh-import.md); strict and order-preserving, safe on
// untrusted input (see mesh.cpp).
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "vocabulary/bytes.h"
#include "vocabulary/mesh_formats.h"

namespace prt::mesh_import {

// ---------------------------------------------------------------------------------------------
// STL. Binary: 80-byte header, uint32 triangle count, 50 bytes per triangle (normal, 3 corners,
// attribute), little endian. Ascii: solid / facet normal / outer loop / vertex… / endloop /
// endfacet / endsolid. Either way a triangle soup: corners with exactly equal coordinates
// (float32, −0 = +0) are welded into one vertex, numbered in order of first appearance.

struct WeldKey {
  uint32_t x, y, z;
  bool operator==(const WeldKey&) const = default;
};
struct WeldHash {
  std::size_t operator()(const WeldKey& k) const {
    uint64_t h = k.x * 0x9E3779B97F4A7C15ull;
    h ^= (k.y + 0x632BE59BD9B4E019ull + (h << 6) + (h >> 2));
    h ^= (k.z + 0x85EBCA77C2B2AE63ull + (h << 6) + (h >> 2));
    return static_cast<std::size_t>(h);
  }
};

class Welder {
 public:
  explicit Welder(RawMesh& raw) : raw_(raw) {}
  uint32_t Add(float x, float y, float z) {
    x += 0.0f;  // −0 → +0
    y += 0.0f;
    z += 0.0f;
    const WeldKey k{std::bit_cast<uint32_t>(x), std::bit_cast<uint32_t>(y),
                    std::bit_cast<uint32_t>(z)};
    ++corners_;
    const auto [it, inserted] = map_.try_emplace(k, static_cast<uint32_t>(raw_.positions.size()));
    if (inserted) raw_.positions.push_back({x, y, z});
    return it->second;
  }
  void Finish() {
    raw_.report.file_vertices = corners_;
    raw_.report.welded_vertices = corners_ - raw_.positions.size();
  }

 private:
  RawMesh& raw_;
  std::unordered_map<WeldKey, uint32_t, WeldHash> map_;
  std::size_t corners_ = 0;
};

RawMesh ReadStlBinary(std::string_view bytes, const std::string& name, uint32_t count) {
  RawMesh raw;
  raw.report.format = "stl-binary";
  Welder welder(raw);
  raw.triangles.reserve(count);
  // ReadStl checked that 84 + 50 · count bytes are there: no read below runs out.
  ByteReader in(
      bytes,
      [&name](const char* what, std::size_t at) {
        throw InputError(name,
                         std::string("truncated: ") + what + " at byte " + std::to_string(at));
      },
      84);
  for (uint32_t t = 0; t < count; ++t) {
    in.Skip(12, "triangle normal");
    uint32_t idx[3];
    for (int c = 0; c < 3; ++c) {
      float xyz[3];
      for (float& x : xyz) {
        x = in.Get<float>("triangle corner");
        if (!std::isfinite(x)) {
          throw InputError(name, "triangle " + std::to_string(t) + " of " + std::to_string(count) +
                                     ": corner " + std::to_string(c) + " is not finite");
        }
      }
      idx[c] = welder.Add(xyz[0], xyz[1], xyz[2]);
    }
    in.Skip(2, "triangle attribute");
    AddPolygon(raw, idx, 3);
  }
  welder.Finish();
  return raw;
}

RawMesh ReadStlAscii(std::string_view text, const std::string& name) {
  RawMesh raw;
  raw.report.format = "stl-ascii";
  Welder welder(raw);
  TokenReader tokens(text, 1);
  std::string_view tok;
  auto expect = [&](std::string_view want) {
    if (!tokens.Next(tok)) {
      FailLine(name, tokens.line(), "truncated: expected '" + std::string(want) + "'");
    }
    if (tok != want) {
      FailLine(name, tokens.line(),
               "expected '" + std::string(want) + "', found '" + std::string(tok) + "'");
    }
  };
  std::vector<uint32_t> idx;
  bool in_solid = false;
  while (tokens.Next(tok)) {
    if (tok == "solid") {
      tokens.SkipRestOfLine();  // the solid's name
      in_solid = true;
    } else if (tok == "endsolid") {
      tokens.SkipRestOfLine();
      in_solid = false;
    } else if (tok == "facet" && in_solid) {
      expect("normal");
      for (int k = 0; k < 3; ++k) {
        double v;
        if (!tokens.Next(tok) || !ParseDouble(tok, v)) {
          FailLine(name, tokens.line(), "facet normal needs 3 numbers");
        }
      }
      expect("outer");
      expect("loop");
      idx.clear();
      while (true) {
        if (!tokens.Next(tok)) FailLine(name, tokens.line(), "truncated: expected 'endloop'");
        if (tok == "endloop") break;
        if (tok != "vertex") {
          FailLine(name, tokens.line(), "expected 'vertex', found '" + std::string(tok) + "'");
        }
        double c[3];
        for (double& ci : c) {
          if (!tokens.Next(tok) || !ParseDouble(tok, ci)) {
            FailLine(name, tokens.line(), "vertex needs 3 numbers");
          }
          if (!IsStorableFloat(ci)) {
            FailLine(name, tokens.line(), "'" + std::string(tok) + "' is not a finite float32");
          }
        }
        idx.push_back(welder.Add(static_cast<float>(c[0]), static_cast<float>(c[1]),
                                 static_cast<float>(c[2])));
      }
      expect("endfacet");
      AddPolygon(raw, idx.data(), idx.size());
    } else {
      FailLine(name, tokens.line(), "unexpected '" + std::string(tok) + "' in ascii STL");
    }
  }
  if (in_solid) FailLine(name, tokens.line(), "truncated: missing 'endsolid'");
  welder.Finish();
  return raw;
}

RawMesh ReadStl(std::string_view bytes, const std::string& name) {
  if (bytes.size() >= 84) {
    const auto count = LoadAt<uint32_t>(bytes, 80);
    if (84 + 50 * static_cast<uint64_t>(count) == bytes.size()) {
      return ReadStlBinary(bytes, name, count);
    }
  }
  std::size_t i = 0;
  while (i < bytes.size() && (IsSpace(bytes[i]) || bytes[i] == '\n')) ++i;
  if (bytes.substr(i, 5) == "solid" && bytes.find("facet") != std::string_view::npos) {
    return ReadStlAscii(bytes, name);
  }
  if (bytes.substr(i, 5) == "solid" && bytes.size() < 84) return ReadStlAscii(bytes, name);
  if (bytes.size() < 84) {
    throw InputError(name, "truncated: " + std::to_string(bytes.size()) +
                               " bytes is shorter than a binary STL header (84 bytes)");
  }
  const auto count = LoadAt<uint32_t>(bytes, 80);
  throw InputError(name, "truncated or not an STL: binary header declares " +
                             std::to_string(count) + " triangles (" +
                             std::to_string(84 + 50 * static_cast<uint64_t>(count)) +
                             " bytes) but the file has " + std::to_string(bytes.size()) + " bytes");
}

}  // namespace prt::mesh_import
