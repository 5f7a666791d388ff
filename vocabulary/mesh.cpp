// Strict, order-preserving readers for PLY, OBJ, OFF and STL (docs/mesh-import.md).
//
// Why not Assimp (libassimp 5.2.5, probed on the project's real meshes): its OBJ and STL
// importers emit one vertex per face corner (bunny_npm_lowres.obj: 11,022 vertices instead of
// 1,839); aiProcess_JoinIdenticalVertices then renumbers them in order of first use (vertex 0
// becomes the file's vertex 3) and, for STL, keeps corners with different facet normals apart
// (pig.stl: 33,890 instead of 8,642); its OFF importer silently replaces an out-of-range index
// and crashes on a truncated file. The order of vertices is the order of spatial samples
// downstream, so a reordering importer cannot be used, and these formats are small enough to
// read exactly.
//
// Safety on untrusted input: every declared count is checked against the bytes that are left
// before anything is reserved, every index against the vertex count, every number for NaN/Inf
// and float32 range; nothing is read past the end of the buffer.
#include "vocabulary/mesh.h"

#include <algorithm>
#include <bit>
#include <cfloat>
#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <sstream>
#include <string_view>
#include <unordered_map>

#include "vocabulary/errors.h"

namespace prt {
namespace {

// ---------------------------------------------------------------------------------------------
// Shared helpers

[[noreturn]] void FailLine(const std::string& name, std::size_t line, const std::string& msg) {
  throw InputError(name, "line " + std::to_string(line) + ": " + msg);
}

bool ParseDouble(std::string_view tok, double& v) {
  if (!tok.empty() && tok.front() == '+') tok.remove_prefix(1);
  if (tok.empty()) return false;
  const auto r = std::from_chars(tok.data(), tok.data() + tok.size(), v);
  return r.ec == std::errc() && r.ptr == tok.data() + tok.size();
}

bool ParseInt(std::string_view tok, int64_t& v) {
  if (!tok.empty() && tok.front() == '+') tok.remove_prefix(1);
  if (tok.empty()) return false;
  const auto r = std::from_chars(tok.data(), tok.data() + tok.size(), v);
  return r.ec == std::errc() && r.ptr == tok.data() + tok.size();
}

// A coordinate must be finite and representable as float32 (storage downstream is float32).
bool IsStorableFloat(double v) {
  return std::isfinite(v) && std::fabs(v) <= FLT_MAX;
}

uint32_t FromLittleEndian(uint32_t u) {
  if constexpr (std::endian::native == std::endian::big) {
    u = (u >> 24) | ((u >> 8) & 0xFF00u) | ((u << 8) & 0xFF0000u) | (u << 24);
  }
  return u;
}

// Splits text into lines (without the line break), counting from 1.
class LineReader {
 public:
  explicit LineReader(std::string_view text, std::size_t first_line = 1)
      : text_(text), line_(first_line - 1) {}
  bool Next(std::string_view& out) {
    if (pos_ >= text_.size()) return false;
    const std::size_t nl = text_.find('\n', pos_);
    const std::size_t stop = nl == std::string_view::npos ? text_.size() : nl;
    out = text_.substr(pos_, stop - pos_);
    if (!out.empty() && out.back() == '\r') out.remove_suffix(1);
    pos_ = nl == std::string_view::npos ? text_.size() : nl + 1;
    ++line_;
    return true;
  }
  std::size_t line() const { return line_; }
  std::size_t offset() const { return pos_; }

 private:
  std::string_view text_;
  std::size_t pos_ = 0;
  std::size_t line_ = 0;
};

bool IsSpace(char c) {
  return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f';
}

// Next whitespace-separated token of a line; false at the end of the line.
bool NextToken(std::string_view& rest, std::string_view& tok) {
  std::size_t i = 0;
  while (i < rest.size() && IsSpace(rest[i])) ++i;
  if (i == rest.size()) {
    rest = {};
    return false;
  }
  std::size_t j = i;
  while (j < rest.size() && !IsSpace(rest[j])) ++j;
  tok = rest.substr(i, j - i);
  rest = rest.substr(j);
  return true;
}

std::string_view StripComment(std::string_view line) {
  const std::size_t hash = line.find('#');
  return hash == std::string_view::npos ? line : line.substr(0, hash);
}

bool IsBlank(std::string_view line) {
  return std::all_of(line.begin(), line.end(), [](char c) { return IsSpace(c); });
}

// Whitespace tokenizer over a whole text that remembers the line of each token (ascii PLY body,
// ascii STL).
class TokenReader {
 public:
  TokenReader(std::string_view text, std::size_t first_line) : text_(text), line_(first_line) {}
  bool Next(std::string_view& tok) {
    while (pos_ < text_.size() && (IsSpace(text_[pos_]) || text_[pos_] == '\n')) {
      if (text_[pos_] == '\n') ++line_;
      ++pos_;
    }
    if (pos_ >= text_.size()) return false;
    const std::size_t start = pos_;
    while (pos_ < text_.size() && !IsSpace(text_[pos_]) && text_[pos_] != '\n') ++pos_;
    tok = text_.substr(start, pos_ - start);
    return true;
  }
  void SkipRestOfLine() {
    while (pos_ < text_.size() && text_[pos_] != '\n') ++pos_;
  }
  std::size_t line() const { return line_; }

 private:
  std::string_view text_;
  std::size_t pos_ = 0;
  std::size_t line_;
};

// What a reader produces before the common checks.
struct RawMesh {
  std::vector<Vec3> positions;
  std::vector<Vec3> file_normals;  // empty, or one per position
  std::vector<std::array<uint32_t, 3>> triangles;
  MeshImportReport report;
};

// Adds a polygon (indices already range-checked) as a triangle fan (v0, vi, vi+1).
void AddPolygon(RawMesh& raw, const uint32_t* idx, std::size_t k) {
  ++raw.report.file_faces;
  if (k < 3) {
    ++raw.report.degenerate_triangles_dropped;
    return;
  }
  if (k > 3) ++raw.report.polygons_triangulated;
  for (std::size_t i = 1; i + 1 < k; ++i) raw.triangles.push_back({idx[0], idx[i], idx[i + 1]});
}

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

// ---------------------------------------------------------------------------------------------
// PLY: header, then elements in header order. Vertex element needs x y z (optionally nx ny nz);
// face element needs a list property vertex_indices (or vertex_index). Other elements and
// properties are read past.

enum class PlyType { kInt8, kUint8, kInt16, kUint16, kInt32, kUint32, kFloat32, kFloat64 };

bool PlyTypeOf(std::string_view s, PlyType& t) {
  static const std::pair<std::string_view, PlyType> kTypes[] = {
      {"char", PlyType::kInt8},      {"int8", PlyType::kInt8},       {"uchar", PlyType::kUint8},
      {"uint8", PlyType::kUint8},    {"short", PlyType::kInt16},     {"int16", PlyType::kInt16},
      {"ushort", PlyType::kUint16},  {"uint16", PlyType::kUint16},   {"int", PlyType::kInt32},
      {"int32", PlyType::kInt32},    {"uint", PlyType::kUint32},     {"uint32", PlyType::kUint32},
      {"float", PlyType::kFloat32},  {"float32", PlyType::kFloat32}, {"double", PlyType::kFloat64},
      {"float64", PlyType::kFloat64}};
  for (const auto& [n, ty] : kTypes) {
    if (n == s) {
      t = ty;
      return true;
    }
  }
  return false;
}

std::size_t PlySize(PlyType t) {
  switch (t) {
    case PlyType::kInt8:
    case PlyType::kUint8:
      return 1;
    case PlyType::kInt16:
    case PlyType::kUint16:
      return 2;
    case PlyType::kInt32:
    case PlyType::kUint32:
    case PlyType::kFloat32:
      return 4;
    case PlyType::kFloat64:
      return 8;
  }
  return 0;
}

bool PlyIsFloat(PlyType t) {
  return t == PlyType::kFloat32 || t == PlyType::kFloat64;
}

struct PlyProperty {
  std::string name;
  bool is_list = false;
  PlyType count_type = PlyType::kUint8;
  PlyType type = PlyType::kFloat32;
};

struct PlyElement {
  std::string name;
  uint64_t count = 0;
  std::vector<PlyProperty> props;
};

enum class PlyFormat { kAscii, kBinaryLE, kBinaryBE };

// Reads one scalar of type t at p (bounds already checked) as double.
double LoadBinary(const unsigned char* p, PlyType t, bool swap) {
  unsigned char b[8];
  const std::size_t n = PlySize(t);
  std::memcpy(b, p, n);
  if (swap) std::reverse(b, b + n);
  switch (t) {
    case PlyType::kInt8: {
      int8_t v;
      std::memcpy(&v, b, 1);
      return v;
    }
    case PlyType::kUint8:
      return b[0];
    case PlyType::kInt16: {
      int16_t v;
      std::memcpy(&v, b, 2);
      return v;
    }
    case PlyType::kUint16: {
      uint16_t v;
      std::memcpy(&v, b, 2);
      return v;
    }
    case PlyType::kInt32: {
      int32_t v;
      std::memcpy(&v, b, 4);
      return v;
    }
    case PlyType::kUint32: {
      uint32_t v;
      std::memcpy(&v, b, 4);
      return v;
    }
    case PlyType::kFloat32: {
      float v;
      std::memcpy(&v, b, 4);
      return v;
    }
    case PlyType::kFloat64: {
      double v;
      std::memcpy(&v, b, 8);
      return v;
    }
  }
  return 0;
}

// Which element is being read, for messages ("face 3 of 4"); formatted only on failure.
struct PlyWhere {
  const std::string& element;
  std::size_t index;
  std::size_t count;
  std::string str() const {
    return element + " " + std::to_string(index) + " of " + std::to_string(count);
  }
};

// Source of PLY values: ascii tokens or binary bytes, with the position for messages.
class PlyValues {
 public:
  PlyValues(std::string_view body, PlyFormat format, std::size_t first_line,
            const std::string& name)
      : body_(body),
        format_(format),
        tokens_(body, first_line),
        swap_((format == PlyFormat::kBinaryBE) == (std::endian::native == std::endian::little)),
        name_(name) {}

  // Reads one value; `what` describes the element for messages ("vertex 12 of 100").
  double Read(PlyType t, const PlyWhere& what) {
    if (format_ == PlyFormat::kAscii) {
      std::string_view tok;
      if (!tokens_.Next(tok)) {
        throw InputError(name_, "truncated: file ends in " + what.str() + " (line " +
                                    std::to_string(tokens_.line()) + ")");
      }
      double v = 0;
      if (PlyIsFloat(t)) {
        if (!ParseDouble(tok, v)) Fail(what, "'" + std::string(tok) + "' is not a number");
      } else {
        int64_t i = 0;
        if (!ParseInt(tok, i)) Fail(what, "'" + std::string(tok) + "' is not an integer");
        v = static_cast<double>(i);
      }
      return v;
    }
    const std::size_t n = PlySize(t);
    if (body_.size() - pos_ < n) {
      throw InputError(name_, "truncated: file ends in " + what.str() + " (byte " +
                                  std::to_string(pos_) + " of the binary body)");
    }
    const double v =
        LoadBinary(reinterpret_cast<const unsigned char*>(body_.data()) + pos_, t, swap_);
    pos_ += n;
    return v;
  }

  [[noreturn]] void Fail(const PlyWhere& what, const std::string& msg) const {
    if (format_ == PlyFormat::kAscii) FailLine(name_, tokens_.line(), what.str() + ": " + msg);
    throw InputError(name_, what.str() + ": " + msg);
  }

  // Reads a list length and checks that the list fits in what is left of the file.
  int64_t ReadListLength(const PlyProperty& p, const PlyWhere& what) {
    const double k = Read(p.count_type, what);
    if (k < 0) Fail(what, "negative list length " + std::to_string(static_cast<int64_t>(k)));
    const std::size_t min_bytes = format_ == PlyFormat::kAscii ? 2 : PlySize(p.type);
    if (k * static_cast<double>(min_bytes) > static_cast<double>(bytes_left())) {
      if (format_ == PlyFormat::kAscii) {
        throw InputError(name_, "truncated: file ends in " + what.str() + " (line " +
                                    std::to_string(tokens_.line()) + ")");
      }
      throw InputError(name_, "truncated: file ends in " + what.str() + " (list of " +
                                  std::to_string(static_cast<int64_t>(k)) + " values, " +
                                  std::to_string(bytes_left()) + " bytes left)");
    }
    return static_cast<int64_t>(k);
  }

  std::size_t bytes_left() const {
    return format_ == PlyFormat::kAscii ? body_.size() : body_.size() - pos_;
  }

 private:
  std::string_view body_;
  PlyFormat format_;
  TokenReader tokens_;
  std::size_t pos_ = 0;
  bool swap_;
  const std::string& name_;
};

RawMesh ReadPly(std::string_view text, const std::string& name) {
  RawMesh raw;
  LineReader lines(text);
  std::string_view line, tok;
  if (!lines.Next(line) || line != "ply") {
    throw InputError(name, "line 1: not a PLY file (first line must be 'ply')");
  }
  PlyFormat format = PlyFormat::kAscii;
  bool have_format = false;
  std::vector<PlyElement> elements;
  bool ended = false;
  while (lines.Next(line)) {
    std::string_view rest = line;
    if (!NextToken(rest, tok)) continue;
    if (tok == "comment" || tok == "obj_info") continue;
    if (tok == "end_header") {
      ended = true;
      break;
    }
    if (tok == "format") {
      NextToken(rest, tok);
      if (tok == "ascii") {
        format = PlyFormat::kAscii;
      } else if (tok == "binary_little_endian") {
        format = PlyFormat::kBinaryLE;
      } else if (tok == "binary_big_endian") {
        format = PlyFormat::kBinaryBE;
      } else {
        FailLine(name, lines.line(), "unknown PLY format '" + std::string(tok) + "'");
      }
      have_format = true;
    } else if (tok == "element") {
      PlyElement e;
      int64_t count = -1;
      if (!NextToken(rest, tok)) FailLine(name, lines.line(), "element without a name");
      e.name = tok;
      if (!NextToken(rest, tok) || !ParseInt(tok, count) || count < 0) {
        FailLine(name, lines.line(), "element '" + e.name + "' without a valid count");
      }
      e.count = static_cast<uint64_t>(count);
      elements.push_back(std::move(e));
    } else if (tok == "property") {
      if (elements.empty()) FailLine(name, lines.line(), "property before any element");
      PlyProperty p;
      if (!NextToken(rest, tok)) FailLine(name, lines.line(), "property without a type");
      if (tok == "list") {
        p.is_list = true;
        std::string_view ct, it;
        if (!NextToken(rest, ct) || !PlyTypeOf(ct, p.count_type) || !NextToken(rest, it) ||
            !PlyTypeOf(it, p.type)) {
          FailLine(name, lines.line(), "bad list property '" + std::string(line) + "'");
        }
        if (PlyIsFloat(p.count_type)) {
          FailLine(name, lines.line(), "list count type must be an integer type");
        }
      } else if (!PlyTypeOf(tok, p.type)) {
        FailLine(name, lines.line(), "unknown property type '" + std::string(tok) + "'");
      }
      if (!NextToken(rest, tok)) FailLine(name, lines.line(), "property without a name");
      p.name = tok;
      elements.back().props.push_back(std::move(p));
    } else {
      FailLine(name, lines.line(), "unknown PLY header keyword '" + std::string(tok) + "'");
    }
  }
  if (!ended) throw InputError(name, "truncated: PLY header has no end_header");
  if (!have_format) throw InputError(name, "PLY header has no format line");
  raw.report.format = format == PlyFormat::kAscii      ? "ply-ascii"
                      : format == PlyFormat::kBinaryLE ? "ply-binary-le"
                                                       : "ply-binary-be";
  const std::size_t body_line = lines.line() + 1;
  PlyValues values(text.substr(lines.offset()), format, body_line, name);

  // Which element carries the vertices and which the faces.
  uint64_t nv = 0;
  bool have_vertices = false;
  for (const PlyElement& e : elements) {
    if (e.name == "vertex") {
      nv = e.count;
      have_vertices = true;
    }
  }
  if (!have_vertices) throw InputError(name, "PLY has no 'vertex' element");
  if (nv > std::numeric_limits<uint32_t>::max()) throw InputError(name, "too many vertices");
  raw.report.file_vertices = static_cast<std::size_t>(nv);

  std::vector<uint32_t> idx;
  for (const PlyElement& e : elements) {
    // Smallest size of one element, to refuse a count the file cannot hold before reserving.
    std::size_t min_size = 0;
    for (const PlyProperty& p : e.props) {
      min_size += format == PlyFormat::kAscii ? 2 : PlySize(p.is_list ? p.count_type : p.type);
    }
    if (min_size > 0 && e.count > values.bytes_left() / min_size + 1) {
      throw InputError(name, "truncated: header declares " + std::to_string(e.count) + " " +
                                 e.name + " elements but only " +
                                 std::to_string(values.bytes_left()) + " bytes follow");
    }
    const std::size_t count = static_cast<std::size_t>(e.count);
    if (e.name == "vertex") {
      int ix = -1, iy = -1, iz = -1, inx = -1, iny = -1, inz = -1;
      for (std::size_t i = 0; i < e.props.size(); ++i) {
        const std::string& pn = e.props[i].name;
        const int ii = static_cast<int>(i);
        if (e.props[i].is_list) continue;
        if (pn == "x") ix = ii;
        if (pn == "y") iy = ii;
        if (pn == "z") iz = ii;
        if (pn == "nx") inx = ii;
        if (pn == "ny") iny = ii;
        if (pn == "nz") inz = ii;
      }
      if (ix < 0 || iy < 0 || iz < 0) {
        throw InputError(name, "PLY vertex element lacks x, y or z");
      }
      const bool normals = inx >= 0 && iny >= 0 && inz >= 0;
      raw.positions.reserve(count);
      if (normals) raw.file_normals.reserve(count);
      std::vector<double> vals(e.props.size(), 0.0);
      for (std::size_t v = 0; v < count; ++v) {
        const PlyWhere what{e.name, v, count};
        for (std::size_t i = 0; i < e.props.size(); ++i) {
          const PlyProperty& p = e.props[i];
          if (p.is_list) {
            const int64_t k = values.ReadListLength(p, what);
            for (int64_t j = 0; j < k; ++j) values.Read(p.type, what);
          } else {
            vals[i] = values.Read(p.type, what);
          }
        }
        for (int i : {ix, iy, iz, inx, iny, inz}) {
          if (i >= 0 && !IsStorableFloat(vals[i])) {
            values.Fail(what, e.props[i].name + " = " + std::to_string(vals[i]) +
                                  " is not a finite float32");
          }
        }
        raw.positions.push_back({vals[ix], vals[iy], vals[iz]});
        if (normals) raw.file_normals.push_back({vals[inx], vals[iny], vals[inz]});
      }
    } else if (e.name == "face") {
      int list = -1;
      for (std::size_t i = 0; i < e.props.size(); ++i) {
        if (e.props[i].is_list &&
            (e.props[i].name == "vertex_indices" || e.props[i].name == "vertex_index")) {
          list = static_cast<int>(i);
        }
      }
      if (list < 0) throw InputError(name, "PLY face element has no vertex_indices list");
      if (PlyIsFloat(e.props[list].type)) {
        throw InputError(name, "PLY vertex_indices must have an integer type");
      }
      raw.triangles.reserve(count);
      for (std::size_t f = 0; f < count; ++f) {
        const PlyWhere what{e.name, f, count};
        for (std::size_t i = 0; i < e.props.size(); ++i) {
          const PlyProperty& p = e.props[i];
          if (!p.is_list) {
            values.Read(p.type, what);
            continue;
          }
          const int64_t kk = values.ReadListLength(p, what);
          if (static_cast<int>(i) != list) {
            for (int64_t j = 0; j < kk; ++j) values.Read(p.type, what);
            continue;
          }
          idx.clear();
          for (int64_t j = 0; j < kk; ++j) {
            const double vi = values.Read(p.type, what);
            if (vi < 0 || vi >= static_cast<double>(nv)) {
              values.Fail(what, "vertex index " + std::to_string(static_cast<int64_t>(vi)) +
                                    " out of range [0, " + std::to_string(nv) + ")");
            }
            idx.push_back(static_cast<uint32_t>(vi));
          }
          AddPolygon(raw, idx.data(), idx.size());
        }
      }
    } else {
      // Any other element (edge, material, …): read past it.
      for (std::size_t r = 0; r < count && !e.props.empty(); ++r) {
        const PlyWhere what{e.name, r, count};
        for (const PlyProperty& p : e.props) {
          if (p.is_list) {
            const int64_t k = values.ReadListLength(p, what);
            for (int64_t j = 0; j < k; ++j) values.Read(p.type, what);
          } else {
            values.Read(p.type, what);
          }
        }
      }
    }
  }
  return raw;
}

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
  const auto* p = reinterpret_cast<const unsigned char*>(bytes.data()) + 84;
  for (uint32_t t = 0; t < count; ++t, p += 50) {
    uint32_t idx[3];
    for (int c = 0; c < 3; ++c) {
      float xyz[3];
      for (int k = 0; k < 3; ++k) {
        uint32_t u;
        std::memcpy(&u, p + 12 + 12 * c + 4 * k, 4);
        u = FromLittleEndian(u);
        xyz[k] = std::bit_cast<float>(u);
        if (!std::isfinite(xyz[k])) {
          throw InputError(name, "triangle " + std::to_string(t) + " of " + std::to_string(count) +
                                     ": corner " + std::to_string(c) + " is not finite");
        }
      }
      idx[c] = welder.Add(xyz[0], xyz[1], xyz[2]);
    }
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
    uint32_t count;
    std::memcpy(&count, bytes.data() + 80, 4);
    count = FromLittleEndian(count);
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
  uint32_t count;
  std::memcpy(&count, bytes.data() + 80, 4);
  count = FromLittleEndian(count);
  throw InputError(name, "truncated or not an STL: binary header declares " +
                             std::to_string(count) + " triangles (" +
                             std::to_string(84 + 50 * static_cast<uint64_t>(count)) +
                             " bytes) but the file has " + std::to_string(bytes.size()) + " bytes");
}

// ---------------------------------------------------------------------------------------------
// Common finishing: drop degenerate triangles, count unreferenced vertices, normals, topology.

TriangleMesh Finish(RawMesh raw, const std::string& name) {
  TriangleMesh mesh;
  mesh.source = name;
  mesh.report = raw.report;
  if (raw.positions.empty()) throw InputError(name, "empty mesh: no vertices");
  mesh.positions = std::move(raw.positions);
  mesh.triangles.reserve(raw.triangles.size());
  for (const auto& t : raw.triangles) {
    if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) {
      ++mesh.report.degenerate_triangles_dropped;
      continue;
    }
    const Vec3 c = Cross(mesh.positions[t[1]] - mesh.positions[t[0]],
                         mesh.positions[t[2]] - mesh.positions[t[0]]);
    if (c == Vec3{0, 0, 0}) {
      ++mesh.report.degenerate_triangles_dropped;
      continue;
    }
    mesh.triangles.push_back(t);
  }
  if (mesh.triangles.empty()) {
    throw InputError(name, "empty mesh: no triangles (" + std::to_string(mesh.positions.size()) +
                               " vertices, " +
                               std::to_string(mesh.report.degenerate_triangles_dropped) +
                               " degenerate faces dropped)");
  }
  std::vector<bool> used(mesh.positions.size(), false);
  for (const auto& t : mesh.triangles) {
    for (uint32_t v : t) used[v] = true;
  }
  mesh.report.unreferenced_vertices =
      static_cast<std::size_t>(std::count(used.begin(), used.end(), false));

  ComputeAreaWeightedNormals(mesh);
  if (!raw.file_normals.empty()) {
    mesh.report.normals_from_file = true;
    for (std::size_t v = 0; v < mesh.positions.size(); ++v) {
      const Vec3 n = Normalize(raw.file_normals[v]);
      if (n == Vec3{}) continue;  // zero-length file normal: keep the area-weighted one
      if (used[v] && Dot(n, mesh.normals[v]) < 0) ++mesh.report.normals_against_winding;
      mesh.normals[v] = n;
    }
  }
  AnalyzeTopology(mesh);
  return mesh;
}

std::string LowerExtension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext;
}

}  // namespace

void ComputeAreaWeightedNormals(TriangleMesh& mesh) {
  std::vector<Vec3> sum(mesh.positions.size(), Vec3{});
  for (const auto& t : mesh.triangles) {
    const Vec3& p0 = mesh.positions[t[0]];
    const Vec3 c = Cross(mesh.positions[t[1]] - p0, mesh.positions[t[2]] - p0);
    for (uint32_t v : t) sum[v] += c;
  }
  mesh.normals.resize(mesh.positions.size());
  for (std::size_t v = 0; v < sum.size(); ++v) {
    const Vec3 n = Normalize(sum[v]);
    mesh.normals[v] = (n == Vec3{} || !IsFinite(n)) ? Vec3{0, 1, 0} : n;
  }
}

double SignedVolume(const TriangleMesh& mesh) {
  double volume = 0;
  for (const auto& t : mesh.triangles) {
    volume += Dot(mesh.positions[t[0]], Cross(mesh.positions[t[1]], mesh.positions[t[2]]));
  }
  return volume / 6.0;
}

void FlipWinding(TriangleMesh& mesh) {
  for (auto& t : mesh.triangles) std::swap(t[1], t[2]);
  for (Vec3& n : mesh.normals) n = -n;
  mesh.report.signed_volume = -mesh.report.signed_volume;
  mesh.report.inward_wound = mesh.report.closed && mesh.report.signed_volume < 0;
}

void AnalyzeTopology(TriangleMesh& mesh) {
  // Directed edges bucketed by their first vertex (counting sort): an edge a→b is matched when
  // b's bucket holds b→a; a repeated directed edge means a non-manifold or inconsistently
  // oriented surface.
  const std::size_t nv = mesh.positions.size();
  std::vector<uint32_t> start(nv + 1, 0);
  for (const auto& t : mesh.triangles) {
    for (uint32_t v : t) ++start[v + 1];
  }
  for (std::size_t v = 0; v < nv; ++v) start[v + 1] += start[v];
  std::vector<uint32_t> fill(start.begin(), start.end() - 1);
  std::vector<uint32_t> target(mesh.triangles.size() * 3);
  for (const auto& t : mesh.triangles) {
    for (int k = 0; k < 3; ++k) target[fill[t[k]]++] = t[(k + 1) % 3];
  }
  bool manifold = true;
  std::size_t boundary = 0;
  for (std::size_t a = 0; a < nv; ++a) {
    for (uint32_t i = start[a]; i < start[a + 1]; ++i) {
      const uint32_t b = target[i];
      for (uint32_t j = i + 1; j < start[a + 1]; ++j) {
        if (target[j] == b) manifold = false;
      }
      bool matched = false;
      for (uint32_t j = start[b]; j < start[b + 1] && !matched; ++j) matched = target[j] == a;
      if (!matched) ++boundary;
    }
  }
  mesh.report.boundary_edges = boundary;
  mesh.report.closed = manifold && boundary == 0 && !mesh.triangles.empty();
  mesh.report.signed_volume = SignedVolume(mesh);
  mesh.report.inward_wound = mesh.report.closed && mesh.report.signed_volume < 0;
}

std::string DescribeImport(const TriangleMesh& mesh) {
  const MeshImportReport& r = mesh.report;
  std::ostringstream s;
  s << mesh.source << ": " << r.format << ", " << mesh.positions.size() << " vertices, "
    << mesh.triangles.size() << " triangles";
  if (r.welded_vertices) s << ", " << r.welded_vertices << " corners welded";
  if (r.polygons_triangulated) s << ", " << r.polygons_triangulated << " polygons fan-triangulated";
  if (r.degenerate_triangles_dropped) {
    s << ", " << r.degenerate_triangles_dropped << " degenerate faces dropped";
  }
  if (r.unreferenced_vertices) {
    s << ", " << r.unreferenced_vertices << " unreferenced vertices kept";
  }
  s << (r.normals_from_file ? ", normals from file" : ", area-weighted normals");
  if (r.normals_against_winding) {
    s << " (" << r.normals_against_winding << " point against the winding)";
  }
  s << (r.closed ? ", closed" : ", open (" + std::to_string(r.boundary_edges) + " boundary edges)");
  if (r.inward_wound) s << ", WOUND INWARD (signed volume " << r.signed_volume << ")";
  return s.str();
}

TriangleMesh ParseMesh(const std::string& bytes, const std::string& name) {
  const std::string ext = LowerExtension(name);
  RawMesh raw;
  if (ext == ".ply") {
    raw = ReadPly(bytes, name);
  } else if (ext == ".obj") {
    raw = ReadObj(bytes, name);
  } else if (ext == ".off") {
    raw = ReadOff(bytes, name);
  } else if (ext == ".stl") {
    raw = ReadStl(bytes, name);
  } else {
    throw InputError(
        name, "unknown mesh format '" + ext + "' (supported extensions: .ply, .obj, .off, .stl)");
  }
  return Finish(std::move(raw), name);
}

TriangleMesh LoadMesh(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw InputError(path, "no such file");
  if (std::filesystem::is_directory(path, ec)) throw InputError(path, "is a directory");
  const std::string ext = LowerExtension(path);
  if (ext != ".ply" && ext != ".obj" && ext != ".off" && ext != ".stl") {
    throw InputError(
        path, "unknown mesh format '" + ext + "' (supported extensions: .ply, .obj, .off, .stl)");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, "cannot open for reading");
  std::string bytes;
  in.seekg(0, std::ios::end);
  const std::streamoff size = in.tellg();
  if (size < 0) throw InputError(path, "cannot determine the file size");
  bytes.resize(static_cast<std::size_t>(size));
  in.seekg(0, std::ios::beg);
  in.read(bytes.data(), size);
  if (!in) throw InputError(path, "read error");
  return ParseMesh(bytes, path);
}

}  // namespace prt
