// The paper's released lens YAML (yaml-cpp), read as is:
//   stop_idx: [i]          0-based index of the aperture stop (a flat surface)
//   sequence: [GAGAAGA]    one letter per surface: the medium after it, G glass or A air
//   hfov: [deg]            half field of view
//   f_number: [N]
//   c: [...]               curvatures, 1/mm, one per surface
//   t: [...]               thicknesses, mm, one per surface; the last is the distance to the image
//   nd: [...], v: [...]    d-line index and Abbe number, one per G, in order
// Single values may be written as one-element lists (as the paper does) or as plain scalars.
// Glasses are model glasses (nd, vd); the specs are the paper's: sensor diagonal 16 mm and its 15
// wavelengths. Keys other than these are ignored.

#include <fmt/format.h>
#include <yaml-cpp/eventhandler.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "lens_io_detail.h"
#include "lensopt/core/error.h"
#include "lensopt/lens/input_limits.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/lens/validate.h"

namespace lensopt {

namespace {

constexpr std::array<std::string_view, 8> kYamlKeys = {"stop_idx", "sequence", "hfov", "f_number",
                                                       "c",        "t",        "nd",   "v"};

// Turns yaml-cpp nodes into lens values, throwing Error at the node's file:line:column.
class YamlReader {
 public:
  YamlReader(std::string file, YAML::Node root) : file_(std::move(file)), root_(std::move(root)) {}

  SourceLocation at(const YAML::Mark& mark) const {
    if (mark.is_null()) return SourceLocation{file_};
    return {file_, mark.line + 1, mark.column + 1};
  }
  [[noreturn]] void fail(const YAML::Mark& mark, const std::string& message) const {
    throw Error(at(mark), message);
  }
  [[noreturn]] void fail(const YAML::Node& node, const std::string& message) const {
    fail(node.Mark(), message);
  }

  // The value of a top-level key; a missing key is an error naming a present key it may be a
  // misspelling of.
  YAML::Node required(std::string_view key) const {
    const YAML::Node& root = root_;
    const YAML::Node node = root[std::string(key)];
    if (node.IsDefined() && !node.IsNull()) return node;
    std::string hint;
    for (const auto& item : root) {
      const std::string present = item.first.as<std::string>("");
      const std::array<std::string_view, 1> wanted = {key};
      if (std::find(kYamlKeys.begin(), kYamlKeys.end(), present) == kYamlKeys.end() &&
          !detail::closest_key(present, wanted).empty()) {
        hint = fmt::format(" (the file has '{}' at line {})", present, item.first.Mark().line + 1);
        break;
      }
    }
    if (node.IsDefined()) fail(node, fmt::format("'{}' has no value", key));
    fail(root.Mark(), fmt::format("missing key '{}'{}", key, hint));
  }

  // A scalar, or the one element of a one-element list.
  YAML::Node single(const YAML::Node& node, std::string_view key) const {
    if (node.IsScalar()) return node;
    if (node.IsSequence() && node.size() == 1 && node[0].IsScalar()) return node[0];
    fail(node, fmt::format("{} must be one value, or a list of one value", key));
  }

  // A list of scalars (a single scalar counts as a list of one).
  std::vector<YAML::Node> list(const YAML::Node& node, std::string_view key) const {
    if (node.IsScalar()) return {node};
    if (!node.IsSequence()) fail(node, fmt::format("{} must be a list", key));
    std::vector<YAML::Node> items;
    for (const YAML::Node& item : node) {
      if (!item.IsScalar())
        fail(item, fmt::format("{}[{}] must be a single value", key, items.size()));
      items.push_back(item);
    }
    return items;
  }

  double number(const YAML::Node& node, const std::string& what) const {
    double x = 0.0;
    try {
      x = node.as<double>();
    } catch (const YAML::Exception&) {
      fail(node, fmt::format("{} must be a number, not '{}'", what, node.Scalar()));
    }
    if (!std::isfinite(x)) fail(node, fmt::format("{} = {} must be finite", what, x));
    return x;
  }

  std::vector<double> numbers(const YAML::Node& node, std::string_view key) const {
    std::vector<double> values;
    for (const YAML::Node& item : list(node, key))
      values.push_back(number(item, fmt::format("{}[{}]", key, values.size())));
    return values;
  }

  int integer(const YAML::Node& node, std::string_view what) const {
    try {
      return node.as<int>();
    } catch (const YAML::Exception&) {
      fail(node, fmt::format("{} must be an integer, not '{}'", what, node.Scalar()));
    }
  }

 private:
  std::string file_;
  YAML::Node root_;
};

// The limits of lens/input_limits.h from the parser's events, before any tree is walked: the
// nesting depth, the number of aliases and the number of nodes the document expands to (an
// alias counts the nodes of its anchor's node, so nested aliases multiply). Linear in the text.
class AliasBudget : public YAML::EventHandler {
 public:
  explicit AliasBudget(std::string file) : file_(std::move(file)) {}

  void OnDocumentStart(const YAML::Mark&) override {}
  void OnDocumentEnd() override {}
  void OnNull(const YAML::Mark& mark, YAML::anchor_t anchor) override { leaf(mark, anchor); }
  void OnScalar(const YAML::Mark& mark, const std::string&, YAML::anchor_t anchor,
                const std::string&) override {
    leaf(mark, anchor);
  }
  void OnAlias(const YAML::Mark& mark, YAML::anchor_t anchor) override {
    if (++aliases_ > kMaxYamlAliases)
      fail(mark,
           fmt::format("more than {} aliases (*name); a lens file needs none", kMaxYamlAliases));
    add(mark, anchor < sizes_.size() && sizes_[anchor] > 0 ? sizes_[anchor] : 1);
  }
  void OnSequenceStart(const YAML::Mark& mark, const std::string&, YAML::anchor_t anchor,
                       YAML::EmitterStyle::value) override {
    open(mark, anchor);
  }
  void OnSequenceEnd() override { close(); }
  void OnMapStart(const YAML::Mark& mark, const std::string&, YAML::anchor_t anchor,
                  YAML::EmitterStyle::value) override {
    open(mark, anchor);
  }
  void OnMapEnd() override { close(); }

 private:
  struct Open {
    YAML::anchor_t anchor;
    std::size_t nodes;
  };
  [[noreturn]] void fail(const YAML::Mark& mark, const std::string& message) const {
    throw Error(SourceLocation{file_, mark.line + 1, mark.column + 1}, message);
  }
  // n more nodes in the expanded document (and in every open collection).
  void add(const YAML::Mark& mark, std::size_t n) {
    total_ += n;
    if (total_ > kMaxYamlNodes)
      fail(mark, fmt::format("the document expands to more than {} nodes here (nested aliases?); "
                             "lensopt reads at most {}",
                             kMaxYamlNodes, kMaxYamlNodes));
    if (!open_.empty()) open_.back().nodes += n;
  }
  void record(YAML::anchor_t anchor, std::size_t n) {
    if (anchor == 0) return;
    if (anchor >= sizes_.size()) sizes_.resize(anchor + 1, 0);
    sizes_[anchor] = n;
  }
  void leaf(const YAML::Mark& mark, YAML::anchor_t anchor) {
    add(mark, 1);
    record(anchor, 1);
  }
  void open(const YAML::Mark& mark, YAML::anchor_t anchor) {
    if (open_.size() >= static_cast<std::size_t>(kMaxYamlNesting))
      fail(mark, fmt::format("lists and maps nest more than {} levels deep here; lensopt reads at "
                             "most {}",
                             kMaxYamlNesting, kMaxYamlNesting));
    add(mark, 1);
    open_.push_back({anchor, 1});
  }
  void close() {
    if (open_.empty()) return;
    const Open done = open_.back();
    open_.pop_back();
    if (!open_.empty()) open_.back().nodes += done.nodes - 1;  // the 1 was added at its start
    record(done.anchor, done.nodes);
  }

  std::string file_;
  std::vector<Open> open_;
  std::vector<std::size_t> sizes_;  // expanded nodes by anchor id (0: not closed yet)
  std::size_t aliases_ = 0;
  std::size_t total_ = 0;
};

void check_yaml_budget(const std::string& text, const std::string& source_name) {
  std::istringstream stream(text);
  YAML::Parser parser(stream);
  AliasBudget budget(source_name);
  while (parser.HandleNextDocument(budget)) {
  }
}

// Duplicate keys in any map (yaml-cpp keeps both and its lookup takes the first): an Error at the
// second naming the first's line.
void check_duplicate_keys(const YamlReader& reader, const YAML::Node& node, int depth = 0) {
  if (depth > 64) return;
  if (node.IsMap()) {
    std::map<std::string, int> first_line;
    for (const auto& item : node) {
      if (item.first.IsScalar()) {
        const std::string key = item.first.Scalar();
        const int line = item.first.Mark().line + 1;
        const auto [it, fresh] = first_line.emplace(key, line);
        if (!fresh)
          reader.fail(item.first,
                      fmt::format("duplicate key '{}' (first given at line {})", key, it->second));
      }
      check_duplicate_keys(reader, item.second, depth + 1);
    }
  } else if (node.IsSequence()) {
    for (const auto& item : node) check_duplicate_keys(reader, item, depth + 1);
  }
}

}  // namespace

Lens parse_lens_yaml(std::string_view text, const std::string& source_name) {
  YAML::Node root;
  try {
    const std::string owned(text);
    check_yaml_budget(owned, source_name);
    root = YAML::Load(owned);
  } catch (const YAML::Exception& e) {
    const SourceLocation where =
        e.mark.is_null() ? SourceLocation{source_name}
                         : SourceLocation{source_name, e.mark.line + 1, e.mark.column + 1};
    throw Error(where, fmt::format("YAML syntax error: {}", e.msg));
  }
  const YamlReader reader(source_name, root);
  check_duplicate_keys(reader, root);
  if (!root.IsMap())
    reader.fail(root,
                "expected a map with the keys stop_idx, sequence, hfov, f_number, c, t, "
                "nd, v (the paper's lens format)");

  // sequence: one letter per surface, the medium after it.
  const YAML::Node sequence_node = reader.required("sequence");
  std::string sequence;
  for (const YAML::Node& item : reader.list(sequence_node, "sequence")) sequence += item.Scalar();
  if (sequence.empty()) reader.fail(sequence_node, "sequence is empty");
  if (sequence.size() > kMaxSurfaces)
    reader.fail(sequence_node, fmt::format("sequence has {} surfaces; lensopt reads at most {}",
                                           sequence.size(), kMaxSurfaces));
  for (std::size_t i = 0; i < sequence.size(); ++i) {
    const char letter = static_cast<char>(std::toupper(static_cast<unsigned char>(sequence[i])));
    if (letter != 'G' && letter != 'A')
      reader.fail(
          sequence_node,
          fmt::format("sequence letter {} is '{}'; each must be G (glass after the surface) "
                      "or A (air)",
                      i + 1, sequence[i]));
    sequence[i] = letter;
  }
  const std::size_t surface_count = sequence.size();
  const auto glass_count =
      static_cast<std::size_t>(std::count(sequence.begin(), sequence.end(), 'G'));
  if (sequence.back() != 'A')
    reader.fail(sequence_node,
                fmt::format("sequence '{}' ends in glass; the last surface must be followed by air "
                            "(A)",
                            sequence));

  // c and t: one per surface; nd and v: one per glass.
  const YAML::Node c_node = reader.required("c");
  const YAML::Node t_node = reader.required("t");
  const std::vector<double> c = reader.numbers(c_node, "c");
  const std::vector<double> t = reader.numbers(t_node, "t");
  if (c.size() != surface_count)
    reader.fail(c_node, fmt::format("c has {} curvatures but sequence '{}' has {} surfaces",
                                    c.size(), sequence, surface_count));
  if (t.size() != surface_count)
    reader.fail(t_node, fmt::format("t has {} thicknesses but sequence '{}' has {} surfaces",
                                    t.size(), sequence, surface_count));
  std::vector<double> nd;
  std::vector<double> v;
  std::vector<YAML::Node> nd_items;
  std::vector<YAML::Node> v_items;
  if (glass_count > 0) {
    const YAML::Node nd_node = reader.required("nd");
    const YAML::Node v_node = reader.required("v");
    nd = reader.numbers(nd_node, "nd");
    v = reader.numbers(v_node, "v");
    nd_items = reader.list(nd_node, "nd");
    v_items = reader.list(v_node, "v");
    if (nd.size() != glass_count)
      reader.fail(nd_node, fmt::format("nd has {} values but sequence '{}' has {} glasses (G)",
                                       nd.size(), sequence, glass_count));
    if (v.size() != glass_count)
      reader.fail(v_node, fmt::format("v has {} values but sequence '{}' has {} glasses (G)",
                                      v.size(), sequence, glass_count));
  }

  // stop_idx: a flat surface.
  const YAML::Node stop_node = reader.single(reader.required("stop_idx"), "stop_idx");
  const int stop_index = reader.integer(stop_node, "stop_idx");
  if (stop_index < 0 || static_cast<std::size_t>(stop_index) >= surface_count)
    reader.fail(stop_node, fmt::format("stop_idx = {} is out of range: the lens has {} surfaces "
                                       "(0 to {})",
                                       stop_index, surface_count, surface_count - 1));
  if (c[stop_index] != 0.0)
    reader.fail(stop_node, fmt::format("stop_idx = {} is a curved surface (c = {} /mm); the stop "
                                       "must be flat (c = 0)",
                                       stop_index, c[stop_index]));

  Lens lens;
  lens.name = std::filesystem::path(source_name).stem().string();
  lens.source_path = source_name;
  const YAML::Node hfov_node = reader.single(reader.required("hfov"), "hfov");
  const YAML::Node f_number_node = reader.single(reader.required("f_number"), "f_number");
  lens.specs.half_field_deg = reader.number(hfov_node, "hfov");
  lens.specs.f_number = reader.number(f_number_node, "f_number");
  LensSourceLines lines;
  lines.half_field_deg = hfov_node.Mark().line + 1;
  lines.f_number = f_number_node.Mark().line + 1;
  if (!(lens.specs.half_field_deg >= 0.0 && lens.specs.half_field_deg < 89.0))
    reader.fail(hfov_node,
                fmt::format("hfov = {} must be in [0, 89) degrees", lens.specs.half_field_deg));
  if (!(lens.specs.f_number > 0.0))
    reader.fail(f_number_node, fmt::format("f_number = {} must be > 0", lens.specs.f_number));

  std::size_t glass = 0;
  for (std::size_t i = 0; i < surface_count; ++i) {
    Surface surface;
    surface.curvature_per_mm = c[i];
    surface.thickness_mm = t[i];
    surface.written_as_radius = false;
    surface.is_stop = static_cast<int>(i) == stop_index;
    if (sequence[i] == 'G') {
      if (!(nd[glass] > 1.0))
        reader.fail(nd_items[glass], fmt::format("nd[{}] = {} must be > 1", glass, nd[glass]));
      if (!(v[glass] > 0.0))
        reader.fail(v_items[glass], fmt::format("v[{}] = {} must be > 0", glass, v[glass]));
      surface.material = Material::model(nd[glass], v[glass]);
      ++glass;
    }
    lens.surfaces.push_back(surface);
  }
  validate_lens(lens, lines);
  return lens;
}

}  // namespace lensopt
