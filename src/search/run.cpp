// Running a search: candidates in parallel, one result file per finished candidate (resume),
// the ranking, the leaderboards, the best lenses, and merging shard directories.
#include <fmt/core.h>
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <exception>
#include <limits>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <set>
#include <thread>

#include "lensopt/analysis/analyze.h"
#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/formats/zmx.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/search/search.h"
#include "optimize/summary_json.h"
#include "search_detail.h"

namespace lensopt {
namespace {

using Clock = std::chrono::steady_clock;
namespace fs = std::filesystem;

constexpr double kInf = std::numeric_limits<double>::infinity();

std::string status_of(const CandidateResult& r) {
  return r.ok ? "ok" : "error";
}

std::string csv_field(const std::string& s) {
  if (s.find_first_of(",\"\n") == std::string::npos) return s;
  std::string out = "\"";
  for (char c : s) out += c == '"' ? std::string("\"\"") : std::string(1, c);
  return out + "\"";
}

std::string spot_text(double um) {
  return std::isfinite(um) ? fmt::format("{:.4f}", um) : "inf";
}

std::string join(const std::vector<std::string>& v, const char* sep) {
  std::string out;
  for (const std::string& s : v) out += (out.empty() ? "" : sep) + s;
  return out;
}

// search.json: the whole search (not one shard), the same in every shard's directory.
std::string search_json_text(const std::vector<SearchCandidate>& candidates,
                             const SearchOptions& options, const std::string& fingerprint) {
  nlohmann::json ids = nlohmann::json::array();
  for (const SearchCandidate& c : candidates) ids.push_back(c.id);
  nlohmann::json j;
  j["fingerprint"] = fingerprint;
  j["candidates_total"] = candidates.size();
  j["candidates"] = ids;
  j["optimize"] = detail::optimize_settings_json(options.optimize, options.paper_then_strict);
  // Given specs apply to every candidate; the others are each lens file's own (generated starts:
  // these values).
  j["specs"] = {{"f_number", options.f_number},
                {"half_field_deg", options.half_field_deg},
                {"sensor_diagonal_mm", options.sensor_diagonal_mm},
                {"given",
                 {{"f_number", options.f_number_given},
                  {"half_field_deg", options.half_field_given},
                  {"sensor_diagonal_mm", options.sensor_diagonal_given}}}};
  return j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) + "\n";
}

nlohmann::json read_json_file(const fs::path& path) {
  const std::string text = read_file(path);
  try {
    return nlohmann::json::parse(text);
  } catch (const nlohmann::json::exception& e) {
    throw Error(SourceLocation{path.string()}, fmt::format("not valid JSON: {}", e.what()));
  }
}

// Writes leaderboards and best/ into dir.
void write_outputs(const fs::path& dir, const std::vector<CandidateResult>& ranked,
                   const std::string& fingerprint, int candidates_in_run, int top_k) {
  write_file_atomic(dir / "leaderboard.csv", leaderboard_csv(ranked));
  write_file_atomic(dir / "leaderboard.json",
                    leaderboard_json(ranked, fingerprint, candidates_in_run));
  const fs::path best = dir / "best";
  fs::create_directories(best);
  std::set<std::string> keep;
  int written = 0;
  for (const CandidateResult& r : ranked) {
    if (written >= top_k) break;
    if (!r.ok || r.lens_toml.empty()) continue;
    const std::string stem = fmt::format("rank{:02d}_{}", r.rank, file_safe_id(r.id));
    write_file_atomic(best / (stem + ".toml"), r.lens_toml);
    // The same lens for OpticStudio (every GCAT its glasses need; formats/zmx.h).
    write_file_atomic(best / (stem + ".zmx"),
                      format_zmx(parse_lens_toml(r.lens_toml, (best / (stem + ".toml")).string())));
    keep.insert(stem + ".toml");
    keep.insert(stem + ".zmx");
    ++written;
  }
  // Lenses of an earlier leaderboard that are no longer among the best K.
  for (const auto& entry : fs::directory_iterator(best)) {
    const std::string name = entry.path().filename().string();
    const fs::path extension = entry.path().extension();
    if (name.rfind("rank", 0) == 0 && (extension == ".toml" || extension == ".zmx") &&
        !keep.count(name))
      fs::remove(entry.path());
  }
}

void fill_summary_counts(SearchSummary& s) {
  s.failed = 0;
  s.feasible = 0;
  for (const CandidateResult& r : s.leaderboard) {
    s.failed += !r.ok;
    s.feasible += r.ok && r.constraints_met;
  }
}

}  // namespace

std::string file_safe_id(const std::string& id) {
  std::string out = id;
  for (char& c : out)
    if (c == ':' || c == '/' || c == '\\' || c == ' ') c = '_';
  return out;
}

CandidateResult run_candidate(const SearchCandidate& candidate, const OptimizeOptions& base,
                              bool paper_then_strict, bool& interrupted) {
  interrupted = false;
  CandidateResult r;
  r.index = candidate.index;
  r.id = candidate.id;
  r.source = candidate.source;
  r.layout = candidate.layout;
  r.glass_seed = candidate.glass_seed;
  r.start_spot_um = kInf;
  r.final_spot_um = kInf;
  const auto t0 = Clock::now();
  if (!candidate.error.empty()) {
    r.error = candidate.error;
    return r;
  }
  try {
    // A lens file gets the bounds `lensopt optimize` gives it: the paper's bounds (glass 1..3 mm,
    // image clearance 12 mm) would drive a 100 mm lens's thick glasses to negative thickness.
    OptimizeOptions options = base;
    if (candidate.from_lens_file)
      options.loss = bounds_for(candidate.start, base.loss, BoundsMode::kAuto);
    OptimizeResult o;
    int stage_iterations = 0, stage_evaluations = 0;
    double start_spot_um = 0;
    bool kept_start = true;
    if (paper_then_strict) {
      OptimizeOptions soft = options;
      soft.loss.paper_penalties = true;
      const OptimizeResult first = optimize_lens(candidate.start, soft);
      if (first.interrupted) {
        interrupted = true;
        return r;
      }
      OptimizeOptions strict = options;
      strict.loss.paper_penalties = false;
      o = optimize_lens(first.lens, strict);
      stage_iterations = first.iterations;
      stage_evaluations = first.loss_evaluations;
      start_spot_um = first.start_spot_um;
      kept_start = first.kept_start;
    } else {
      o = optimize_lens(candidate.start, options);
      start_spot_um = o.start_spot_um;
    }
    if (o.interrupted) {
      interrupted = true;
      return r;
    }
    r.ok = true;
    static_cast<OptimizeSummary&>(r) = summarize(o);
    r.start_spot_um = std::isfinite(start_spot_um) ? start_spot_um : kInf;
    r.iterations = stage_iterations + o.iterations;
    r.loss_evaluations = stage_evaluations + o.loss_evaluations;
    r.kept_start = kept_start && o.kept_start;
    r.lens_toml = format_lens_toml(o.lens);
  } catch (const Error& e) {
    r.ok = false;
    r.error = e.message();
  } catch (const std::exception& e) {
    r.ok = false;
    r.error = std::string("internal error: ") + e.what();
  }
  if (!r.ok) {
    // The start's spot still tells how far off it was (when its rays trace).
    try {
      AnalyzeOptions full;
      const AnalysisReport a = analyze_lens(candidate.start, full);
      r.start_spot_um = a.mean_rms_spot_um.value_or(kInf);
    } catch (const std::exception&) {
    }
  }
  r.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  return r;
}

std::string result_to_json(const CandidateResult& r, const std::string& fingerprint) {
  nlohmann::json j;
  j["fingerprint"] = fingerprint;
  j["index"] = r.index;
  j["id"] = r.id;
  j["source"] = r.source;
  j["layout"] = r.layout;
  j["glass_seed"] = r.glass_seed;
  j["status"] = status_of(r);
  j["error"] = r.error;
  add_summary_json(j, r);
  j["lens_toml"] = r.lens_toml;
  return j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) + "\n";
}

CandidateResult result_from_json(const std::string& text, const std::string& source_name,
                                 std::string* fingerprint) {
  try {
    const nlohmann::json j = nlohmann::json::parse(text);
    CandidateResult r;
    static_cast<OptimizeSummary&>(r) = summary_from_json(j);
    r.index = j.at("index").get<int>();
    r.id = j.at("id").get<std::string>();
    r.source = j.at("source").get<std::string>();
    r.layout = j.at("layout").get<std::string>();
    r.glass_seed = j.at("glass_seed").get<int>();
    r.ok = j.at("status").get<std::string>() == "ok";
    r.error = j.at("error").get<std::string>();
    r.lens_toml = j.at("lens_toml").get<std::string>();
    if (fingerprint) *fingerprint = j.at("fingerprint").get<std::string>();
    return r;
  } catch (const nlohmann::json::exception& e) {
    throw Error(SourceLocation{source_name}, fmt::format("not a search result: {}", e.what()));
  }
}

void rank_results(std::vector<CandidateResult>& results) {
  // Class 0: ran, every constraint met; 1: ran, some constraint violated; 2: error.
  auto cls = [](const CandidateResult& r) { return !r.ok ? 2 : r.constraints_met ? 0 : 1; };
  std::sort(results.begin(), results.end(),
            [&](const CandidateResult& a, const CandidateResult& b) {
              if (cls(a) != cls(b)) return cls(a) < cls(b);
              if (a.ok && a.final_spot_um != b.final_spot_um)
                return a.final_spot_um < b.final_spot_um;
              return a.index < b.index;
            });
  for (std::size_t i = 0; i < results.size(); ++i) results[i].rank = static_cast<int>(i) + 1;
}

std::string leaderboard_csv(const std::vector<CandidateResult>& ranked) {
  std::string out =
      "rank,id,source,layout,glass_seed,status,constraints_met,start_spot_um,final_spot_um,"
      "glasses,failing_constraints,kept_start,iterations,loss_evaluations,error,seconds\n";
  for (const CandidateResult& r : ranked) {
    out += fmt::format("{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{:.2f}\n", r.rank,
                       csv_field(r.id), csv_field(r.source), csv_field(r.layout), r.glass_seed,
                       status_of(r), r.ok ? (r.constraints_met ? "yes" : "no") : "",
                       spot_text(r.start_spot_um), r.ok ? spot_text(r.final_spot_um) : "",
                       csv_field(join(r.glasses, " ")), csv_field(r.failing),
                       r.ok ? (r.kept_start ? "yes" : "no") : "", r.iterations, r.loss_evaluations,
                       csv_field(r.error), r.seconds);
  }
  return out;
}

std::string leaderboard_json(const std::vector<CandidateResult>& ranked,
                             const std::string& fingerprint, int candidates_in_run) {
  nlohmann::json rows = nlohmann::json::array();
  for (const CandidateResult& r : ranked) {
    nlohmann::json row = {
        {"rank", r.rank},         {"index", r.index},   {"id", r.id},
        {"source", r.source},     {"layout", r.layout}, {"glass_seed", r.glass_seed},
        {"status", status_of(r)}, {"error", r.error}};
    add_summary_json(row, r);
    if (!r.ok) row["final_mean_rms_spot_um"] = nlohmann::json();
    rows.push_back(std::move(row));
  }
  nlohmann::json j;
  j["fingerprint"] = fingerprint;
  j["candidates"] = candidates_in_run;
  j["finished"] = ranked.size();
  j["complete"] = static_cast<int>(ranked.size()) == candidates_in_run;
  j["leaderboard"] = rows;
  return j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) + "\n";
}

SearchSummary run_search(const SearchOptions& options, const fs::path& dir,
                         const std::atomic<bool>* interrupt) {
  options.validate();
  const auto t0 = Clock::now();
  const std::vector<SearchCandidate> candidates = make_candidates(options);
  SearchSummary summary;
  summary.fingerprint = search_fingerprint(candidates, options);
  summary.candidates_total = static_cast<int>(candidates.size());

  // The directory: a new one, or one of this very search (resume).
  std::error_code ec;
  fs::create_directories(dir / "results", ec);
  if (ec)
    throw Error(SourceLocation{dir.string()}, "cannot create the results folder: " + ec.message());
  const fs::path search_json = dir / "search.json";
  if (fs::exists(search_json)) {
    const nlohmann::json j = read_json_file(search_json);
    const std::string old = j.value("fingerprint", "");
    if (old != summary.fingerprint)
      throw Error(SourceLocation{search_json.string()},
                  fmt::format("this folder holds another search (fingerprint {}, this search {}): "
                              "its candidates, starts or optimizer settings differ; use another "
                              "output folder",
                              old, summary.fingerprint));
  } else {
    write_file_atomic(search_json, search_json_text(candidates, options, summary.fingerprint));
  }

  // Finished candidates of this shard (resume) and the ones left.
  std::vector<CandidateResult> results;
  std::vector<const SearchCandidate*> pending;
  for (const SearchCandidate& c : candidates) {
    if (!in_shard(c.index, options.shard_index, options.shard_count)) continue;
    ++summary.candidates_in_run;
    const fs::path path = dir / "results" / (file_safe_id(c.id) + ".json");
    if (!fs::exists(path)) {
      pending.push_back(&c);
      continue;
    }
    std::string fp;
    CandidateResult r = result_from_json(read_file(path), path.string(), &fp);
    if (fp != summary.fingerprint || r.id != c.id)
      throw Error(SourceLocation{path.string()},
                  "a result of another search; use another output folder");
    results.push_back(std::move(r));
    ++summary.resumed;
  }

  // Candidates in parallel: each worker takes the next pending one. Every optimization is
  // independent and single-threaded by default, so its result does not depend on the others.
  const int hardware = std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  const int jobs = std::max(1, std::min<int>(options.jobs > 0 ? options.jobs : hardware,
                                             static_cast<int>(pending.size())));
  OptimizeOptions opt = options.optimize;
  opt.sampling.threads = options.optimizer_threads;
  opt.interrupt = interrupt;
  std::atomic<int> next{0};
  std::atomic<bool> stop{false};
  std::mutex mutex;
  std::exception_ptr failure;
  int done = summary.resumed;
  auto worker = [&]() {
    // OpenMP's thread count is per thread: the analyses inside optimize_lens use it too.
    omp_set_num_threads(options.optimizer_threads > 0 ? options.optimizer_threads
                                                      : omp_get_num_procs());
    while (!stop.load()) {
      if (interrupt && interrupt->load()) break;
      const int i = next.fetch_add(1);
      if (i >= static_cast<int>(pending.size())) break;
      const SearchCandidate& c = *pending[i];
      try {
        bool interrupted = false;
        const CandidateResult r = run_candidate(c, opt, options.paper_then_strict, interrupted);
        if (interrupted) break;
        const std::string text = result_to_json(r, summary.fingerprint);
        write_file_atomic(dir / "results" / (file_safe_id(c.id) + ".json"), text);
        std::lock_guard<std::mutex> lock(mutex);
        results.push_back(result_from_json(text, c.id));  // exactly what a resumed run reads
        ++summary.ran;
        ++done;
        if (options.progress) {
          const std::string what =
              r.ok ? fmt::format("{} -> {} um, {}", spot_text(r.start_spot_um),
                                 spot_text(r.final_spot_um),
                                 r.constraints_met ? "constraints met" : "constraints violated")
                   : "error: " + r.error;
          fmt::print(stderr, "[{}/{}] {}: {} ({:.1f} s)\n", done, summary.candidates_in_run, c.id,
                     what, r.seconds);
        }
      } catch (...) {
        std::lock_guard<std::mutex> lock(mutex);
        if (!failure) failure = std::current_exception();
        stop.store(true);
      }
    }
  };
  std::vector<std::thread> threads;
  for (int t = 0; t < jobs && !pending.empty(); ++t) threads.emplace_back(worker);
  for (std::thread& t : threads) t.join();
  if (failure) std::rethrow_exception(failure);

  summary.interrupted = static_cast<int>(results.size()) < summary.candidates_in_run;
  rank_results(results);
  summary.leaderboard = results;
  fill_summary_counts(summary);
  write_outputs(dir, summary.leaderboard, summary.fingerprint, summary.candidates_in_run,
                options.top_k);
  summary.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  summary.candidates_per_minute = summary.seconds > 0 ? summary.ran * 60.0 / summary.seconds : 0.0;
  return summary;
}

SearchSummary merge_searches(const std::vector<fs::path>& dirs, const fs::path& out, int top_k) {
  if (dirs.empty()) throw Error("merge: give the result folders to merge");
  if (top_k < 0) throw Error(fmt::format("top = {} must be >= 0", top_k));
  SearchSummary summary;
  std::string search_text;
  std::vector<std::string> ids;
  std::map<std::string, std::pair<CandidateResult, std::string>> by_id;  // result, its file text
  for (const fs::path& dir : dirs) {
    const fs::path sj = dir / "search.json";
    if (!fs::exists(sj))
      throw Error(SourceLocation{dir.string()}, "not a search folder (no search.json)");
    const nlohmann::json j = read_json_file(sj);
    const std::string fp = j.value("fingerprint", "");
    if (search_text.empty()) {
      search_text = read_file(sj);
      summary.fingerprint = fp;
      ids = j.at("candidates").get<std::vector<std::string>>();
    } else if (fp != summary.fingerprint) {
      throw Error(
          SourceLocation{sj.string()},
          fmt::format("another search (fingerprint {}, the first folder's {}): only shards of "
                      "one search merge",
                      fp, summary.fingerprint));
    }
    const fs::path results = dir / "results";
    if (!fs::is_directory(results)) continue;
    std::vector<fs::path> files;
    for (const auto& entry : fs::directory_iterator(results))
      if (entry.path().extension() == ".json") files.push_back(entry.path());
    std::sort(files.begin(), files.end());
    for (const fs::path& f : files) {
      const std::string text = read_file(f);
      std::string rfp;
      CandidateResult r = result_from_json(text, f.string(), &rfp);
      if (rfp != summary.fingerprint)
        throw Error(SourceLocation{f.string()}, "a result of another search");
      const std::string id = r.id;
      by_id.emplace(id, std::make_pair(std::move(r), text));  // the first folder's copy wins
    }
  }
  const std::set<std::string> known(ids.begin(), ids.end());
  fs::create_directories(out / "results");
  if (fs::exists(out / "search.json")) {
    if (read_json_file(out / "search.json").value("fingerprint", "") != summary.fingerprint)
      throw Error(SourceLocation{(out / "search.json").string()},
                  "the output folder holds another search; merge into a new folder");
  } else {
    write_file_atomic(out / "search.json", search_text);
  }
  std::vector<CandidateResult> merged;
  for (auto& [id, entry] : by_id) {
    if (!known.count(id))
      throw Error(fmt::format("merge: result '{}' is not a candidate of this search", id));
    const fs::path target = out / "results" / (file_safe_id(id) + ".json");
    if (!fs::exists(target)) write_file_atomic(target, entry.second);
    merged.push_back(entry.first);
  }
  summary.candidates_total = static_cast<int>(ids.size());
  summary.candidates_in_run = summary.candidates_total;
  summary.resumed = static_cast<int>(merged.size());
  summary.interrupted = summary.resumed < summary.candidates_total;
  rank_results(merged);
  summary.leaderboard = merged;
  fill_summary_counts(summary);
  write_outputs(out, summary.leaderboard, summary.fingerprint, summary.candidates_total, top_k);
  return summary;
}

}  // namespace lensopt
