// The PLY reader (ascii, binary little and big endian) (docs/mesh-import.md); strict and
// order-preserving, safe on untrusted input (see mesh.cpp).
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "vocabulary/mesh_formats.h"

namespace prt::mesh_import {

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

}  // namespace prt::mesh_import
