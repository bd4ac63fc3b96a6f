// The batch search: layouts (stop positions, cementing) and their codes, taking lenses apart and
// putting them together, the deterministic candidate list and glass seeds, generated starts,
// shards, the ranking (infeasible after feasible, errors last), result files, and that a resumed
// search and merged shards give the leaderboard of one run.
#include <doctest/doctest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>

#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/search/search.h"
#include "optimize/summary_json.h"
#include "test_support.h"

namespace test_search {

using namespace lensopt;
namespace fs = std::filesystem;

namespace {

Lens project_lens(const std::string& name) {
  return read_lens(test::source_dir() / "lenses" / (name + ".toml"));
}

std::string lens_path(const std::string& name) {
  return (test::source_dir() / "lenses" / (name + ".toml")).string();
}

std::vector<std::string> codes(const std::vector<LensLayout>& layouts) {
  std::vector<std::string> out;
  for (const LensLayout& l : layouts) out.push_back(l.code());
  return out;
}

// A leaderboard CSV without its last column (seconds, the one wall-clock field).
std::string without_seconds(const std::string& csv) {
  std::istringstream in(csv);
  std::string line, out;
  while (std::getline(in, line)) out += line.substr(0, line.rfind(',')) + "\n";
  return out;
}

fs::path fresh_dir(const std::string& name) {
  const fs::path dir = test::temp_root() / ("search-" + name);
  fs::remove_all(dir);
  return dir;
}

CandidateResult fake(int index, bool ok, bool met, double final_um) {
  CandidateResult r;
  r.index = index;
  r.id = "c" + std::to_string(index);
  r.ok = ok;
  r.constraints_met = met;
  r.final_spot_um = final_um;
  r.start_spot_um = 100;
  if (!ok) r.error = "rays fail";
  return r;
}

// A tiny but real search: the doublet with its stop in front, between and behind (the optimizer
// rejects a rear stop: an error row), two glass seeds, coarse sampling, few iterations.
SearchOptions tiny_search() {
  SearchOptions o;
  o.starts.push_back(StartGroup{});
  o.starts[0].lens_files = {lens_path("doublet")};
  o.starts[0].vary_stop = true;
  o.starts[0].glass_seeds = 2;
  o.optimize.sampling.rings = 3;
  o.optimize.sampling.fields = 3;
  o.optimize.max_iterations = 3;
  o.optimize.max_rounds = 1;
  o.top_k = 2;
  o.progress = false;
  return o;
}

}  // namespace

TEST_CASE("search: layout codes round-trip and reject malformed codes") {
  for (const char* code :
       {"E-E-S-E", "E-E-S-E=E", "S-E", "E-S", "S-E=E-E", "E=E-S-E=E", "E-E-E-S"}) {
    CAPTURE(code);
    CHECK(parse_layout(code).code() == code);
  }
  const LensLayout tessar = parse_layout("E-E-S-E=E");
  CHECK(tessar.elements == 4);
  CHECK(tessar.stop_gap == 2);
  CHECK(tessar.cemented == std::vector<bool>{false, false, true});
  for (const char* bad : {"", "E", "E-E", "S-S-E", "E=S-E", "E-S=E", "EE-S", "E-X-S", "E-E-S-"})
    CHECK_THROWS_AS(parse_layout(bad), Error);
}

TEST_CASE("search: baselines come apart and go back together unchanged") {
  for (const char* name : {"singlet", "doublet", "cooke", "tessar"}) {
    CAPTURE(name);
    const Lens lens = project_lens(name);
    const LensForm form = decompose_lens(lens);
    const Lens back = compose_lens(form, lens);
    REQUIRE(back.surfaces.size() == lens.surfaces.size());
    for (std::size_t k = 0; k < lens.surfaces.size(); ++k) {
      CAPTURE(k);
      CHECK(back.surfaces[k].curvature_per_mm == lens.surfaces[k].curvature_per_mm);
      CHECK(back.surfaces[k].thickness_mm ==
            doctest::Approx(lens.surfaces[k].thickness_mm).epsilon(1e-12));
      CHECK(back.surfaces[k].is_stop == lens.surfaces[k].is_stop);
      CHECK(back.surfaces[k].material.label() == lens.surfaces[k].material.label());
    }
  }
  CHECK(decompose_lens(project_lens("cooke")).layout.code() == "E-E-S-E");
  CHECK(decompose_lens(project_lens("tessar")).layout.code() == "E-E-S-E=E");
  CHECK(decompose_lens(project_lens("doublet")).layout.code() == "E-S-E");
  CHECK(decompose_lens(project_lens("singlet")).layout.code() == "S-E");
}

TEST_CASE("search: stop positions and cementing enumerate every consistent layout once") {
  const LensLayout cooke = parse_layout("E-E-S-E");
  CHECK(codes(layout_variants(cooke, false, false, {})) == std::vector<std::string>{"E-E-S-E"});
  CHECK(codes(layout_variants(cooke, true, false, {})) ==
        std::vector<std::string>{"E-E-S-E", "S-E-E-E", "E-S-E-E", "E-E-E-S"});
  CHECK(codes(layout_variants(cooke, true, false, StopPlaces{false, true, false})) ==
        std::vector<std::string>{"E-E-S-E", "E-S-E-E"});
  // Cementing only: the stop's gap stays air.
  CHECK(codes(layout_variants(cooke, false, true, {})) ==
        std::vector<std::string>{"E-E-S-E", "E=E-S-E"});
  // Both, 3 elements: patterns (air, air) 4 stops, (air, cem) 3, (cem, air) 3, (cem, cem) 2.
  const auto all = layout_variants(cooke, true, true, {});
  CHECK(all.size() == 12);
  CHECK(all.front().code() == "E-E-S-E");
  std::set<std::string> unique;
  for (const LensLayout& l : all) {
    CHECK_FALSE(l.stop_in_cement());
    unique.insert(l.code());
  }
  CHECK(unique.size() == all.size());
  // 4 elements: 8 patterns; stops at front and rear always, between where the gap is air.
  CHECK(layout_variants(parse_layout("E-E-S-E=E"), true, true, {}).size() == 8 * 2 + 12);
}

TEST_CASE(
    "search: moving the stop keeps the elements and the gap lengths; cementing joins surfaces") {
  const Lens cooke = project_lens("cooke");
  const LensForm form = decompose_lens(cooke);
  // Stop to the front: the elements are untouched, the old stop gap keeps its full length.
  const Lens front = compose_lens(with_layout(form, parse_layout("S-E-E-E")), cooke);
  REQUIRE(front.surfaces.size() == cooke.surfaces.size());
  CHECK(front.stop_index() == 0);
  CHECK(form.focal_length_mm == doctest::Approx(17.156).epsilon(0.05));  // the paraxial EFL
  CHECK(front.surfaces[0].thickness_mm == doctest::Approx(0.1 * form.focal_length_mm));
  CHECK(front.surfaces[1].curvature_per_mm == cooke.surfaces[0].curvature_per_mm);
  CHECK(front.surfaces[4].thickness_mm ==
        doctest::Approx(cooke.surfaces[3].thickness_mm + cooke.surfaces[4].thickness_mm));
  CHECK(decompose_lens(front).layout.code() == "S-E-E-E");
  // Stop into the first gap: split in halves.
  const Lens first_gap = compose_lens(with_layout(form, parse_layout("E-S-E-E")), cooke);
  CHECK(first_gap.stop_index() == 2);
  CHECK(first_gap.surfaces[1].thickness_mm ==
        doctest::Approx(0.5 * cooke.surfaces[1].thickness_mm));
  CHECK(first_gap.surfaces[2].thickness_mm ==
        doctest::Approx(0.5 * cooke.surfaces[1].thickness_mm));
  // Cement elements 1 and 2: one joint with the mean curvature, one surface fewer.
  const Lens cemented = compose_lens(with_layout(form, parse_layout("E=E-S-E")), cooke);
  REQUIRE(cemented.surfaces.size() == cooke.surfaces.size() - 1);
  CHECK(cemented.surfaces[1].curvature_per_mm ==
        doctest::Approx(0.5 *
                        (cooke.surfaces[1].curvature_per_mm + cooke.surfaces[2].curvature_per_mm)));
  CHECK(cemented.surfaces[1].material.label() == "S-TIM1");
  CHECK(cemented.surfaces[1].thickness_mm == cooke.surfaces[2].thickness_mm);
  // The stop cannot sit in a cemented joint.
  CHECK_THROWS_AS(with_layout(form, LensLayout{3, 2, {false, true}}), Error);
  // Split the Tessar's cemented pair: 0.2 mm of air between equal curvatures.
  const Lens tessar = project_lens("tessar");
  const Lens split =
      compose_lens(with_layout(decompose_lens(tessar), parse_layout("E-E-S-E-E")), tessar);
  REQUIRE(split.surfaces.size() == tessar.surfaces.size() + 1);
  CHECK(split.surfaces[6].material.is_air());
  CHECK(split.surfaces[6].thickness_mm == doctest::Approx(0.2));
  CHECK(split.surfaces[6].curvature_per_mm == split.surfaces[7].curvature_per_mm);
}

TEST_CASE(
    "search: the candidate list is deterministic; seed 0 is the file, seeds draw crowns and "
    "flints") {
  SearchOptions o;
  StartGroup g;
  g.lens_files = {lens_path("cooke")};
  g.generate = {2, 3, 4};
  g.vary_stop = true;
  g.vary_cement = true;
  g.glass_seeds = 3;
  o.starts = {g};
  const auto a = make_candidates(o);
  const auto b = make_candidates(o);
  REQUIRE(a.size() == b.size());
  // Cooke: 12 layouts; generated 2: 5, 3: 12, 4: 28; three seeds each.
  CHECK(a.size() == 3 * (12 + 5 + 12 + 28));
  for (std::size_t i = 0; i < a.size(); ++i) {
    CHECK(a[i].index == static_cast<int>(i));
    CHECK(a[i].id == b[i].id);
    CHECK(a[i].error == b[i].error);
    if (a[i].error.empty()) CHECK(format_lens_toml(a[i].start) == format_lens_toml(b[i].start));
  }
  CHECK(search_fingerprint(a, o) == search_fingerprint(b, o));
  std::set<std::string> ids;
  for (const auto& c : a) ids.insert(c.id);
  CHECK(ids.size() == a.size());
  CHECK(a[0].id == "cooke:E-E-S-E:g0");
  CHECK(a[1].id == "cooke:E-E-S-E:g1");
  // Seed 0 of the given layout is the file itself, with the search's specs.
  const Lens cooke = project_lens("cooke");
  REQUIRE(a[0].error.empty());
  REQUIRE(a[0].start.surfaces.size() == cooke.surfaces.size());
  for (std::size_t k = 0; k < cooke.surfaces.size(); ++k) {
    CHECK(a[0].start.surfaces[k].curvature_per_mm == cooke.surfaces[k].curvature_per_mm);
    CHECK(a[0].start.surfaces[k].thickness_mm == cooke.surfaces[k].thickness_mm);
  }
  // Seed k: positive elements get glasses at or above the catalog's median vd, negative below.
  const auto catalog = load_catalog("ohara");
  std::vector<double> vds;
  for (const Glass& g : catalog->glasses) vds.push_back(g.vd);
  std::sort(vds.begin(), vds.end());
  const double median_vd = vds[vds.size() / 2];
  std::set<std::string> seeded;
  for (const auto& c : a) {
    if (c.glass_seed == 0 || !c.error.empty()) continue;
    for (const ElementForm& e : decompose_lens(c.start).elements) {
      REQUIRE(e.glass.kind == Material::Kind::kCatalog);
      const bool positive = (e.front_curvature_per_mm - e.rear_curvature_per_mm) >= 0;
      if (positive)
        CHECK(e.glass.vd >= median_vd);
      else
        CHECK(e.glass.vd < median_vd);
      seeded.insert(e.glass.glass_name);
    }
  }
  CHECK(seeded.size() >= 4);  // the seeds do vary the glasses
  // Another option that changes results changes the fingerprint.
  SearchOptions other = o;
  other.optimize.sampling.rings = 5;
  CHECK(search_fingerprint(a, other) != search_fingerprint(a, o));
}

TEST_CASE("search: generated starts have the asked layout and a traceable first order") {
  for (int n = 1; n <= 4; ++n) {
    SearchOptions o;
    StartGroup g;
    g.generate = {n};
    g.vary_stop = true;
    g.vary_cement = true;
    g.stops = StopPlaces{true, true, false};
    o.starts = {g};
    for (const SearchCandidate& c : make_candidates(o)) {
      CAPTURE(c.id);
      REQUIRE(c.error.empty());
      CHECK(decompose_lens(c.start).layout.code() == c.layout);
      CHECK(c.start.element_count() >= 1);
      CHECK(c.start.surfaces.back().thickness_mm > 0.0);  // the paraxial focus is behind the lens
      CHECK(c.start.specs.focal_length_mm() == doctest::Approx(17.156).epsilon(1e-4));
    }
  }
}

TEST_CASE("search: shards partition the candidates; --shard parses I/N") {
  for (int n = 1; n <= 5; ++n) {
    for (int index = 0; index < 40; ++index) {
      int owners = 0;
      for (int i = 1; i <= n; ++i) owners += in_shard(index, i, n);
      CHECK(owners == 1);
    }
  }
  int i = 0, n = 0;
  parse_shard("2/8", i, n);
  CHECK(i == 2);
  CHECK(n == 8);
  for (const char* bad : {"0/3", "4/3", "3", "a/b", "1/0", "1/3x", "/3"})
    CHECK_THROWS_AS(parse_shard(bad, i, n), Error);
}

TEST_CASE("search: ranking puts feasible designs first, then infeasible ones, then errors") {
  std::vector<CandidateResult> r = {fake(0, true, false, 10.0), fake(1, false, false, 0.0),
                                    fake(2, true, true, 30.0),  fake(3, true, true, 20.0),
                                    fake(4, true, true, 20.0),  fake(5, true, false, INFINITY)};
  rank_results(r);
  std::vector<int> order;
  for (const auto& x : r) order.push_back(x.index);
  CHECK(order == std::vector<int>{3, 4, 2, 0, 5, 1});
  for (std::size_t k = 0; k < r.size(); ++k) CHECK(r[k].rank == static_cast<int>(k) + 1);
  const std::string csv = leaderboard_csv(r);
  CHECK(csv.rfind("rank,id,", 0) == 0);
  CHECK(csv.find("\n1,c3,") != std::string::npos);
}

TEST_CASE("search: result files round-trip exactly, an infinite spot as null") {
  CandidateResult r = fake(7, true, false, 12.345678901234567);
  r.start_spot_um = INFINITY;
  r.glasses = {"S-LAH96", "S-TIM1"};
  r.failing = "ray angle = 61.0000 (<= 60.000)";
  r.lens_toml = "[lens]\nname = \"x\"\n";
  r.seconds = 1.25;
  const std::string text = result_to_json(r, "abc");
  CHECK(text.find("Infinity") == std::string::npos);
  std::string fp;
  const CandidateResult back = result_from_json(text, "t.json", &fp);
  CHECK(fp == "abc");
  CHECK(back.final_spot_um == r.final_spot_um);
  CHECK(std::isinf(back.start_spot_um));
  CHECK(back.glasses == r.glasses);
  CHECK(back.failing == r.failing);
  CHECK(back.lens_toml == r.lens_toml);
  CHECK(result_to_json(back, "abc") == text);
  CHECK_THROWS_AS(result_from_json("{}", "t.json"), Error);
}

TEST_CASE("search: a candidate's result carries optimize --json's keys for the optimize summary") {
  // One serializer (optimize/summary_json.h): the summary's keys and values are those that
  // `lensopt optimize --json` writes, and a search result file holds them unchanged.
  CandidateResult r = fake(3, true, true, 4.5);
  r.glasses = {"N-BK7"};
  r.iterations = 17;
  r.loss_evaluations = 40;
  nlohmann::json summary;
  add_summary_json(summary, r);
  const nlohmann::json file = nlohmann::json::parse(result_to_json(r, "fp"));
  for (const char* key : {"start_mean_rms_spot_um", "final_mean_rms_spot_um", "constraints_met",
                          "failing_constraints", "glasses", "iterations", "loss_evaluations",
                          "kept_start", "seconds"}) {
    INFO(key);
    REQUIRE(summary.contains(key));
    CHECK(file.at(key) == summary.at(key));
  }
  CHECK(file.at("final_mean_rms_spot_um").get<double>() == 4.5);
  const OptimizeSummary back = summary_from_json(summary);
  CHECK(back.iterations == 17);
  CHECK(back.glasses == r.glasses);
}

TEST_CASE("search: one run, a resumed run and merged shards give the same leaderboard") {
  const SearchOptions o = tiny_search();
  const auto candidates = make_candidates(o);
  REQUIRE(candidates.size() == 6);  // E-S-E, S-E-E, E-E-S, two seeds each

  // One run, two candidates at a time.
  const fs::path one = fresh_dir("one");
  SearchOptions parallel = o;
  parallel.jobs = 2;
  const SearchSummary s = run_search(parallel, one);
  CHECK(s.ran == 6);
  CHECK_FALSE(s.interrupted);
  CHECK(s.failed == 2);  // the rear stop: reported and skipped, not fatal
  CHECK(s.leaderboard.back().ok == false);
  CHECK(s.leaderboard.front().ok);
  const std::string reference = without_seconds(read_file(one / "leaderboard.csv"));
  CHECK(fs::exists(one / "best"));
  int best_files = 0;
  for (const auto& e : fs::directory_iterator(one / "best"))
    best_files += e.path().extension() == ".toml";
  CHECK(best_files == 2);

  // Resume: a run killed after two candidates left their result files; the rest is redone.
  const fs::path resumed = fresh_dir("resumed");
  fs::create_directories(resumed / "results");
  fs::copy_file(one / "search.json", resumed / "search.json");
  for (int i : {0, 3}) {
    const std::string name = file_safe_id(candidates[i].id) + ".json";
    fs::copy_file(one / "results" / name, resumed / "results" / name);
  }
  SearchOptions serial = o;
  serial.jobs = 1;
  const SearchSummary r = run_search(serial, resumed);
  CHECK(r.resumed == 2);
  CHECK(r.ran == 4);
  CHECK(without_seconds(read_file(resumed / "leaderboard.csv")) == reference);
  // Rerunning a finished search does nothing and changes nothing.
  const SearchSummary again = run_search(serial, resumed);
  CHECK(again.ran == 0);
  CHECK(without_seconds(read_file(resumed / "leaderboard.csv")) == reference);

  // Three shards, merged.
  std::vector<fs::path> shards;
  for (int i = 1; i <= 3; ++i) {
    SearchOptions shard = serial;
    shard.shard_index = i;
    shard.shard_count = 3;
    shards.push_back(fresh_dir("shard" + std::to_string(i)));
    const SearchSummary ss = run_search(shard, shards.back());
    CHECK(ss.candidates_in_run == 2);
  }
  const fs::path merged = fresh_dir("merged");
  const SearchSummary m = merge_searches(shards, merged, o.top_k);
  CHECK(m.resumed == 6);
  CHECK_FALSE(m.interrupted);
  CHECK(without_seconds(read_file(merged / "leaderboard.csv")) == reference);

  // Another search's folder is refused, for runs and merges.
  SearchOptions different = serial;
  different.optimize.max_iterations = 4;
  CHECK_THROWS_AS(run_search(different, one), Error);
  const fs::path other = fresh_dir("other");
  different.starts = {StartGroup{}};
  different.starts[0].lens_files = {lens_path("singlet")};
  run_search(different, other);
  CHECK_THROWS_AS(merge_searches({one, other}, fresh_dir("bad-merge"), 1), Error);
  for (const char* d :
       {"one", "resumed", "shard1", "shard2", "shard3", "merged", "other", "bad-merge"})
    fs::remove_all(test::temp_root() / (std::string("search-") + d));
}

TEST_CASE(
    "search: a description's start groups, specs and optimizer settings; bad keys name file:line") {
  const fs::path dir = fresh_dir("description");
  fs::create_directories(dir);
  const std::string lenses = (test::source_dir() / "lenses").string();
  write_file_atomic(
      dir / "s.toml",
      "[search]\nvary_stop = true\nstops = [\"front\", \"between\"]\ntop = 3\n"
      "[[search.starts]]\nlenses = [\"" +
          lenses +
          "/cooke.toml\"]\n"
          "vary_cement = true\n"
          "[[search.starts]]\ngenerate = [2]\nvary_stop = false\nglass_seeds = 2\n"
          "[specs]\nfocal_length_mm = 20.0\n"
          "[optimize]\nglass_search = \"snap\"\nconstraints = \"paper\"\nrings = 6\n");
  CHECK(is_search_description(dir / "s.toml"));
  CHECK_FALSE(is_search_description(test::source_dir() / "lenses" / "cooke.toml"));
  SearchOptions o;
  read_search_description(dir / "s.toml", o);
  REQUIRE(o.starts.size() == 2);
  CHECK(o.starts[0].lens_files.size() == 1);
  CHECK(o.starts[0].vary_stop);  // inherited from [search]
  CHECK(o.starts[0].vary_cement);
  CHECK_FALSE(o.starts[0].stops.rear);
  CHECK(o.starts[1].generate == std::vector<int>{2});
  CHECK_FALSE(o.starts[1].vary_stop);
  CHECK(o.starts[1].glass_seeds == 2);
  CHECK(o.top_k == 3);
  CHECK(o.sensor_diagonal_mm == doctest::Approx(2.0 * 20.0 * std::tan(25.0 * M_PI / 180.0)));
  CHECK(o.optimize.glass_search == GlassSearch::kSnap);
  CHECK(o.optimize.loss.paper_penalties);
  CHECK(o.optimize.sampling.rings == 6);
  o.validate();
  {
    // A requested F-number below 0.5 (an image-space NA above 1) is refused before any work,
    // even for a start that, traced as written, may have a paraxial F-number below 0.5.
    SearchOptions fast = o;
    fast.f_number = 0.4;
    fast.f_number_given = true;
    CHECK_THROWS_WITH(fast.validate(), doctest::Contains("f_number = 0.4 must be in [0.5, 1000]"));
  }
  // Cooke: stops front, between (2 gaps), cementing: 4 patterns -> 1 + ... ; generated: 1 layout
  // x 2.
  const auto candidates = make_candidates(o);
  CHECK(candidates.back().id == "gen2:E-S-E:g1");
  CHECK(candidates.front().start.specs.focal_length_mm() == doctest::Approx(20.0));

  write_file_atomic(dir / "bad.toml", "[search]\nlenses = []\nvary_stops = true\n");
  SearchOptions bad;
  try {
    read_search_description(dir / "bad.toml", bad);
    FAIL("unknown key accepted");
  } catch (const Error& e) {
    CHECK(std::string(e.what()).find("bad.toml:3:") != std::string::npos);
    CHECK(std::string(e.what()).find("vary_stops") != std::string::npos);
  }
  fs::remove_all(dir);
}

TEST_CASE("search: paper+strict runs the paper's penalties, then strict bounds from that result") {
  SearchOptions o = tiny_search();
  o.starts[0].vary_stop = false;
  o.starts[0].glass_seeds = 1;
  const auto candidates = make_candidates(o);
  REQUIRE(candidates.size() == 1);
  SearchOptions two_stage = o;
  two_stage.paper_then_strict = true;
  CHECK(search_fingerprint(candidates, two_stage) != search_fingerprint(candidates, o));
  bool interrupted = false;
  const CandidateResult single = run_candidate(candidates[0], o.optimize, false, interrupted);
  const CandidateResult both = run_candidate(candidates[0], o.optimize, true, interrupted);
  CHECK_FALSE(interrupted);
  REQUIRE(single.ok);
  REQUIRE(both.ok);
  CHECK(both.start_spot_um == single.start_spot_um);  // the candidate's own start
  CHECK(both.iterations > single.iterations);         // two optimizations
  CHECK(std::isfinite(both.final_spot_um));
}

TEST_CASE("search: a lens file keeps its own specs unless the search gives them") {
  // An f/2.8, 30 deg start (the Cooke with its specs changed).
  Lens cooke = read_lens(lens_path("cooke"));
  cooke.specs.f_number = 2.8;
  cooke.specs.half_field_deg = 30.0;
  cooke.specs.sensor_diagonal_mm = 20.0;
  const auto dir = std::filesystem::temp_directory_path() /
                   ("lensopt_search_specs_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const auto path = dir / "cooke28.toml";
  write_lens(cooke, path);
  SearchOptions o;
  StartGroup g;
  g.lens_files = {path.string()};
  g.generate = {2};
  o.starts = {g};
  for (const SearchCandidate& c : make_candidates(o)) {
    CAPTURE(c.id);
    if (c.source == "gen2") {
      CHECK(c.start.specs.f_number == 2.0);  // generated: the paper's defaults
      CHECK(c.start.specs.half_field_deg == 25.0);
    } else {
      CHECK(c.start.specs.f_number == 2.8);  // a file: its own
      CHECK(c.start.specs.half_field_deg == 30.0);
      CHECK(c.start.specs.sensor_diagonal_mm == 20.0);
    }
  }
  // Given explicitly, a spec replaces the file's own, and only that one.
  o.f_number = 4.0;
  o.f_number_given = true;
  for (const SearchCandidate& c : make_candidates(o)) {
    CAPTURE(c.id);
    CHECK(c.start.specs.f_number == 4.0);
    if (c.source != "gen2") CHECK(c.start.specs.half_field_deg == 30.0);
  }
  std::filesystem::remove_all(dir);
}

}  // namespace test_search
