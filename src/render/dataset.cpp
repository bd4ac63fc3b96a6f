#include "lensopt/render/dataset.h"

#include <fmt/format.h>
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <set>

#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"

namespace lensopt {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

constexpr const char* kCsvName = "render_metrics.csv";
constexpr const char* kJsonName = "render_metrics.json";

bool is_hidden(const fs::path& p) {
  const std::string name = p.filename().string();
  return !name.empty() && name[0] == '.';
}

// Whether `p` lies inside directory `dir` (both made absolute and normal).
bool is_inside(const fs::path& p, const fs::path& dir) {
  std::error_code ec;
  const fs::path a = fs::weakly_canonical(p, ec);
  const fs::path b = fs::weakly_canonical(dir, ec);
  auto ai = a.begin();
  for (auto bi = b.begin(); bi != b.end(); ++bi, ++ai) {
    if (bi->empty()) continue;  // trailing separator
    if (ai == a.end() || *ai != *bi) return false;
  }
  return true;
}

std::string csv_field(const std::string& s) {
  if (s.find_first_of(",\"\n") == std::string::npos) return s;
  std::string out = "\"";
  for (char c : s) {
    if (c == '"') out += '"';
    out += c;
  }
  return out + "\"";
}

std::string number_or_empty(const std::optional<double>& v, int digits) {
  if (!v) return "";
  if (std::isinf(*v)) return "inf";
  return fmt::format("{:.{}f}", *v, digits);
}

nlohmann::json number_or_null(const std::optional<double>& v) {
  return (v && std::isfinite(*v)) ? nlohmann::json(*v) : nlohmann::json(nullptr);
}

// Collects the images to render: (input, relative output path), or failures.
std::vector<ImageRecord> collect_inputs(const DatasetOptions& options) {
  std::vector<ImageRecord> records;
  for (const fs::path& input : options.inputs) {
    std::error_code ec;
    if (fs::is_directory(input, ec)) {
      std::vector<fs::path> files;
      fs::recursive_directory_iterator it(input, fs::directory_options::skip_permission_denied, ec);
      if (ec) {
        ImageRecord r;
        r.input = input;
        r.error = fmt::format("cannot list directory: {}", ec.message());
        records.push_back(r);
        continue;
      }
      for (; it != fs::recursive_directory_iterator(); it.increment(ec)) {
        if (ec) break;
        const fs::path& p = it->path();
        if (is_hidden(p)) {
          if (it->is_directory(ec)) it.disable_recursion_pending();
          continue;
        }
        if (it->is_directory(ec)) {
          if (is_inside(p, options.output_dir)) it.disable_recursion_pending();
          continue;
        }
        if (!it->is_regular_file(ec) || !is_supported_image(p)) continue;
        if (is_inside(p, options.output_dir)) continue;
        files.push_back(p);
      }
      std::sort(files.begin(), files.end());
      for (const fs::path& f : files) {
        ImageRecord r;
        r.input = f;
        r.relative_path = f.lexically_relative(input).generic_string();
        records.push_back(r);
      }
    } else {
      ImageRecord r;
      r.input = input;
      r.relative_path = input.filename().generic_string();
      records.push_back(r);
    }
  }
  return records;
}

struct PreviousMetrics {
  std::map<std::string, std::pair<std::optional<double>, std::optional<double>>> by_path;
  nlohmann::json settings;
};

PreviousMetrics load_previous(const fs::path& json_path) {
  PreviousMetrics prev;
  std::error_code ec;
  if (!fs::exists(json_path, ec)) return prev;
  try {
    const nlohmann::json j = nlohmann::json::parse(read_file(json_path));
    prev.settings = j.value("settings", nlohmann::json::object());
    for (const auto& img : j.at("images")) {
      std::optional<double> psnr, ssim;
      if (img.contains("psnr_db") && img["psnr_db"].is_number())
        psnr = img["psnr_db"].get<double>();
      if (img.contains("psnr_identical") && img["psnr_identical"].get<bool>())
        psnr = std::numeric_limits<double>::infinity();
      if (img.contains("ssim") && img["ssim"].is_number()) ssim = img["ssim"].get<double>();
      prev.by_path[img.at("path").get<std::string>()] = {psnr, ssim};
    }
  } catch (const std::exception&) {
    prev.by_path.clear();  // unreadable: metrics of skipped images stay empty
  }
  return prev;
}

nlohmann::json settings_json(const Renderer& renderer) {
  const RenderOptions& o = renderer.options();
  return {{"lens", renderer.model().lens_name},
          {"res_factor", o.res_factor},
          {"distortion", o.distortion},
          {"relative_illumination", o.relative_illumination}};
}

void summarize(DatasetSummary& s) {
  s.rendered = s.skipped = s.failed = 0;
  double psnr_sum = 0, ssim_sum = 0;
  int psnr_count = 0, ssim_count = 0;
  for (const ImageRecord& r : s.records) {
    switch (r.status) {
      case ImageRecord::Status::kRendered:
        ++s.rendered;
        break;
      case ImageRecord::Status::kSkipped:
        ++s.skipped;
        break;
      case ImageRecord::Status::kFailed:
        ++s.failed;
        break;
    }
    if (r.status == ImageRecord::Status::kFailed) continue;
    if (r.psnr_db && std::isfinite(*r.psnr_db)) {
      psnr_sum += *r.psnr_db;
      ++psnr_count;
    }
    if (r.ssim) {
      ssim_sum += *r.ssim;
      ++ssim_count;
    }
  }
  s.mean_psnr_db = psnr_count ? std::optional<double>(psnr_sum / psnr_count) : std::nullopt;
  s.mean_ssim = ssim_count ? std::optional<double>(ssim_sum / ssim_count) : std::nullopt;
}

void write_metrics(const Renderer& renderer, DatasetSummary s) {
  summarize(s);
  std::string csv = "path,input,status,width,height,psnr_db,ssim,seconds,error\n";
  nlohmann::json images = nlohmann::json::array();
  nlohmann::json failed = nlohmann::json::array();
  for (const ImageRecord& r : s.records) {
    csv += fmt::format("{},{},{},{},{},{},{},{:.3f},{}\n", csv_field(r.relative_path),
                       csv_field(r.input.string()), status_name(r.status), r.width, r.height,
                       number_or_empty(r.psnr_db, 4), number_or_empty(r.ssim, 6), r.seconds,
                       csv_field(r.error));
    nlohmann::json j = {{"path", r.relative_path},
                        {"input", r.input.string()},
                        {"status", status_name(r.status)},
                        {"width", r.width},
                        {"height", r.height},
                        {"psnr_db", number_or_null(r.psnr_db)},
                        {"ssim", number_or_null(r.ssim)},
                        {"seconds", r.seconds}};
    if (r.psnr_db && std::isinf(*r.psnr_db)) j["psnr_identical"] = true;
    if (!r.error.empty()) {
      j["error"] = r.error;
      failed.push_back(fmt::format("{}: {}", r.input.string(), r.error));
    }
    images.push_back(j);
  }
  csv += fmt::format("mean,,,,,{},{},,\n", number_or_empty(s.mean_psnr_db, 4),
                     number_or_empty(s.mean_ssim, 6));
  nlohmann::json j = {{"settings", settings_json(renderer)},
                      {"images", images},
                      {"rendered", s.rendered},
                      {"skipped", s.skipped},
                      {"failed", s.failed},
                      {"failed_inputs", failed},
                      {"mean_psnr_db", number_or_null(s.mean_psnr_db)},
                      {"mean_ssim", number_or_null(s.mean_ssim)},
                      {"metrics",
                       "PSNR (dB, peak 1) and SSIM (11x11 Gaussian window, sigma 1.5) "
                       "between each input and its blurred image, before relative "
                       "illumination and distortion"}};
  write_file_atomic(s.csv_path, csv);
  write_file_atomic(s.json_path, j.dump(2) + "\n");
}

}  // namespace

const char* status_name(ImageRecord::Status status) {
  switch (status) {
    case ImageRecord::Status::kRendered:
      return "rendered";
    case ImageRecord::Status::kSkipped:
      return "skipped";
    case ImageRecord::Status::kFailed:
      return "failed";
  }
  return "?";
}

void DatasetOptions::validate() const {
  if (inputs.empty()) throw Error("render: no input image or directory given");
  if (output_dir.empty()) throw Error("render: no output directory given (-o OUT)");
  if (jobs < 0 || jobs > 1024) throw Error(fmt::format("jobs = {} must be in [0, 1024]", jobs));
}

void ensure_writable_directory(const fs::path& dir) {
  const SourceLocation where{dir.string()};
  std::error_code ec;
  if (fs::exists(dir, ec) && !fs::is_directory(dir, ec))
    throw Error(where, "cannot write output: it exists and is not a directory");
  fs::create_directories(dir, ec);
  if (ec) throw Error(where, fmt::format("cannot create the output directory: {}", ec.message()));
  const fs::path probe = dir / ".lensopt-write-test";
  try {
    write_file_atomic(probe, "");
  } catch (const Error& e) {
    throw Error(where, fmt::format("cannot write in the output directory: {}", e.message()));
  }
  fs::remove(probe, ec);
}

RenderResult render_file(const Renderer& renderer, const fs::path& input, const fs::path& output,
                         int threads) {
  if (!image_format_name(input).empty() && image_format_name(input) != image_format_name(output)) {
    throw Error(SourceLocation{output.string()}, "the output must have the input's format");
  }
  const LoadedImage loaded = read_image(input);
  RenderResult result;
  try {
    result = renderer.render(loaded.image, threads);
  } catch (const Error& e) {
    throw Error(SourceLocation{input.string()}, e.message());
  }
  std::error_code ec;
  if (output.has_parent_path()) {
    fs::create_directories(output.parent_path(), ec);
    if (ec) {
      throw Error(SourceLocation{output.string()},
                  fmt::format("cannot create directory: {}", ec.message()));
    }
  }
  write_image(output, result.image, loaded.spec);
  return result;
}

DatasetSummary render_dataset(const Renderer& renderer, const DatasetOptions& options,
                              const DatasetProgress& progress) {
  options.validate();
  const auto start = Clock::now();
  ensure_writable_directory(options.output_dir);
  DatasetSummary summary;
  summary.csv_path = options.output_dir / kCsvName;
  summary.json_path = options.output_dir / kJsonName;
  summary.records = collect_inputs(options);

  // Two inputs must not write the same output.
  std::map<std::string, fs::path> seen;
  for (const ImageRecord& r : summary.records) {
    if (r.relative_path.empty()) continue;
    auto [it, fresh] = seen.emplace(r.relative_path, r.input);
    if (!fresh) {
      throw Error(fmt::format(
          "inputs {} and {} would both be written to {}: render them in "
          "separate runs or from their common folder",
          it->second.string(), r.input.string(), (options.output_dir / r.relative_path).string()));
    }
    if (r.relative_path == kCsvName || r.relative_path == kJsonName)
      throw Error(fmt::format("input {} would overwrite the metrics file", r.input.string()));
  }

  const PreviousMetrics previous = load_previous(summary.json_path);
  bool kept_other_settings = false;
  // Decide what to do with each record.
  std::vector<int> todo;
  for (int i = 0; i < static_cast<int>(summary.records.size()); ++i) {
    ImageRecord& r = summary.records[i];
    if (r.relative_path.empty()) continue;  // failed while listing
    std::error_code ec;
    if (!options.force && fs::exists(options.output_dir / r.relative_path, ec)) {
      r.status = ImageRecord::Status::kSkipped;
      auto it = previous.by_path.find(r.relative_path);
      if (it != previous.by_path.end()) {
        std::tie(r.psnr_db, r.ssim) = it->second;
        kept_other_settings |= previous.settings != settings_json(renderer);
      }
      continue;
    }
    todo.push_back(i);
  }

  if (kept_other_settings) {
    summary.notes.push_back(fmt::format(
        "some existing outputs were rendered with other settings ({}); they are kept (use "
        "--force to render them again)",
        previous.settings.dump()));
  }
  const int total = static_cast<int>(summary.records.size());
  int done = 0;
  std::mutex mutex;
  auto last_write = Clock::now();
  auto report = [&](const ImageRecord& r) {  // caller holds the mutex
    ++done;
    if (progress) progress(r, done, total);
  };
  for (const ImageRecord& r : summary.records)
    if (r.status == ImageRecord::Status::kSkipped || r.relative_path.empty()) report(r);

  const int threads = options.jobs > 0 ? options.jobs : omp_get_max_threads();
  const int outer = std::max(1, std::min<int>(threads, static_cast<int>(todo.size())));
  const int inner = std::max(1, threads / outer);
  auto work = [&](int k) {
    // The record is filled in a copy and stored under the mutex (the metrics writer reads all).
    ImageRecord r = summary.records[todo[k]];
    const auto t0 = Clock::now();
    try {
      const RenderResult result =
          render_file(renderer, r.input, options.output_dir / r.relative_path, inner);
      r.status = ImageRecord::Status::kRendered;
      r.psnr_db = result.psnr_db;
      r.ssim = result.ssim;
      r.width = result.image.width;
      r.height = result.image.height;
    } catch (const Error& e) {
      r.status = ImageRecord::Status::kFailed;
      r.error = e.message();
    } catch (const std::exception& e) {
      r.status = ImageRecord::Status::kFailed;
      r.error = e.what();
    }
    r.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
    std::lock_guard<std::mutex> lock(mutex);
    summary.records[todo[k]] = r;
    report(r);
    if (Clock::now() - last_write > std::chrono::seconds(10)) {
      try {
        write_metrics(renderer, summary);
      } catch (const Error&) {
        // retried at the end, where a failure is reported
      }
      last_write = Clock::now();
    }
  };
  if (outer == 1) {
    for (int k = 0; k < static_cast<int>(todo.size()); ++k) work(k);
  } else {
#pragma omp parallel for num_threads(outer) schedule(dynamic, 1)
    for (int k = 0; k < static_cast<int>(todo.size()); ++k) work(k);
  }
  summarize(summary);
  write_metrics(renderer, summary);
  summary.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return summary;
}

}  // namespace lensopt
