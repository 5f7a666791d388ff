// What the mesh readers (mesh_off.cpp, mesh_obj.cpp, mesh_ply.cpp, mesh_stl.cpp) share: number
// parsing, tokenizers, the raw mesh they produce before mesh.cpp's common checks, and the readers
// themselves. Internal to vocabulary/ (mesh.h is the interface).
#pragma once

#include <algorithm>
#include <array>
#include <bit>
#include <cfloat>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>
#include <vector>

#include "vocabulary/errors.h"
#include "vocabulary/mesh.h"

namespace prt::mesh_import {

// ---------------------------------------------------------------------------------------------
// Shared helpers

[[noreturn]] void FailLine(const std::string& name, std::size_t line, const std::string& msg);

bool ParseDouble(std::string_view tok, double& v);

bool ParseInt(std::string_view tok, int64_t& v);

// A coordinate must be finite and representable as float32 (storage downstream is float32).
bool IsStorableFloat(double v);

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

bool IsSpace(char c);

// Next whitespace-separated token of a line; false at the end of the line.
bool NextToken(std::string_view& rest, std::string_view& tok);

std::string_view StripComment(std::string_view line);

bool IsBlank(std::string_view line);

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
void AddPolygon(RawMesh& raw, const uint32_t* idx, std::size_t k);

// The readers (docs/mesh-import.md); each throws InputError naming `name` and the line or record.
RawMesh ReadOff(std::string_view text, const std::string& name);
RawMesh ReadObj(std::string_view text, const std::string& name);
RawMesh ReadPly(std::string_view text, const std::string& name);
RawMesh ReadStl(std::string_view bytes, const std::string& name);

}  // namespace prt::mesh_import
