// Scene files (TOML, docs/scene-format.md): parsing, validation with file:line messages, data
// path resolution, and the world-space geometry (fit, transforms, ground grid).
#include "vocabulary/scene.h"

#include <toml++/toml.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <numbers>
#include <set>
#include <sstream>
#include <stdexcept>
#include <string_view>

#include "vocabulary/errors.h"
#include "vocabulary/mesh_io.h"

namespace prt {
namespace {

namespace fs = std::filesystem;

// ---------------------------------------------------------------------------------------------
// Validation helpers: every getter records its key as known, so that what is left is unknown.

std::string Join(const std::vector<std::string>& items, const char* sep) {
  std::string out;
  for (std::size_t i = 0; i < items.size(); ++i) out += (i ? sep : "") + items[i];
  return out;
}

std::string TypeName(const toml::node& n) {
  switch (n.type()) {
    case toml::node_type::table:
      return "a table";
    case toml::node_type::array:
      return "an array";
    case toml::node_type::string:
      return "a string";
    case toml::node_type::integer:
      return "an integer";
    case toml::node_type::floating_point:
      return "a float";
    case toml::node_type::boolean:
      return "a boolean";
    default:
      return "a date/time";
  }
}

std::string FormatNumber(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

class Section {
 public:
  Section(const toml::table& table, std::string label, const std::string& file)
      : table_(table), label_(std::move(label)), file_(file) {}

  int line() const { return static_cast<int>(table_.source().begin.line); }

  [[noreturn]] void Fail(const toml::node* n, std::string_view key, const std::string& msg) const {
    const int l = n ? static_cast<int>(n->source().begin.line) : line();
    throw InputError(
        file_, "line " + std::to_string(l) + ": " + label_ + " " + std::string(key) + ": " + msg);
  }

  const toml::node* Find(std::string_view key) {
    known_.emplace_back(key);
    return table_.get(key);
  }

  double Number(std::string_view key, double def, double lo, double hi, bool lo_open = false,
                bool hi_open = false) {
    const toml::node* n = Find(key);
    if (!n) return def;
    if (!n->is_number()) Fail(n, key, "expected a number, got " + TypeName(*n));
    const double v = *n->value<double>();
    if (!std::isfinite(v)) Fail(n, key, "must be finite");
    const bool below = lo_open ? !(v > lo) : !(v >= lo);
    const bool above = hi_open ? !(v < hi) : !(v <= hi);
    if (below || above) {
      Fail(n, key,
           FormatNumber(v) + " is out of range " + (lo_open ? "(" : "[") + FormatNumber(lo) + ", " +
               (std::isinf(hi) ? "∞" : FormatNumber(hi)) + (hi_open ? ")" : "]"));
    }
    return v;
  }

  int64_t Integer(std::string_view key, int64_t def, int64_t lo, int64_t hi) {
    const toml::node* n = Find(key);
    if (!n) return def;
    if (!n->is_integer()) Fail(n, key, "expected an integer, got " + TypeName(*n));
    const int64_t v = *n->value<int64_t>();
    if (v < lo || v > hi) {
      Fail(n, key,
           std::to_string(v) + " is out of range [" + std::to_string(lo) + ", " +
               std::to_string(hi) + "]");
    }
    return v;
  }

  bool Bool(std::string_view key, bool def) {
    const toml::node* n = Find(key);
    if (!n) return def;
    if (!n->is_boolean()) Fail(n, key, "expected true or false, got " + TypeName(*n));
    return *n->value<bool>();
  }

  std::string String(std::string_view key, const std::string& def, bool required = false) {
    const toml::node* n = Find(key);
    if (!n) {
      if (required) Fail(nullptr, key, "is required");
      return def;
    }
    if (!n->is_string()) Fail(n, key, "expected a string, got " + TypeName(*n));
    std::string v = *n->value<std::string>();
    if (v.empty()) Fail(n, key, "must not be empty");
    return v;
  }

  std::string Choice(std::string_view key, const std::string& def,
                     std::initializer_list<std::string> options) {
    const toml::node* n = table_.get(key);
    const std::string v = String(key, def);
    if (std::find(options.begin(), options.end(), v) == options.end()) {
      Fail(n, key, "'" + v + "' is not one of: " + Join(std::vector<std::string>(options), ", "));
    }
    return v;
  }

  // An array of `dims` finite numbers.
  std::vector<double> Numbers(std::string_view key, std::size_t dims) {
    const toml::node* n = Find(key);
    if (!n) return {};
    const toml::array* a = n->as_array();
    if (!a || a->size() != dims) {
      Fail(n, key, "expected an array of " + std::to_string(dims) + " numbers");
    }
    std::vector<double> out;
    for (const toml::node& e : *a) {
      if (!e.is_number()) Fail(&e, key, "expected numbers, got " + TypeName(e));
      const double v = *e.value<double>();
      if (!std::isfinite(v)) Fail(&e, key, "must be finite");
      out.push_back(v);
    }
    return out;
  }

  Vec3 Vector(std::string_view key, const Vec3& def) {
    const std::vector<double> v = Numbers(key, 3);
    return v.empty() ? def : Vec3{v[0], v[1], v[2]};
  }

  Rgb Albedo(std::string_view key, const Rgb& def) {
    const toml::node* n = table_.get(key);
    const std::vector<double> v = Numbers(key, 3);
    if (v.empty()) return def;
    for (double c : v) {
      if (c < 0 || c > 1) {
        Fail(n, key, "components must lie in [0, 1] (got " + FormatNumber(c) + ")");
      }
    }
    return {static_cast<float>(v[0]), static_cast<float>(v[1]), static_cast<float>(v[2])};
  }

  const toml::table* SubTable(std::string_view key) {
    const toml::node* n = Find(key);
    if (!n) return nullptr;
    if (!n->is_table()) Fail(n, key, "expected a table, got " + TypeName(*n));
    return n->as_table();
  }

  // Every key not asked for is an error.
  void RejectUnknown() const {
    for (auto&& [k, v] : table_) {
      if (std::find(known_.begin(), known_.end(), k.str()) == known_.end()) {
        throw InputError(file_, "line " + std::to_string(k.source().begin.line) +
                                    ": unknown key '" + std::string(k.str()) + "' in " + label_ +
                                    " (known: " + Join(known_, ", ") + ")");
      }
    }
  }

 private:
  const toml::table& table_;
  std::string label_;
  const std::string& file_;
  std::vector<std::string> known_;
};

bool IsPowerOfTwo(int64_t v) {
  return v > 0 && (v & (v - 1)) == 0;
}

// ---------------------------------------------------------------------------------------------
// Transforms

struct Mat3 {
  double m[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  Vec3 operator*(const Vec3& v) const {
    return {m[0][0] * v.x + m[0][1] * v.y + m[0][2] * v.z,
            m[1][0] * v.x + m[1][1] * v.y + m[1][2] * v.z,
            m[2][0] * v.x + m[2][1] * v.y + m[2][2] * v.z};
  }
  Mat3 operator*(const Mat3& o) const {
    Mat3 r;
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) {
        r.m[i][j] = m[i][0] * o.m[0][j] + m[i][1] * o.m[1][j] + m[i][2] * o.m[2][j];
      }
    }
    return r;
  }
};

// The proper rotation taking `axis` to +Y (docs/scene-format.md lists them).
Mat3 UpRotation(const std::string& axis) {
  Mat3 r;
  if (axis == "+y") return r;
  if (axis == "-y") return Mat3{{{1, 0, 0}, {0, -1, 0}, {0, 0, -1}}};
  if (axis == "+z") return Mat3{{{1, 0, 0}, {0, 0, 1}, {0, -1, 0}}};
  if (axis == "-z") return Mat3{{{1, 0, 0}, {0, 0, -1}, {0, 1, 0}}};
  if (axis == "+x") return Mat3{{{0, -1, 0}, {1, 0, 0}, {0, 0, 1}}};
  if (axis == "-x") return Mat3{{{0, 1, 0}, {-1, 0, 0}, {0, 0, 1}}};
  throw std::invalid_argument("unknown up axis '" + axis + "'");
}

// R = Rz·Ry·Rx: rotation about x first, then y, then z (degrees, right-handed).
Mat3 EulerRotation(const Vec3& deg) {
  const double k = std::numbers::pi / 180.0;
  const double cx = std::cos(deg.x * k), sx = std::sin(deg.x * k);
  const double cy = std::cos(deg.y * k), sy = std::sin(deg.y * k);
  const double cz = std::cos(deg.z * k), sz = std::sin(deg.z * k);
  const Mat3 rx{{{1, 0, 0}, {0, cx, -sx}, {0, sx, cx}}};
  const Mat3 ry{{{cy, 0, sy}, {0, 1, 0}, {-sy, 0, cy}}};
  const Mat3 rz{{{cz, -sz, 0}, {sz, cz, 0}, {0, 0, 1}}};
  return rz * ry * rx;
}

// ---------------------------------------------------------------------------------------------
// Parsing

const char* const kUpAxes[] = {"+x", "-x", "+y", "-y", "+z", "-z"};

// The glossy-material keys of a [[mesh]] or [ground] table (docs/scene-format.md).
template <class S>
void ParseGlossy(S& s, const toml::table& t, const Rgb& albedo, GlossyMaterialSettings& g) {
  g.brdf = s.Choice("brdf", g.brdf, {"lambert", "phong", "ashikhmin-shirley", "ggx"});
  g.specular = s.Albedo("specular", g.specular);
  g.exponent = s.Number("exponent", g.exponent, 0, 1e6, true);
  g.exponent_v = s.Number("exponent_v", g.exponent, 0, 1e6, true);
  g.roughness = s.Number("roughness", g.roughness, 0, 1, true);  // GGX: α = roughness²
  for (int c = 0; c < 3; ++c) {
    if (albedo[c] + g.specular[c] > 1.0f + 1e-6f) {
      s.Fail(t.get("specular"), "specular",
             "albedo + specular must not exceed 1 in any channel (energy conservation)");
    }
  }
}

SceneDescription ParseTable(const toml::table& root, const std::string& file,
                            const std::vector<std::string>& search_dirs) {
  SceneDescription scene;
  scene.file = file;
  scene.search_dirs = search_dirs;
  Section top(root, "top level", file);
  auto section = [&](std::string_view key) -> const toml::table* { return top.SubTable(key); };

  static const toml::table kEmpty;
  {
    const toml::table* t = section("scene");
    Section s(t ? *t : kEmpty, "[scene]", file);
    scene.name = s.String("name", scene.name);
    const toml::node* nn = t ? t->get("n") : nullptr;
    const int64_t n = s.Integer("n", 32, 8, 256);
    if (!IsPowerOfTwo(n)) s.Fail(nn, "n", std::to_string(n) + " is not a power of two (8..256)");
    scene.cubemap_n = static_cast<int>(n);
    scene.samples = s.Choice("samples", "vertices", {"vertices", "camera"}) == "camera"
                        ? SpatialSamples::kCameraPixels
                        : SpatialSamples::kVertices;
    s.RejectUnknown();
  }
  {
    const toml::table* t = section("ground");
    Section s(t ? *t : kEmpty, "[ground]", file);
    GroundPlane& g = scene.ground;
    g.enabled = s.Bool("enabled", t != nullptr);
    g.height = s.Number("height", g.height, -1e30, 1e30);
    const std::vector<double> c = s.Numbers("center", 2);
    if (!c.empty()) g.center = {c[0], 0, c[1]};
    g.size = s.Number("size", g.size, 0, 1e30, true);
    g.resolution = static_cast<int>(s.Integer("resolution", g.resolution, 2, 4096));
    g.albedo = s.Albedo("albedo", g.albedo);
    ParseGlossy(s, t ? *t : kEmpty, g.albedo, g.glossy);
    s.RejectUnknown();
  }
  {
    const toml::node* n = top.Find("mesh");
    if (n) {
      const toml::array* arr = n->as_array();
      if (!arr || !arr->is_array_of_tables()) {
        top.Fail(n, "mesh", "expected an array of tables: write each mesh as [[mesh]]");
      }
      std::set<std::string> names;
      for (const toml::node& e : *arr) {
        const toml::table& mt = *e.as_table();
        Section s(mt, "[[mesh]]", file);
        MeshInstance m;
        m.line = s.line();
        m.name = s.String("name", "mesh" + std::to_string(scene.meshes.size()));
        if (!names.insert(m.name).second) {
          s.Fail(mt.get("name"), "name", "'" + m.name + "' is used by an earlier [[mesh]]");
        }
        m.path = s.String("path", "", true);
        m.resolved_path = FindDataFile(m.path, search_dirs);
        m.albedo = s.Albedo("albedo", m.albedo);
        if (const toml::table* ft = s.SubTable("fit")) {
          Section f(*ft, "[[mesh]] fit", file);
          FitBox fit;
          fit.size = f.Number("size", fit.size, 0, 1e30, true);
          fit.center = f.Vector(
              "center", {scene.ground.center.x, scene.ground.height, scene.ground.center.z});
          std::string up = f.String("up", fit.up_axis);
          for (char& ch : up) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
          if (up.size() == 1) up = "+" + up;
          if (std::find(std::begin(kUpAxes), std::end(kUpAxes), up) == std::end(kUpAxes)) {
            f.Fail(ft->get("up"), "up", "expected one of +x -x +y -y +z -z");
          }
          fit.up_axis = up;
          f.RejectUnknown();
          m.fit = fit;
        }
        m.scale = s.Number("scale", m.scale, 0, 1e30, true);
        m.rotate_deg = s.Vector("rotate_deg", m.rotate_deg);
        m.translate = s.Vector("translate", m.translate);
        m.flip_winding = s.Bool("flip_winding", m.flip_winding);
        ParseGlossy(s, mt, m.albedo, m.glossy);
        s.RejectUnknown();
        scene.meshes.push_back(std::move(m));
      }
    }
  }
  if (scene.meshes.empty() && !scene.ground.enabled) {
    throw InputError(file, "line 1: the scene has no geometry (no [[mesh]] and no [ground])");
  }
  {
    const toml::table* t = section("camera");
    Section s(t ? *t : kEmpty, "[camera]", file);
    Camera& c = scene.camera;
    c.eye = s.Vector("eye", c.eye);
    c.target = s.Vector("target", c.target);
    c.up = s.Vector("up", c.up);
    c.fov_deg = s.Number("fov", c.fov_deg, 0, 180, true, true);
    c.width = static_cast<int>(s.Integer("width", c.width, 1, 16384));
    c.height = static_cast<int>(s.Integer("height", c.height, 1, 16384));
    c.supersample = static_cast<int>(s.Integer("supersample", c.supersample, 1, 16));
    const Vec3 view = c.target - c.eye;
    if (Length(view) == 0) s.Fail(t ? t->get("target") : nullptr, "target", "equals eye");
    if (Length(Cross(Normalize(view), Normalize(c.up))) < 1e-6) {
      s.Fail(t ? t->get("up") : nullptr, "up", "is zero or parallel to the view direction");
    }
    s.RejectUnknown();
  }
  {
    const toml::table* t = section("sampling");
    Section s(t ? *t : kEmpty, "[sampling]", file);
    SamplingSettings& p = scene.sampling;
    p.rays_per_texel = static_cast<int>(s.Integer("rays_per_texel", p.rays_per_texel, 1, 65536));
    p.seed = static_cast<uint64_t>(s.Integer("seed", 1, 0, INT64_MAX));
    p.method = s.Choice("method", p.method, {"brute", "sparse"});
    p.job = s.Choice("job", p.job, {"transport", "visibility"});
    p.bounces = static_cast<int>(s.Integer("bounces", p.bounces, 0, 8));
    p.estimator = s.Choice("estimator", p.estimator, {"gather", "path"});
    const toml::node* in = t ? t->get("indirect_n") : nullptr;
    const int64_t indirect_n = s.Integer("indirect_n", p.indirect_n, 0, 256);
    if (indirect_n != 0 && !IsPowerOfTwo(indirect_n))
      s.Fail(in, "indirect_n", std::to_string(indirect_n) + " is not 0 or a power of two");
    p.indirect_n = static_cast<int>(indirect_n);
    p.gather_paths = static_cast<int>(s.Integer("gather_paths", p.gather_paths, 1, 65536));
    p.near_field = s.Number("near_field", p.near_field, 0.0, 100.0);
    s.RejectUnknown();
  }
  {
    const toml::table* t = section("visibility");
    Section s(t ? *t : kEmpty, "[visibility]", file);
    VisibilitySettings& v = scene.visibility;
    const toml::node* nn = t ? t->get("n") : nullptr;
    const int64_t n = s.Integer("n", v.n, 16, 256);
    if (!IsPowerOfTwo(n)) s.Fail(nn, "n", std::to_string(n) + " is not a power of two (16..256)");
    v.n = static_cast<int>(n);
    v.supersample = static_cast<int>(s.Integer("supersample", v.supersample, 1, 16));
    v.bits = static_cast<int>(s.Integer("bits", v.bits, 1, 8));
    if (v.bits > 1 && v.supersample == 1) {
      s.Fail(t ? t->get("bits") : nullptr, "bits",
             "anti-aliased levels (bits > 1) need supersample > 1");
    }
    s.RejectUnknown();
  }
  {
    const toml::table* t = section("glossy");
    Section s(t ? *t : kEmpty, "[glossy]", file);
    scene.glossy.terms = static_cast<int>(s.Integer("terms", scene.glossy.terms, 1, 16));
    s.RejectUnknown();
  }
  {
    const toml::table* t = section("sparse");
    Section s(t ? *t : kEmpty, "[sparse]", file);
    SparseSettings& p = scene.sparse;
    p.initial_fraction = s.Number("initial_fraction", p.initial_fraction, 0, 1, true);
    p.dense_budget = s.Number("dense_budget", p.dense_budget, 0, 1, true);
    if (p.dense_budget < p.initial_fraction) {
      s.Fail(t ? t->get("dense_budget") : nullptr, "dense_budget",
             "must be at least initial_fraction (" + FormatNumber(p.initial_fraction) + ")");
    }
    p.iterations = static_cast<int>(s.Integer("iterations", p.iterations, 1, 100));
    p.radius = s.Number("radius", p.radius, 0, 1, true);
    p.max_neighbors = static_cast<int>(s.Integer("max_neighbors", p.max_neighbors, 1, 1000));
    // §7: 350 features at n = 32 (about 6% of 6144 directions); the same fraction at other n.
    const int64_t n = scene.cubemap_n;
    const int64_t default_features = (350 * n * n + 512) / 1024;
    p.features = static_cast<int>(s.Integer("features", default_features, 1, 6 * n * n));
    p.lambda = s.Number("lambda", p.lambda, 0, 1e30, true);
    p.window = static_cast<int>(s.Integer("window", p.window, 3, 15));
    p.unity_weight = s.Number("unity_weight", p.unity_weight, 0, 100, false);
    p.max_residual = s.Number("max_residual", p.max_residual, 0, 10, false);
    p.min_normal_cos = s.Number("min_normal_cos", p.min_normal_cos, -2, 1, false);
    p.rank_floor = static_cast<int>(s.Integer("rank_floor", p.rank_floor, 0, 1000));
    // Unset, an image run with gathered bounces takes "full": every surface pixel gathers, which
    // costs little next to the vertices' support rows and is 0.7–1.5 points closer to Cycles
    // than the dense pixels' combination (docs/image-relighting.md, "Interreflection").
    const bool image_gather =
        scene.samples == SpatialSamples::kCameraPixels && scene.sampling.estimator == "gather";
    p.indirect = s.Choice("indirect", image_gather ? std::string("full") : p.indirect,
                          {"combination", "features", "full"});
    p.feature_paths = static_cast<int>(s.Integer("feature_paths", p.feature_paths, 0, 65536));
    if (p.window % 2 == 0) {
      s.Fail(t ? t->get("window") : nullptr, "window",
             "must be odd (a window centred on the texel), got " + std::to_string(p.window));
    }
    p.seed = static_cast<uint64_t>(s.Integer("seed", 1, 0, INT64_MAX));
    s.RejectUnknown();
  }
  {
    const toml::table* t = section("compression");
    Section s(t ? *t : kEmpty, "[compression]", file);
    CompressionSettings& p = scene.compression;
    p.row_wavelet = s.Choice("row_wavelet", p.row_wavelet, {"haar", "d4"});
    p.column_wavelet = s.Choice("column_wavelet", p.column_wavelet, {"legall53", "cdf97"});
    p.scheme = s.Choice("scheme", p.scheme, {"2d", "4d", "adaptive4d", "cpca"});
    p.bits = static_cast<int>(s.Integer("bits", p.bits, 1, 16));
    p.keep_fraction = s.Number("keep_fraction", p.keep_fraction, 0, 1, true);
    p.budget = s.Choice("budget", p.budget, {"column", "global"});
    p.light_weight = static_cast<int>(s.Integer("light_weight", p.light_weight, 0, 16));
    p.order_normal_weight = s.Number("order_normal_weight", p.order_normal_weight, 0, 100);
    p.clusters = static_cast<int>(s.Integer("clusters", p.clusters, 1, 1 << 20));
    p.bases = static_cast<int>(s.Integer("bases", p.bases, 0, 256));
    p.coefficient_bits = static_cast<int>(s.Integer("coefficient_bits", p.coefficient_bits, 2, 24));
    s.RejectUnknown();
  }
  {
    const toml::node* n = top.Find("environments");
    const toml::array* list = nullptr;
    std::string label = "environments";
    if (n && n->is_table()) {
      Section s(*n->as_table(), "[environments]", file);
      const toml::node* pn = s.Find("paths");
      if (pn && !pn->is_array()) s.Fail(pn, "paths", "expected an array of paths");
      if (pn) list = pn->as_array();
      s.RejectUnknown();
      label = "[environments] paths";
    } else if (n && n->is_array()) {
      list = n->as_array();
    } else if (n) {
      top.Fail(n, "environments", "expected a table [environments] with paths = [...]");
    }
    if (list) {
      for (const toml::node& e : *list) {
        if (!e.is_string() || e.value<std::string>()->empty()) {
          throw InputError(file, "line " + std::to_string(e.source().begin.line) + ": " + label +
                                     ": expected non-empty path strings, got " + TypeName(e));
        }
        const std::string p = *e.value<std::string>();
        const std::string found = FindDataFile(p, search_dirs);
        scene.environments.push_back(found.empty() ? p : found);
      }
    }
  }
  top.RejectUnknown();
  return scene;
}

const char kDefaultScene[] =
    R"toml(# prtfarm's default scene: the Stanford bunny (CGAL's watertight remesh, 37,706 vertices)
# fitted on a 64×64 ground grid, lit by Blender's sunrise and city environment maps, n = 32.
# The format is specified in docs/scene-format.md. Relative paths are looked up next to this
# file, then in each folder of PRT_DATA_PATH (colon-separated), then as given; the build tree's
# data/ folder holds meshes/ and envmaps/ (cmake/PrtData.cmake). This text is also compiled into
# the binaries (DefaultSceneText() in vocabulary/scene.h) and must stay identical to it.

[scene]
name = "bunny"
n = 32
samples = "vertices"

[[mesh]]
name = "bunny"
path = "meshes/bunny00.off"
albedo = [0.8, 0.8, 0.8]
fit = { size = 1.0, center = [0.0, 0.0, 0.0], up = "+y" }

[ground]
enabled = true
height = 0.0
center = [0.0, 0.0]
size = 4.0
resolution = 64
albedo = [0.6, 0.6, 0.6]

[camera]
eye = [0.0, 1.2, 3.2]
target = [0.0, 0.4, 0.0]
up = [0.0, 1.0, 0.0]
fov = 35.0
width = 640
height = 480

[sampling]
rays_per_texel = 4
seed = 1
method = "sparse"
# Two diffuse interreflections after the direct light (docs/interreflection.md).
bounces = 2

[sparse]
initial_fraction = 0.05
dense_budget = 0.25
iterations = 4
radius = 0.035
max_neighbors = 40
features = 350
lambda = 0.001
window = 7
unity_weight = 1
max_residual = 0.3
min_normal_cos = 0.5
rank_floor = 2
indirect = "combination"
seed = 1

[compression]
row_wavelet = "haar"
column_wavelet = "legall53"
scheme = "adaptive4d"
bits = 9
keep_fraction = 0.05
# One magnitude threshold over the whole matrix: adaptive 4D is then 1.2-2.4x smaller than 2D at
# equal relit error on this scene (docs/compression.md); the paper's per-column budget is not.
budget = "global"

[environments]
paths = ["envmaps/sunrise.exr", "envmaps/city.exr"]
)toml";

}  // namespace

// ---------------------------------------------------------------------------------------------

std::vector<std::string> DataSearchDirs(const std::string& base_dir,
                                        const std::vector<std::string>& extra_dirs) {
  std::vector<std::string> dirs;
  if (!base_dir.empty()) dirs.push_back(base_dir);
  if (const char* env = std::getenv("PRT_DATA_PATH")) {
    std::string_view rest(env);
    while (!rest.empty()) {
      const std::size_t colon = rest.find(':');
      const std::string_view dir = rest.substr(0, colon);
      if (!dir.empty()) dirs.emplace_back(dir);
      if (colon == std::string_view::npos) break;
      rest.remove_prefix(colon + 1);
    }
  }
  for (const std::string& d : extra_dirs) {
    if (!d.empty()) dirs.push_back(d);
  }
  return dirs;
}

std::string FindDataFile(const std::string& path, const std::vector<std::string>& dirs,
                         std::vector<std::string>* tried) {
  auto is_file = [](const fs::path& p) {
    std::error_code ec;
    return fs::exists(p, ec) && !fs::is_directory(p, ec);
  };
  const fs::path given(path);
  if (!given.is_absolute()) {
    for (const std::string& d : dirs) {
      const fs::path candidate = (fs::path(d) / given).lexically_normal();
      if (tried) tried->push_back(candidate.string());
      if (is_file(candidate)) return candidate.string();
    }
  }
  if (tried) tried->push_back(path);
  return is_file(given) ? path : std::string();
}

std::string ResolveScenePath(const SceneDescription& scene, const std::string& path, int line) {
  std::vector<std::string> tried;
  const std::string found = FindDataFile(path, scene.search_dirs, &tried);
  if (!found.empty()) return found;
  throw InputError(scene.file, (line > 0 ? "line " + std::to_string(line) + ": " : "") + "'" +
                                   path + "' not found; looked at: " + Join(tried, ", ") +
                                   " (PRT_DATA_PATH adds folders to look in)");
}

SceneDescription ParseScene(const std::string& text, const std::string& name,
                            const std::string& base_dir,
                            const std::vector<std::string>& extra_data_dirs) {
  toml::table root;
  try {
    root = toml::parse(text, name);
  } catch (const toml::parse_error& e) {
    throw InputError(
        name, "line " + std::to_string(e.source().begin.line) + ": TOML syntax error at column " +
                  std::to_string(e.source().begin.column) + ": " + std::string(e.description()));
  }
  return ParseTable(root, name, DataSearchDirs(base_dir, extra_data_dirs));
}

SceneDescription LoadSceneFile(const std::string& path,
                               const std::vector<std::string>& extra_data_dirs) {
  std::error_code ec;
  if (!fs::exists(path, ec)) throw InputError(path, "no such file");
  if (fs::is_directory(path, ec)) throw InputError(path, "is a directory, not a scene file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, "cannot open for reading");
  std::ostringstream text;
  text << in.rdbuf();
  std::string base = fs::path(path).parent_path().string();
  if (base.empty()) base = ".";
  return ParseScene(text.str(), path, base, extra_data_dirs);
}

const std::string& DefaultSceneText() {
  static const std::string text(kDefaultScene);
  return text;
}

SceneDescription LoadDefaultScene(const std::string& data_dir) {
  return ParseScene(DefaultSceneText(), "<default scene>", "", {data_dir});
}

void TransformInstance(const MeshInstance& instance, TriangleMesh& mesh) {
  Mat3 up;
  double fit_scale = 1.0;
  Vec3 fit_offset{0, 0, 0};
  if (instance.fit) {
    up = UpRotation(instance.fit->up_axis);
    Vec3 lo{INFINITY, INFINITY, INFINITY}, hi{-INFINITY, -INFINITY, -INFINITY};
    for (const Vec3& p : mesh.positions) {
      const Vec3 q = up * p;
      lo = {std::min(lo.x, q.x), std::min(lo.y, q.y), std::min(lo.z, q.z)};
      hi = {std::max(hi.x, q.x), std::max(hi.y, q.y), std::max(hi.z, q.z)};
    }
    const double extent = std::max({hi.x - lo.x, hi.y - lo.y, hi.z - lo.z});
    if (!(extent > 0) || !std::isfinite(extent)) {
      throw InputError(mesh.source, "cannot fit: the mesh's bounding box has no extent");
    }
    fit_scale = instance.fit->size / extent;
    const Vec3 bottom{0.5 * (lo.x + hi.x), lo.y, 0.5 * (lo.z + hi.z)};
    fit_offset = instance.fit->center - bottom * fit_scale;
  }
  const Mat3 rot = EulerRotation(instance.rotate_deg);
  const Mat3 normal_rot = rot * up;
  const double s = instance.scale;
  for (Vec3& p : mesh.positions) {
    p = instance.translate + rot * ((up * p * fit_scale + fit_offset) * s);
    if (!IsFinite(p)) throw InputError(mesh.source, "the transform makes a vertex non-finite");
  }
  for (Vec3& n : mesh.normals) n = Normalize(normal_rot * n);
  const double k = fit_scale * s;
  mesh.report.signed_volume *= k * k * k;
}

SceneGeometry BuildSceneGeometry(const SceneDescription& scene) {
  SceneGeometry geometry;
  for (const MeshInstance& inst : scene.meshes) {
    const std::string where = "line " + std::to_string(inst.line) + ": mesh '" + inst.name + "': ";
    SceneMesh sm;
    sm.name = inst.name;
    sm.albedo = inst.albedo;
    try {
      std::string path = inst.resolved_path;
      if (path.empty()) path = ResolveScenePath(scene, inst.path);
      sm.mesh = LoadMesh(path);
      if (inst.flip_winding) FlipWinding(sm.mesh);
      TransformInstance(inst, sm.mesh);
    } catch (const InputError& e) {
      const std::string msg = e.what();
      // ResolveScenePath's message already starts with the scene file.
      const std::string inner =
          msg.rfind(scene.file + ": ", 0) == 0 ? msg.substr(scene.file.size() + 2) : msg;
      throw InputError(scene.file, where + inner);
    }
    geometry.meshes.push_back(std::move(sm));
  }
  if (scene.ground.enabled) {
    SceneMesh g;
    g.name = "ground";
    g.mesh = MakeGroundGrid(scene.ground);
    g.albedo = scene.ground.albedo;
    g.is_ground = true;
    g.grid_resolution = scene.ground.resolution;
    geometry.meshes.push_back(std::move(g));
  }
  Vec3 lo{INFINITY, INFINITY, INFINITY}, hi{-INFINITY, -INFINITY, -INFINITY};
  for (const SceneMesh& m : geometry.meshes) {
    for (const Vec3& p : m.mesh.positions) {
      lo = {std::min(lo.x, p.x), std::min(lo.y, p.y), std::min(lo.z, p.z)};
      hi = {std::max(hi.x, p.x), std::max(hi.y, p.y), std::max(hi.z, p.z)};
    }
  }
  if (geometry.vertex_count() > 0) {
    geometry.bounds_min = lo;
    geometry.bounds_max = hi;
  }
  return geometry;
}

TriangleMesh MakeGroundGrid(const GroundPlane& ground) {
  if (ground.resolution < 2) throw std::invalid_argument("ground resolution must be >= 2");
  if (!(ground.size > 0) || !std::isfinite(ground.size)) {
    throw std::invalid_argument("ground size must be positive and finite");
  }
  const int res = ground.resolution;
  TriangleMesh mesh;
  mesh.source = "ground grid";
  mesh.report.format = "ground-grid";
  const std::size_t count = static_cast<std::size_t>(res) * res;
  mesh.positions.reserve(count);
  const double x0 = ground.center.x - 0.5 * ground.size;
  const double z0 = ground.center.z - 0.5 * ground.size;
  const double step = ground.size / (res - 1);
  for (int iz = 0; iz < res; ++iz) {
    for (int ix = 0; ix < res; ++ix) {
      // Exact end points: the last row/column lands on cx + s/2 without rounding drift.
      const double x = ix == res - 1 ? ground.center.x + 0.5 * ground.size : x0 + step * ix;
      const double z = iz == res - 1 ? ground.center.z + 0.5 * ground.size : z0 + step * iz;
      mesh.positions.push_back({x, ground.height, z});
    }
  }
  mesh.normals.assign(count, Vec3{0, 1, 0});
  mesh.triangles.reserve(static_cast<std::size_t>(2) * (res - 1) * (res - 1));
  for (int iz = 0; iz + 1 < res; ++iz) {
    for (int ix = 0; ix + 1 < res; ++ix) {
      const uint32_t a = static_cast<uint32_t>(iz * res + ix);  // (ix, iz)
      const uint32_t b = a + 1;                                 // (ix+1, iz)
      const uint32_t c = a + static_cast<uint32_t>(res);        // (ix, iz+1)
      const uint32_t d = c + 1;                                 // (ix+1, iz+1)
      // (c−a)×(b−a) = (0,0,dz)×(dx,0,0) = (0, dz·dx, 0): +Y.
      mesh.triangles.push_back({a, c, b});
      mesh.triangles.push_back({b, c, d});
    }
  }
  mesh.report.file_vertices = count;
  mesh.report.file_faces = mesh.triangles.size();
  AnalyzeTopology(mesh);
  return mesh;
}

}  // namespace prt
