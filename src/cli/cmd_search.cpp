// lensopt search [DESCRIPTION.toml] [LENS...] -o DIR: batch baseline search (many starts, each
// optimized with Levenberg-Marquardt, ranked by the mean spot); `lensopt search merge DIR...`
// combines the folders of shards.
#include <fmt/core.h>

#include <cmath>
#include <filesystem>
#include <memory>

#include "commands.h"
#include "lensopt/core/atomic_file.h"
#include "lensopt/core/constants.h"
#include "lensopt/core/error.h"
#include "lensopt/core/interrupt.h"
#include "lensopt/core/output_checks.h"
#include "lensopt/search/search.h"
#include "optimize/optimize_table.h"

namespace lensopt::cli {
namespace {

struct SearchCommand {
  std::vector<std::string> inputs;
  std::string output;
  bool vary_stop = false, vary_cement = false, list = false, quiet = false, no_soft_start = false;
  std::vector<int> generate;
  std::vector<std::string> stops;
  int glass_seeds = -1, top = -1, jobs = -1, threads = -1;
  std::string shard, glass_search, constraints;
  int rings = -1, fields = -1, max_iterations = -1, max_rounds = -1, neighbours = -1;
  double f_number = NAN, half_field_deg = NAN, focal_length_mm = NAN;
};

struct MergeCommand {
  std::vector<std::string> dirs;
  std::string output;
  int top = 5;
};

void print_leaderboard(const SearchSummary& s, int rows) {
  fmt::print("  rank  final (um)  start (um)  constraints  id\n");
  int shown = 0;
  for (const CandidateResult& r : s.leaderboard) {
    if (shown++ >= rows) break;
    if (!r.ok) {
      fmt::print("  {:4d}  {:>10}  {:>10}  {:<11}  {}: {}\n", r.rank, "-", "-", "error", r.id,
                 r.error);
      continue;
    }
    fmt::print("  {:4d}  {:10.3f}  {:10.3f}  {:<11}  {}\n", r.rank, r.final_spot_um,
               r.start_spot_um, r.constraints_met ? "met" : "violated", r.id);
  }
  if (static_cast<int>(s.leaderboard.size()) > rows)
    fmt::print("  ... {} more in leaderboard.csv\n", s.leaderboard.size() - rows);
}

void run_search_command(const SearchCommand& cmd) {
  SearchOptions options;
  std::string first_stem;
  StartGroup cli_group;  // lenses and --generate of the command line
  for (const std::string& input : cmd.inputs) {
    const std::filesystem::path p(input);
    if (first_stem.empty()) first_stem = p.stem().string();
    if (p.extension() == ".toml" && std::filesystem::exists(p) && is_search_description(p))
      read_search_description(p, options);
    else
      cli_group.lens_files.push_back(input);
  }
  cli_group.generate = cmd.generate;
  if (first_stem.empty() && !cmd.generate.empty())
    first_stem = fmt::format("gen{}", cmd.generate[0]);
  if (!cli_group.lens_files.empty() || !cli_group.generate.empty())
    options.starts.push_back(cli_group);
  // The variation flags apply to every group (the description's too) when given.
  StopPlaces stops{false, false, false};
  for (const std::string& s : cmd.stops) {
    if (s == "front")
      stops.front = true;
    else if (s == "between")
      stops.between = true;
    else if (s == "rear")
      stops.rear = true;
    else
      throw Error(SourceLocation{"--stops"}, fmt::format("'{}' must be front, between or rear", s));
  }
  for (StartGroup& g : options.starts) {
    if (cmd.vary_stop) g.vary_stop = true;
    if (cmd.vary_cement) g.vary_cement = true;
    if (!cmd.stops.empty()) g.stops = stops;
    if (cmd.glass_seeds > 0) g.glass_seeds = cmd.glass_seeds;
  }
  if (cmd.top >= 0) options.top_k = cmd.top;
  if (cmd.jobs >= 0) options.jobs = cmd.jobs;
  if (cmd.threads >= 0) options.optimizer_threads = cmd.threads;
  if (!cmd.shard.empty()) parse_shard(cmd.shard, options.shard_index, options.shard_count);
  if (!cmd.glass_search.empty())
    options.optimize.glass_search =
        parse_glass_search(cmd.glass_search, SourceLocation{"--glass-search"});
  if (!cmd.constraints.empty()) {
    options.optimize.loss.paper_penalties = cmd.constraints == "paper";
    options.paper_then_strict = cmd.constraints == "paper+strict";
  }
  if (cmd.rings > 0) options.optimize.sampling.rings = cmd.rings;
  if (cmd.fields > 0) options.optimize.sampling.fields = cmd.fields;
  if (cmd.max_iterations > 0) options.optimize.max_iterations = cmd.max_iterations;
  if (cmd.max_rounds > 0) options.optimize.max_rounds = cmd.max_rounds;
  if (cmd.no_soft_start) options.optimize.soft_start = false;
  if (cmd.neighbours >= 0) options.optimize.glass_neighbours = cmd.neighbours;
  if (!std::isnan(cmd.f_number)) {
    options.f_number = cmd.f_number;
    options.f_number_given = true;
  }
  if (!std::isnan(cmd.half_field_deg)) {
    options.half_field_deg = cmd.half_field_deg;
    options.half_field_given = true;
  }
  if (!std::isnan(cmd.focal_length_mm)) {
    options.sensor_diagonal_mm =
        2.0 * cmd.focal_length_mm * std::tan(options.half_field_deg * kPi / 180.0);
    options.sensor_diagonal_given = true;
  }
  options.progress = !cmd.quiet;
  options.validate();

  if (cmd.list) {
    fmt::print("{}", candidate_list_text(make_candidates(options), options));
    return;
  }
  std::string out = cmd.output;
  if (out.empty()) {
    out = "search-" + first_stem;
    if (options.shard_count > 1)
      out += fmt::format("-shard{}of{}", options.shard_index, options.shard_count);
  }

  {
    std::vector<std::filesystem::path> ins(cmd.inputs.begin(), cmd.inputs.end());
    check_output_dir(out, ins);
  }
  const SearchSummary s = [&] {
    const InterruptScope interrupt;  // SIGINT / SIGTERM: finish the running candidates, stop
    return run_search(options, out, interrupt.flag());
  }();

  fmt::print("lensopt search: {} of {} candidates{} -> {}/ (fingerprint {})\n", s.candidates_in_run,
             s.candidates_total,
             options.shard_count > 1
                 ? fmt::format(" (shard {}/{})", options.shard_index, options.shard_count)
                 : "",
             out, s.fingerprint);
  fmt::print(
      "  {} finished before this run, {} now ({:.1f} s, {:.2f} candidates/min); {} meet every "
      "constraint, {} failed\n",
      s.resumed, s.ran, s.seconds, s.candidates_per_minute, s.feasible, s.failed);
  print_leaderboard(s, 10);
  if (s.interrupted) {
    fmt::print(stderr,
               "lensopt search: stopped with {} of {} candidates finished; run the same command "
               "again to resume\n",
               s.leaderboard.size(), s.candidates_in_run);
    throw ExitCode{130};
  }
  // Failed candidates are reported and skipped; a search in which every one failed has no
  // result, and does not exit 0.
  if (!s.leaderboard.empty() && s.failed == static_cast<int>(s.leaderboard.size())) {
    fmt::print(stderr,
               "lensopt: error: {}: every candidate failed ({} of {}); the reasons are in the "
               "leaderboard above and in {}/leaderboard.csv\n",
               cmd.inputs.empty() ? out : cmd.inputs.front(), s.failed, s.leaderboard.size(), out);
    throw ExitCode{1};
  }
}

void run_merge_command(const MergeCommand& cmd) {
  if (cmd.output.empty()) throw Error("merge: give -o OUT (the merged folder)");
  std::vector<std::filesystem::path> dirs(cmd.dirs.begin(), cmd.dirs.end());
  check_output_dir(cmd.output, dirs);
  const SearchSummary s = merge_searches(dirs, cmd.output, cmd.top);
  fmt::print(
      "lensopt search merge: {} folders, {} of {} candidates -> {}/ (fingerprint {}); {} meet "
      "every constraint, {} failed\n",
      dirs.size(), s.resumed, s.candidates_total, cmd.output, s.fingerprint, s.feasible, s.failed);
  print_leaderboard(s, 10);
  if (s.interrupted)
    fmt::print(stderr, "lensopt search merge: warning: {} candidates have no result yet\n",
               s.candidates_total - s.resumed);
}

}  // namespace

void setup_search(CLI::App& app) {
  auto cmd = std::make_shared<SearchCommand>();
  auto merge = std::make_shared<MergeCommand>();
  CLI::App* sub = app.add_subcommand("search",
                                     "Batch baseline search: many starts, each optimized "
                                     "(Levenberg-Marquardt), ranked by mean spot");
  sub->add_option(
      "INPUT", cmd->inputs,
      "a search description (.toml with [search]) and/or starting lenses (globs allowed)");
  sub->add_option("-o,--output", cmd->output,
                  "results folder (default search-<first input>); rerun to resume");
  sub->add_flag("--vary-stop", cmd->vary_stop,
                "also try the stop in front, in every air gap, behind");
  sub->add_flag("--vary-cement", cmd->vary_cement,
                "also try every neighbouring pair cemented and air-spaced");
  sub->add_option("--stops", cmd->stops,
                  "stop positions --vary-stop tries: front,between,rear (default all)")
      ->delimiter(',');
  sub->add_option("--glass-seeds", cmd->glass_seeds,
                  "glass seeds per start and layout (seed 0: the start's)")
      ->check(CLI::Range(1, 1000));
  sub->add_option("--generate", cmd->generate, "generated starts with these element counts (1..4)")
      ->delimiter(',');
  sub->add_option("--top", cmd->top, "best lenses written to best/ (default 5)")
      ->check(CLI::Range(0, 1000000));
  sub->add_option("-j,--jobs", cmd->jobs, "candidates in parallel (default: every core)")
      ->check(CLI::Range(0, 1024));
  sub->add_option("--threads", cmd->threads, "threads per optimization (default 1; 0: every core)")
      ->check(CLI::Range(0, 1024));
  sub->add_option("--shard", cmd->shard,
                  "run slice I of N (1-based): candidates with index mod N = I-1");
  sub->add_option("--glass-search", cmd->glass_search, "none (default) | snap | neighbours")
      ->check(CLI::IsMember({"none", "snap", "neighbours", "neighbors"}));
  sub->add_option("--constraints", cmd->constraints,
                  "strict (default) | paper | paper+strict (paper penalties, then strict bounds)")
      ->check(CLI::IsMember({"strict", "paper", "paper+strict"}));
  sub->add_option("--rings", cmd->rings, "pupil rings during optimization (default 8)")
      ->check(CLI::Range(1, 256));
  sub->add_option("--fields", cmd->fields, "fields during optimization (default 11)")
      ->check(CLI::Range(1, 1000));
  sub->add_option("--max-iterations", cmd->max_iterations, "LM iterations per round (default 50)")
      ->check(CLI::Range(1, 1000000));
  sub->add_option("--max-rounds", cmd->max_rounds, "reweighting rounds per phase (default 4)")
      ->check(CLI::Range(1, 1000));
  sub->add_flag(
      "--no-soft-start", cmd->no_soft_start,
      "strict constraints: skip the optimizer's first phase on the paper's soft penalties");
  sub->add_option("--neighbours", cmd->neighbours, "catalog glasses tried per element (neighbours)")
      ->check(CLI::Range(0, 64));
  sub->add_option("--f-number", cmd->f_number,
                  "f-number of every candidate (default: a lens file's own; generated starts 2)")
      ->check(kFinite);
  sub->add_option("--half-field-deg", cmd->half_field_deg,
                  "half field of view (default: a lens file's own; generated starts 25)")
      ->check(kFinite);
  sub->add_option("--focal-length-mm", cmd->focal_length_mm,
                  "focal length (default 17.156: 16 mm diagonal)")
      ->check(kFinite);
  sub->add_flag("--list", cmd->list, "print the candidate list (index, shard, id) and exit");
  sub->add_flag("-q,--quiet", cmd->quiet, "no line per finished candidate on stderr");

  CLI::App* m = sub->add_subcommand(
      "merge", "Merge result folders (shards) of one search into one leaderboard");
  m->add_option("DIR", merge->dirs, "result folders of one search")->required();
  m->add_option("-o,--output", merge->output, "merged folder (results/, leaderboards, best/)")
      ->required();
  m->add_option("--top", merge->top, "best lenses written to best/ (default 5)");
  m->callback([merge] { run_merge_command(*merge); });

  sub->callback([cmd, m] {
    if (m->parsed()) return;
    if (cmd->inputs.empty() && cmd->generate.empty())
      throw Error("search: give a search description, starting lenses or --generate N");
    run_search_command(*cmd);
  });
}

}  // namespace lensopt::cli
