// What the mesh readers share (see mesh_formats.h).
#include "vocabulary/mesh_formats.h"

namespace prt::mesh_import {

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

bool IsStorableFloat(double v) {
  return std::isfinite(v) && std::fabs(v) <= FLT_MAX;
}

bool IsSpace(char c) {
  return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f';
}

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

void AddPolygon(RawMesh& raw, const uint32_t* idx, std::size_t k) {
  ++raw.report.file_faces;
  if (k < 3) {
    ++raw.report.degenerate_triangles_dropped;
    return;
  }
  if (k > 3) ++raw.report.polygons_triangulated;
  for (std::size_t i = 1; i + 1 < k; ++i) raw.triangles.push_back({idx[0], idx[i], idx[i + 1]});
}

}  // namespace prt::mesh_import
