// The OBJ reader (docs/mesh-import.md); strict and order-preserving, safe on untrusted input
// (see mesh.cpp).
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "vocabulary/mesh_formats.h"

namespace prt::mesh_import {

// ---------------------------------------------------------------------------------------------
// OBJ: "v x y z [w | r g b]", "vn x y z", "f a b c …" with a, a/t, a/t/n or a//n (1-based,
// negative = relative to the vertices defined so far). Everything else (vt, g, o, s, usemtl,
// mtllib, l, p, …) is ignored.

RawMesh ReadObj(std::string_view text, const std::string& name) {
  RawMesh raw;
  raw.report.format = "obj";
  std::vector<Vec3> vn;
  // (position, vn index) of every corner that names a normal.
  std::vector<std::pair<uint32_t, int64_t>> corner_normals;
  bool any_corner_without_normal = false;
  int64_t max_index = -1;
  std::size_t max_index_line = 0;
  LineReader lines(text);
  std::string_view line, tok;
  std::vector<uint32_t> idx;
  std::vector<int64_t> nidx;
  while (lines.Next(line)) {
    std::string_view rest = StripComment(line);
    if (!NextToken(rest, tok)) continue;
    if (tok == "v" || tok == "vn") {
      const bool is_normal = tok == "vn";
      double c[3];
      for (double& ci : c) {
        if (!NextToken(rest, tok) || !ParseDouble(tok, ci)) {
          FailLine(name, lines.line(), "expected 3 numbers in '" + std::string(line) + "'");
        }
        if (!IsStorableFloat(ci)) {
          FailLine(name, lines.line(), "'" + std::string(tok) + "' is not a finite float32");
        }
      }
      if (is_normal) {
        vn.push_back({c[0], c[1], c[2]});
      } else {
        if (raw.positions.size() >= std::numeric_limits<uint32_t>::max()) {
          FailLine(name, lines.line(), "too many vertices");
        }
        raw.positions.push_back({c[0], c[1], c[2]});
      }
    } else if (tok == "f") {
      idx.clear();
      nidx.clear();
      while (NextToken(rest, tok)) {
        // a, a/t, a/t/n, a//n
        const std::size_t s1 = tok.find('/');
        const std::string_view a = tok.substr(0, s1);
        std::string_view n;
        if (s1 != std::string_view::npos) {
          const std::size_t s2 = tok.find('/', s1 + 1);
          if (s2 != std::string_view::npos) n = tok.substr(s2 + 1);
        }
        int64_t vi = 0;
        if (!ParseInt(a, vi) || vi == 0) {
          FailLine(name, lines.line(), "bad vertex reference '" + std::string(tok) + "'");
        }
        const int64_t count = static_cast<int64_t>(raw.positions.size());
        const int64_t resolved = vi > 0 ? vi - 1 : count + vi;
        if (resolved < 0) {
          FailLine(name, lines.line(),
                   "vertex reference " + std::to_string(vi) + " out of range (" +
                       std::to_string(count) + " vertices defined so far)");
        }
        if (resolved >= std::numeric_limits<uint32_t>::max()) {
          FailLine(name, lines.line(), "vertex reference " + std::to_string(vi) + " too large");
        }
        if (resolved > max_index) {
          max_index = resolved;
          max_index_line = lines.line();
        }
        idx.push_back(static_cast<uint32_t>(resolved));
        int64_t ni = -1;
        if (!n.empty()) {
          int64_t nn = 0;
          if (!ParseInt(n, nn) || nn == 0) {
            FailLine(name, lines.line(), "bad normal reference '" + std::string(tok) + "'");
          }
          const int64_t ncount = static_cast<int64_t>(vn.size());
          ni = nn > 0 ? nn - 1 : ncount + nn;
          if (ni < 0 || ni >= ncount) {
            FailLine(name, lines.line(),
                     "normal reference " + std::to_string(nn) + " out of range (" +
                         std::to_string(ncount) + " normals defined so far)");
          }
        }
        nidx.push_back(ni);
      }
      for (std::size_t i = 0; i < idx.size(); ++i) {
        if (nidx[i] < 0) {
          any_corner_without_normal = true;
        } else {
          corner_normals.push_back({idx[i], nidx[i]});
        }
      }
      AddPolygon(raw, idx.data(), idx.size());
    }
  }
  const int64_t nv = static_cast<int64_t>(raw.positions.size());
  raw.report.file_vertices = raw.positions.size();
  if (max_index >= nv) {
    FailLine(name, max_index_line,
             "vertex reference " + std::to_string(max_index + 1) + " out of range (the file has " +
                 std::to_string(nv) + " vertices)");
  }
  if (!vn.empty() && !any_corner_without_normal) {
    // Is there a single normal per position? (Checked after the whole file is read, since a
    // face may refer to a vertex defined later.) File normals only when every referenced
    // position has exactly one; an unreferenced position keeps the computed +Y.
    std::vector<int64_t> corner_normal(raw.positions.size(), -1);  // −1 none, −2 conflicting
    for (const auto& [v, n] : corner_normals) {
      int64_t& slot = corner_normal[v];
      if (slot == -1) {
        slot = n;
      } else if (slot >= 0 && slot != n && !(vn[slot] == vn[n])) {
        slot = -2;
      }
    }
    bool consistent = true;
    std::vector<bool> referenced(raw.positions.size(), false);
    for (const auto& t : raw.triangles) {
      for (uint32_t v : t) referenced[v] = true;
    }
    for (std::size_t v = 0; v < corner_normal.size(); ++v) {
      if (referenced[v] && corner_normal[v] < 0) consistent = false;
    }
    if (consistent) {
      raw.file_normals.resize(raw.positions.size(), Vec3{});
      for (std::size_t v = 0; v < corner_normal.size(); ++v) {
        if (corner_normal[v] >= 0) raw.file_normals[v] = vn[corner_normal[v]];
      }
    }
  }
  return raw;
}

}  // namespace prt::mesh_import
