#include "farm/farm_options.h"

#include <gtest/gtest.h>

#include <sstream>
#include <string>
#include <vector>

namespace prt {
namespace {

int Parse(std::vector<std::string> args, FarmOptions& o, std::string* out = nullptr) {
  args.insert(args.begin(), "prt-farm");
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  std::ostringstream so, se;
  const int code = ParseFarmCommandLine(static_cast<int>(argv.size()), argv.data(), o, so, se);
  if (out) *out = so.str() + se.str();
  return code;
}

TEST(FarmOptionsTest, ParsesTheDocumentedOptions) {
  FarmOptions o;
  ASSERT_EQ(Parse({"scene.toml", "--out", "r", "--threads", "3", "--resume", "--method", "brute",
                   "--rays-per-texel", "16", "--job-seconds", "2.5", "--rows-per-block", "64",
                   "--coordinator-only", "--seed", "7"},
                  o),
            -1);
  EXPECT_EQ(o.scene_path, "scene.toml");
  EXPECT_EQ(o.out_dir, "r");
  EXPECT_EQ(o.threads, 3);
  EXPECT_TRUE(o.resume);
  EXPECT_EQ(o.method, "brute");
  EXPECT_EQ(o.rays_per_texel, 16);
  EXPECT_EQ(o.seed, std::optional<uint64_t>(7));
  EXPECT_DOUBLE_EQ(o.job_seconds, 2.5);
  EXPECT_EQ(o.rows_per_block, 64u);
  EXPECT_FALSE(o.coordinator_works);
  FarmOptions d;
  ASSERT_EQ(Parse({}, d), -1);
  EXPECT_EQ(d.scene_path, "");  // the embedded default scene
  EXPECT_EQ(d.out_dir, "run");
  EXPECT_TRUE(d.coordinator_works);
}

TEST(FarmOptionsTest, HelpAndVersionExit0UsageErrorsExit1) {
  FarmOptions o;
  std::string out;
  EXPECT_EQ(Parse({"--help"}, o, &out), kExitOk);
  EXPECT_NE(out.find("--rays-per-texel"), std::string::npos);
  EXPECT_NE(out.find("Exit codes"), std::string::npos);
  EXPECT_EQ(out.find("--fail-after-jobs"), std::string::npos);  // hidden
  EXPECT_EQ(Parse({"--version"}, o, &out), kExitOk);
  EXPECT_EQ(out, "prt-farm " + FarmVersion() + "\n");
  EXPECT_EQ(Parse({"--bogus"}, o), kExitUsage);
  EXPECT_EQ(Parse({"--method", "magic"}, o), kExitUsage);
  EXPECT_EQ(Parse({"--rays-per-texel", "0"}, o), kExitUsage);
  EXPECT_EQ(Parse({"--threads", "-2"}, o), kExitUsage);
  EXPECT_EQ(Parse({"a.toml", "b.toml"}, o), kExitUsage);
  FarmOptions c;
  EXPECT_EQ(Parse({"--resume", "--force"}, c), kExitUsage);
}

}  // namespace
}  // namespace prt
