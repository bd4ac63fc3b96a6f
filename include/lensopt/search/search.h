// Scripted batch baseline search (`lensopt search`): many starting lenses, each re-optimized by
// the Levenberg-Marquardt optimizer (optimize_lens), ranked by the paper's mean RMS spot at full
// sampling, as the paper obtained its baselines ("Baseline Lenses": several starting points with
// different stop positions and cemented interfaces, re-optimized, the best kept).
//
// Candidates. A candidate is (source, layout, glass seed):
//   source  a lens file, or a generated start of n elements (a classical form: powers phi_i f of
//           {1}, {0.5, 0.5}, {1.25, -1.7, 1.4} (Cooke), {1.1, -1.8, 2.6, -1.0} (Tessar), equi-
//           convex / equi-concave elements with c_front - c_rear = phi / (nd - 1), positive
//           elements 3 mm thick, negative ones 1.2 mm, 1 mm air, 2 mm around the stop);
//   layout  where the stop is and which neighbouring elements are cemented, written as a code:
//           'E' per element, '-' air or '=' cemented between neighbours, 'S' the stop, e.g.
//           Cooke "E-E-S-E", Tessar "E-E-S-E=E", a front stop "S-E-E", a rear stop "E-E-S".
//           Moving the stop out of a gap joins that gap's two parts; into a gap splits it in
//           halves; in front it sits 0.1 f before the first vertex, behind 0.06 f after the last
//           (f the lens's paraxial EFL).
//           Cementing two air-spaced neighbours gives the joint surface the mean of the two
//           curvatures; splitting a cemented pair puts 0.2 mm of air between equal curvatures;
//   seed    0 keeps the start's glasses (a generated start: the catalog glasses nearest to
//           (nd, vd) = (1.7639, 48.49) for positive and (1.6259, 35.70) for negative elements);
//           seed k >= 1 draws each element's glass from the catalog, positive elements (thin-lens
//           power (nd - 1)(c_front - c_rear) > 0) from the glasses with vd at or above the
//           catalog's median vd (crowns), negative ones below it (flints), index
//           splitmix64(k, element) mod class size: the same on every machine.
// A modified start keeps its defocus: t_last = BFL_new + (t_last - BFL)_old (paraxial, 587.6 nm).
// Specs: a start read from a lens file keeps its own specs (f-number, half field, sensor
// diagonal) except those the search gives explicitly ([specs] or --f-number ...); generated
// starts, which have none, get the given specs or else the paper's (f/2, 25 deg, 16 mm).
//
// Order and ids. Sources in order (files as given, globs sorted, then generated element counts),
// for each the given layout first and then the variants (cement patterns in binary order, air
// before cemented from the first pair; stop positions front to rear), for each seed 0..N-1. The
// id "<source>:<layout>:g<seed>" names a candidate on every machine; the index is its place.
//
// Ranking. Candidates that ran are ranked by the final mean RMS spot (full sampling), those that
// meet every constraint first, then the others; candidates that failed (an error) last; ties by
// index. Every column of the leaderboard but `seconds` is a function of the search alone, not of
// threads, shards, interruptions or the machine's load.
//
// Results directory. search.json (the search's fingerprint: a hash of every candidate's id and
// start prescription and of the optimizer settings), results/<id>.json (one per finished
// candidate, written atomically the moment it finishes: a killed search resumes with the
// unfinished ones), leaderboard.csv, leaderboard.json and best/rankNN_<id>.toml with its Zemax
// twin best/rankNN_<id>.zmx (the best K).
// Shards: candidate i belongs to shard I of N (1-based) when i mod N = I - 1. Merging directories
// of one search unions their results and ranks them again: the leaderboard of one run.
#pragma once

#include <atomic>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "lensopt/core/random.h"  // splitmix64: the glass seeds' generator
#include "lensopt/lens/lens.h"
#include "lensopt/optimize/optimizer.h"

namespace lensopt {

// Where the stop is and which neighbouring elements are cemented.
struct LensLayout {
  int elements = 0;
  int stop_gap = 0;  // 0: before element 1; i: between elements i and i+1; n: after element n
  std::vector<bool> cemented;  // one per neighbouring pair (elements - 1)

  // "E-E-S-E=E" (see above).
  std::string code() const;
  // Whether the stop sits in a cemented joint (impossible).
  bool stop_in_cement() const;
  bool operator==(const LensLayout& other) const = default;
};

// Parses a layout code; throws Error naming the code.
LensLayout parse_layout(const std::string& code);

// One glass element: front and rear curvature (1/mm), centre thickness (mm), glass.
struct ElementForm {
  double front_curvature_per_mm = 0;
  double rear_curvature_per_mm = 0;
  double thickness_mm = 0;
  Material glass;
};

// A lens taken apart into elements, gaps and the stop, to be put together in another layout.
struct LensForm {
  LensLayout layout;
  std::vector<ElementForm> elements;
  std::vector<double> gap_mm;  // air between elements i and i+1 (0 where cemented; the whole gap
                               // where the stop sits)
  double stop_fraction = 0.5;  // share of the stop's gap before the stop
  double front_stop_mm = 0;    // stop to first vertex (stop in front)
  double rear_stop_mm = 0;     // last vertex to stop (stop behind)
  double image_mm = 0;         // last surface (element or stop) to the image plane
  double focal_length_mm = 17.156;  // paraxial EFL (587.6 nm); places a moved front or rear stop
};

// Takes a lens apart. Throws Error (naming the lens's file) if it is not a sequence of glass
// elements with one flat stop in air (e.g. an air-to-air surface that is not the stop).
LensForm decompose_lens(const Lens& lens);

// The lens of a form: `like` gives the name, catalog, specs and other tables.
Lens compose_lens(const LensForm& form, const Lens& like);

// The form in another layout (same element count): stop moved, pairs cemented or split.
// Throws Error if the layout puts the stop into a cemented joint.
LensForm with_layout(const LensForm& form, const LensLayout& layout);

// Stop positions a search may try.
struct StopPlaces {
  bool front = true;
  bool between = true;
  bool rear = true;
};

// The given layout first, then every other layout with its stop and cementing varied as asked.
std::vector<LensLayout> layout_variants(const LensLayout& given, bool vary_stop, bool vary_cement,
                                        const StopPlaces& places);

// The generated start of `elements` (1..4) elements in `layout` (its element count), glasses
// from `catalog` (seed 0), at focal length f (mm).
LensForm generated_form(const LensLayout& layout, const Catalog& catalog, double focal_length_mm);

// The default layout of a generated start: stop in the middle gap, no cemented pair.
LensLayout default_layout(int elements);

// Seeds every element's glass (see above); seed 0 leaves the form as it is.
void seed_glasses(LensForm& form, int seed, const Catalog& catalog);

// A group of starting lenses and how each is varied.
struct StartGroup {
  std::vector<std::string> lens_files;  // starting lens files (TOML, the paper's YAML, .zmx)
  std::vector<int> generate;            // generated starts: element counts (1..4)
  bool vary_stop = false;
  bool vary_cement = false;
  StopPlaces stops;
  int glass_seeds = 1;  // seeds 0..N-1 per (source, layout)
};

// What a search runs: sources, variations, specs, optimizer settings, output.
struct SearchOptions {
  std::vector<StartGroup> starts;  // in order; a source named twice gets a suffix ("cooke-2")
  std::string catalog = "ohara";   // for generated starts and glass seeds
  double f_number = 2.0;           // specs of every candidate (default: the paper's)
  double half_field_deg = 25.0;
  double sensor_diagonal_mm = 16.0;  // f = d / (2 tan hfov) = 17.156 mm
  // Which of the three the search gave explicitly: only those replace a lens file's own specs.
  bool f_number_given = false;
  bool half_field_given = false;
  bool sensor_diagonal_given = false;
  OptimizeOptions optimize;  // each candidate's optimizer settings
  // Constraints "paper+strict": two optimizations per candidate, the paper's soft penalties first
  // (they reach the basins of the paper's own designs, which cross the bounds slightly), then
  // strict bounds from that result (which walks it into the feasible set).
  bool paper_then_strict = false;
  int top_k = 5;              // best lenses written as TOML and .zmx
  int jobs = 0;               // candidates in parallel (0: every core)
  int optimizer_threads = 1;  // threads of each optimization (0: every core)
  int shard_index = 1;        // this run's shard I of N (1-based)
  int shard_count = 1;
  bool progress = true;  // one line per finished candidate on stderr

  SearchOptions();  // quiet optimizer, glass search "none" (the fast, robust setting)
  void validate() const;
};

// Reads a search description (TOML, see docs/search.md) into `options`: the [search] table's own
// start keys make one group, each [[search.starts]] table another; lens paths are resolved
// relative to the description's folder. Throws Error with file:line:column.
void read_search_description(const std::filesystem::path& path, SearchOptions& options);

// Whether a TOML file is a search description (has a [search] table) rather than a lens.
bool is_search_description(const std::filesystem::path& path);

// One candidate of the search.
struct SearchCandidate {
  int index = 0;
  std::string id;      // "<source>:<layout>:g<seed>"
  std::string source;  // file stem (made unique) or "gen<n>"
  std::string layout;  // layout code
  int glass_seed = 0;
  Lens start;         // the starting lens (when error is empty)
  std::string error;  // why the start could not be built (reported as a failed candidate)
  // From a lens file (not a generated start): optimized with the bounds `lensopt optimize` gives
  // that file (BoundsMode::kAuto: the paper's for the paper's lenses, else the lens's own).
  bool from_lens_file = false;
};

// Every candidate of the search, in order (not only the shard's). Unreadable lens files throw.
std::vector<SearchCandidate> make_candidates(const SearchOptions& options);

// The search's fingerprint: FNV-1a (64 bit, hex) over the candidates' ids and start
// prescriptions and the optimizer settings that change results (not threads or verbosity).
std::string search_fingerprint(const std::vector<SearchCandidate>& candidates,
                               const SearchOptions& options);

// Whether candidate `index` belongs to shard I of N.
bool in_shard(int index, int shard_index, int shard_count);

// Parses "I/N" (1 <= I <= N); throws Error.
void parse_shard(const std::string& text, int& shard_index, int& shard_count);

// The outcome of one candidate.
// A candidate's result: the optimize summary (the same fields and JSON keys as `lensopt optimize
// --json`; start_spot_um is the candidate's own start, seconds its wall time) and the candidate.
struct CandidateResult : OptimizeSummary {
  int index = 0;
  std::string id, source, layout;
  int glass_seed = 0;
  bool ok = false;  // the optimizer ran (else `error`)
  std::string error;
  std::string lens_toml;  // the optimized lens
  int rank = 0;           // 1-based, set by rank_results
};

// Optimizes one candidate (twice with `paper_then_strict`: paper penalties, then strict bounds
// from that result; iterations, evaluations and time are summed, the start spot is the
// candidate's own); an error (rays fail, the optimizer throws) is a result, not a throw. A
// candidate from a lens file takes bounds_for(start, options.loss, BoundsMode::kAuto).
// `interrupted` is set when options.interrupt stopped it (the result is then not final).
CandidateResult run_candidate(const SearchCandidate& candidate, const OptimizeOptions& options,
                              bool paper_then_strict, bool& interrupted);

// Result <-> JSON text (doubles round-trip exactly; +inf is written as null).
std::string result_to_json(const CandidateResult& result, const std::string& fingerprint);
CandidateResult result_from_json(const std::string& text, const std::string& source_name,
                                 std::string* fingerprint = nullptr);

// Sorts (see Ranking above) and sets rank.
void rank_results(std::vector<CandidateResult>& results);

// The leaderboard of ranked results. CSV columns: rank, id, source, layout, glass_seed, status,
// constraints_met, start_spot_um, final_spot_um, glasses, failing_constraints, kept_start,
// iterations, loss_evaluations, error, seconds.
std::string leaderboard_csv(const std::vector<CandidateResult>& ranked);
std::string leaderboard_json(const std::vector<CandidateResult>& ranked,
                             const std::string& fingerprint, int candidates_in_run);

// File name of a candidate's result and best-lens files: the id with ':' as '_'.
std::string file_safe_id(const std::string& id);

struct SearchSummary {
  int candidates_total = 0;   // in the whole search
  int candidates_in_run = 0;  // in this shard
  int resumed = 0;            // finished before this run (read from the directory)
  int ran = 0;                // finished by this run
  int failed = 0;             // errors among all finished
  int feasible = 0;           // every constraint met
  bool interrupted = false;
  double seconds = 0;                // wall time of this run
  double candidates_per_minute = 0;  // ran / wall minutes
  std::vector<CandidateResult> leaderboard;
  std::string fingerprint;
};

// Runs (or resumes) the search into `dir`. `interrupt` (may be null) stops it: unfinished
// candidates are left for the next run. Throws Error if `dir` holds another search's results.
SearchSummary run_search(const SearchOptions& options, const std::filesystem::path& dir,
                         const std::atomic<bool>* interrupt = nullptr);

// Writes the candidate list (index, id, shard) without running anything.
std::string candidate_list_text(const std::vector<SearchCandidate>& candidates,
                                const SearchOptions& options);

// Unions the results of several directories of one search (same fingerprint) into `out`
// (results/, search.json, leaderboards, best/): exactly the leaderboard of one run when the
// directories hold every candidate. Throws Error on a fingerprint mismatch.
SearchSummary merge_searches(const std::vector<std::filesystem::path>& dirs,
                             const std::filesystem::path& out, int top_k);

}  // namespace lensopt
