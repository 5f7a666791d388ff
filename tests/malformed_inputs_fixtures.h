// The fixture generator of the malformed-input catalogue (tests/malformed_inputs_test.cpp,
// docs/testing.md "Malformed inputs"): writes every broken mesh, environment map and scene file
// the catalogue feeds to prt-farm, prt-pack and prt-view, plus the few valid files they are
// derived from. Everything is generated (nothing binary is checked in), so each fixture is a
// deliberate, documented defect of an otherwise valid file.
#pragma once

#include <filesystem>
#include <string>

namespace prt::testing {

// Writes the fixtures into `dir` (created if missing). `box_off` is tests/data/box.off, copied
// beside the generated scenes so that they name it by a relative path.
void WriteMalformedFixtures(const std::filesystem::path& dir, const std::filesystem::path& box_off);

// The valid tiny scene (tests/data/tiny.toml with n = 8) with `replace` substituted for the
// first occurrence of `find` ("" = unchanged; find = "" appends `replace` at the end).
std::string TinySceneWith(const std::string& find, const std::string& replace);

}  // namespace prt::testing
