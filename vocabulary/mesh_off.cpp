// The OFF reader (docs/mesh-import.md); strict and order-preserving, safe on untrusted input
// (see mesh.cpp).
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "vocabulary/mesh_formats.h"

namespace prt::mesh_import {

// ---------------------------------------------------------------------------------------------
// OFF: "OFF" | "COFF" | "NOFF" | "CNOFF", counts "nv nf [ne]", nv vertex lines "x y z [nx ny nz]
// [colour]", nf face lines "k i0 … ik−1 [colour]". '#' starts a comment.

RawMesh ReadOff(std::string_view text, const std::string& name) {
  RawMesh raw;
  raw.report.format = "off";
  LineReader lines(text);
  std::string_view line;
  auto next_content_line = [&](std::string_view& out) {
    while (lines.Next(out)) {
      out = StripComment(out);
      if (!IsBlank(out)) return true;
    }
    return false;
  };
  if (!next_content_line(line)) throw InputError(name, "empty file (expected an OFF header)");
  std::string_view rest = line, tok;
  NextToken(rest, tok);
  bool has_normals = false;
  if (tok == "OFF" || tok == "COFF") {
  } else if (tok == "NOFF" || tok == "CNOFF") {
    has_normals = true;
  } else if (tok.size() >= 3 && tok.substr(tok.size() - 3) == "OFF") {
    FailLine(
        name, lines.line(),
        "unsupported OFF variant '" + std::string(tok) + "' (supported: OFF, COFF, NOFF, CNOFF)");
  } else {
    FailLine(name, lines.line(), "not an OFF file (first keyword is '" + std::string(tok) + "')");
  }
  // Counts may follow on the header line or come on the next content line.
  std::string_view counts = rest;
  if (IsBlank(counts)) {
    if (!next_content_line(counts)) throw InputError(name, "truncated: no vertex/face counts");
  }
  std::string_view ctok;
  int64_t nv = -1, nf = -1;
  std::string_view crest = counts;
  if (NextToken(crest, ctok) && ctok == "BINARY") {
    FailLine(name, lines.line(), "binary OFF is not supported (use ascii OFF, PLY or STL)");
  }
  crest = counts;
  if (!NextToken(crest, ctok) || !ParseInt(ctok, nv) || !NextToken(crest, ctok) ||
      !ParseInt(ctok, nf) || nv < 0 || nf < 0) {
    FailLine(name, lines.line(), "expected vertex and face counts 'nv nf [ne]'");
  }
  // Each vertex line needs at least 6 bytes ("0 0 0\n"), each face line 8.
  const std::size_t left = text.size() - std::min(text.size(), lines.offset());
  if (static_cast<uint64_t>(nv) > left / 6 + 1 || static_cast<uint64_t>(nf) > left / 8 + 1) {
    FailLine(name, lines.line(),
             "truncated: header declares " + std::to_string(nv) + " vertices and " +
                 std::to_string(nf) + " faces but only " + std::to_string(left) + " bytes follow");
  }
  if (static_cast<uint64_t>(nv) > std::numeric_limits<uint32_t>::max()) {
    FailLine(name, lines.line(), "too many vertices");
  }
  raw.report.file_vertices = static_cast<std::size_t>(nv);
  raw.positions.reserve(static_cast<std::size_t>(nv));
  if (has_normals) raw.file_normals.reserve(static_cast<std::size_t>(nv));
  const int need = has_normals ? 6 : 3;
  for (int64_t v = 0; v < nv; ++v) {
    if (!next_content_line(line)) {
      throw InputError(name, "truncated: file ends after " + std::to_string(v) + " of " +
                                 std::to_string(nv) + " vertices (line " +
                                 std::to_string(lines.line()) + ")");
    }
    double c[6];
    rest = line;
    for (int k = 0; k < need; ++k) {
      if (!NextToken(rest, tok) || !ParseDouble(tok, c[k])) {
        FailLine(name, lines.line(),
                 "vertex " + std::to_string(v) + ": expected " + std::to_string(need) +
                     " numbers, got '" + std::string(line) + "'");
      }
      if (!IsStorableFloat(c[k])) {
        FailLine(
            name, lines.line(),
            "vertex " + std::to_string(v) + ": '" + std::string(tok) + "' is not a finite float32");
      }
    }
    raw.positions.push_back({c[0], c[1], c[2]});
    if (has_normals) raw.file_normals.push_back({c[3], c[4], c[5]});
  }
  raw.triangles.reserve(static_cast<std::size_t>(nf));
  std::vector<uint32_t> idx;
  for (int64_t f = 0; f < nf; ++f) {
    if (!next_content_line(line)) {
      throw InputError(name, "truncated: file ends after " + std::to_string(f) + " of " +
                                 std::to_string(nf) + " faces (line " +
                                 std::to_string(lines.line()) + ")");
    }
    rest = line;
    int64_t k = 0;
    if (!NextToken(rest, tok) || !ParseInt(tok, k)) {
      FailLine(name, lines.line(), "face " + std::to_string(f) + ": expected a corner count");
    }
    if (k < 0 || k > 1'000'000) {
      FailLine(name, lines.line(),
               "face " + std::to_string(f) + ": corner count " + std::to_string(k) +
                   " out of range [0, 1000000]");
    }
    idx.clear();
    for (int64_t i = 0; i < k; ++i) {
      int64_t vi = 0;
      if (!NextToken(rest, tok) || !ParseInt(tok, vi)) {
        FailLine(
            name, lines.line(),
            "face " + std::to_string(f) + ": expected " + std::to_string(k) + " vertex indices");
      }
      if (vi < 0 || vi >= nv) {
        FailLine(name, lines.line(),
                 "face " + std::to_string(f) + ": vertex index " + std::to_string(vi) +
                     " out of range [0, " + std::to_string(nv) + ")");
      }
      idx.push_back(static_cast<uint32_t>(vi));
    }
    AddPolygon(raw, idx.data(), idx.size());
  }
  return raw;
}

}  // namespace prt::mesh_import
