#include "lensopt/render/dataset.h"

#include <fcntl.h>
#include <fmt/format.h>
#include <fmt/ranges.h>
#include <malloc.h>
#include <omp.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <regex>
#include <set>

#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/core/output_checks.h"
#include "lensopt/render/image.h"

namespace lensopt {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

constexpr const char* kMetricsStem = "render_metrics";
// The metrics files of a whole run or of a shard, and (hidden, "." + stem + ".journal") the
// completion records: one JSON line appended (and flushed to the kernel) after each image's
// rename, so a run killed by SIGKILL loses no metric; removed once the CSV/JSON are written.
const std::regex kMetricsJson(R"(^render_metrics(-shard[0-9]+of[0-9]+)?\.json$)");
const std::regex kMetricsJournal(R"(^\.render_metrics(-shard[0-9]+of[0-9]+)?\.journal$)");
const std::regex kShardJson(R"(^render_metrics-shard([0-9]+)of([0-9]+)\.json$)");

fs::path journal_path_for(const fs::path& dir, const std::string& stem) {
  return dir / ("." + stem + ".journal");
}

// FNV-1a, 64 bit: h = (h xor byte) * 1099511628211 for every byte, from 14695981039346656037.
uint64_t fnv1a64(const std::string& text, uint64_t h) {
  for (unsigned char c : text) h = (h ^ c) * 1099511628211ull;
  return h;
}

// The dataset's fingerprint: FNV-1a over its output paths (inputs that failed to list: their
// input path) in order, one line each.
std::string dataset_fingerprint(const std::vector<ImageRecord>& records) {
  uint64_t h = 14695981039346656037ull;
  for (const ImageRecord& r : records)
    h = fnv1a64((r.relative_path.empty() ? "!" + r.input.generic_string() : r.relative_path) + "\n",
                h);
  return fmt::format("{:016x}", h);
}

// Removes the temporaries of write_file_atomic_with under `dir` whose target
// (".<stem>.tmp<pid>-<n><ext>" -> "<stem><ext>" in the same folder) is one of `targets`
// (normal paths), whatever their writer's pid but this process's. Returns how many.
int remove_temp_files_of(const fs::path& dir, const std::set<fs::path>& targets) {
  static const std::regex kTarget(R"(^\.(.*)\.tmp[0-9]+-[0-9]+(\.[^.]*)?$)");
  int removed = 0;
  std::error_code ec;
  for (fs::recursive_directory_iterator it(dir, fs::directory_options::skip_permission_denied, ec),
       end;
       !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    long pid = 0;
    std::smatch m;
    if (!it->is_regular_file(ec) || !is_temp_file_name(name, &pid) || pid == ::getpid() ||
        !std::regex_match(name, m, kTarget))
      continue;
    const fs::path target =
        (it->path().parent_path() / (m[1].str() + m[2].str())).lexically_normal();
    if (targets.count(target) && fs::remove(it->path(), ec)) ++removed;
  }
  return removed;
}

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
      if (files.empty()) {
        // Reported and counted as a failure: a folder that gives nothing to render is a mistake
        // (a wrong path), not a finished run.
        ImageRecord r;
        r.input = input;
        r.error = "no image to render in this folder or below (PNG, JPEG, TIFF, EXR)";
        records.push_back(r);
        continue;
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

struct PreviousRecord {
  std::optional<double> psnr_db, ssim;
  int width = 0, height = 0;
  double seconds = 0;  // its rendering's time, in the run that rendered it
  nlohmann::json settings;
};

struct PreviousMetrics {
  std::map<std::string, PreviousRecord> by_path;
};

// One image of render_metrics.json or of a journal line; false if it records no finished image.
bool parse_record(const nlohmann::json& img, const nlohmann::json& settings, PreviousRecord& r,
                  std::string& path) {
  if (!img.is_object() || !img.contains("path") || !img["path"].is_string()) return false;
  const std::string status = img.value("status", std::string("rendered"));
  if (status != "rendered" && status != "skipped") return false;
  path = img["path"].get<std::string>();
  if (img.contains("psnr_db") && img["psnr_db"].is_number())
    r.psnr_db = img["psnr_db"].get<double>();
  if (img.contains("psnr_identical") && img["psnr_identical"].is_boolean() &&
      img["psnr_identical"].get<bool>())
    r.psnr_db = std::numeric_limits<double>::infinity();
  if (img.contains("ssim") && img["ssim"].is_number()) r.ssim = img["ssim"].get<double>();
  if (img.contains("width") && img["width"].is_number_integer()) r.width = img["width"].get<int>();
  if (img.contains("height") && img["height"].is_number_integer())
    r.height = img["height"].get<int>();
  if (img.contains("seconds") && img["seconds"].is_number())
    r.seconds = img["seconds"].get<double>();
  r.settings = img.contains("settings") ? img["settings"] : settings;
  return r.width > 0 && r.height > 0 && r.psnr_db && r.ssim;
}

// The records of earlier runs in `dir`: every metrics JSON (a whole run's and the shards'), then
// every journal of a run killed before it wrote its JSON (a torn last line is ignored).
PreviousMetrics load_previous(const fs::path& dir) {
  PreviousMetrics prev;
  std::vector<fs::path> jsons, journals;
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (std::regex_match(name, kMetricsJson)) jsons.push_back(it->path());
    if (std::regex_match(name, kMetricsJournal)) journals.push_back(it->path());
  }
  std::sort(jsons.begin(), jsons.end());
  std::sort(journals.begin(), journals.end());
  for (const fs::path& json_path : jsons) {
    try {
      const nlohmann::json j = nlohmann::json::parse(read_file(json_path));
      const nlohmann::json settings = j.value("settings", nlohmann::json::object());
      std::map<std::string, PreviousRecord> records;
      for (const auto& img : j.at("images")) {
        PreviousRecord r;
        std::string path;
        if (parse_record(img, settings, r, path)) records[path] = r;
      }
      for (auto& [path, r] : records) prev.by_path[path] = r;
    } catch (const std::exception&) {
      // unreadable: its images are rendered again
    }
  }
  for (const fs::path& journal_path : journals) {
    std::string text;
    try {
      text = read_file(journal_path);
    } catch (const Error&) {
    }
    std::size_t start = 0;
    while (start < text.size()) {
      const std::size_t end = text.find('\n', start);
      if (end == std::string::npos) break;  // torn last line
      try {
        const nlohmann::json img = nlohmann::json::parse(text.substr(start, end - start));
        PreviousRecord r;
        std::string path;
        if (parse_record(img, nlohmann::json(), r, path)) prev.by_path[path] = r;
      } catch (const std::exception&) {
      }
      start = end + 1;
    }
  }
  return prev;
}

// Whether an existing output can be trusted: a completion record says it was written with this
// size, and the file opens as an image of that size.
bool output_is_complete(const fs::path& output, const PreviousRecord& record) {
  std::error_code ec;
  if (!fs::is_regular_file(output, ec) || fs::file_size(output, ec) == 0 || ec) return false;
  int width = 0, height = 0;
  return read_image_size(output, width, height) && width == record.width && height == record.height;
}

// The PSFs the model holds (ImagingModel::psf_kind): {"kind": "geometric"}; with diffraction
// PSFs also their sampling, and for auto the choice per field (its angle) and channel.
nlohmann::json psf_settings_json(const ImagingModel& m) {
  nlohmann::json psf = {{"kind", m.psf_kind}};
  if (m.psf_pupil_samples <= 0) return psf;
  psf["pupil_samples"] = m.psf_pupil_samples;
  psf["padding"] = m.psf_padding;
  psf["fft_n"] = m.psf_fft_n;
  if (m.psf_kind != "auto") return psf;
  int used = 0;
  nlohmann::json chosen = nlohmann::json::array();
  static constexpr const char* kChannel[kColourChannels] = {"R", "G", "B"};
  for (std::size_t h = 0; h < m.psf_diffraction.size(); ++h) {
    nlohmann::json field = {{"field_deg", h < m.fields_deg.size() ? m.fields_deg[h] : 0.0}};
    for (int k = 0; k < kColourChannels; ++k) {
      field[kChannel[k]] = m.psf_diffraction[h][k] ? "diffraction" : "geometric";
      used += m.psf_diffraction[h][k];
    }
    chosen.push_back(std::move(field));
  }
  psf["diffraction_channels"] = used;
  psf["channels"] = static_cast<int>(m.psf_diffraction.size()) * kColourChannels;
  psf["chosen"] = std::move(chosen);
  return psf;
}

nlohmann::json settings_json(const Renderer& renderer) {
  const RenderOptions& o = renderer.options();
  return {{"lens", renderer.model().lens_name},
          {"res_factor", o.res_factor},
          {"distortion", o.distortion},
          {"relative_illumination", o.relative_illumination},
          {"psf", psf_settings_json(renderer.model())}};
}

void summarize(DatasetSummary& s) {
  s.rendered = s.skipped = s.failed = s.interrupted = 0;
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
      case ImageRecord::Status::kInterrupted:
        ++s.interrupted;
        break;
    }
    if (r.status == ImageRecord::Status::kFailed || r.status == ImageRecord::Status::kInterrupted)
      continue;
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

// Writes s.csv_path and s.json_path; `shard_count` > 1 adds the shard to the JSON.
void write_metrics(const nlohmann::json& settings, DatasetSummary s, int shard_index = 1,
                   int shard_count = 1) {
  summarize(s);
  std::string csv = "path,input,status,width,height,psnr_db,ssim,seconds,error\n";
  nlohmann::json images = nlohmann::json::array();
  nlohmann::json failed = nlohmann::json::array();
  for (const ImageRecord& r : s.records) {
    csv += fmt::format("{},{},{},{},{},{},{},{:.3f},{}\n", csv_field(r.relative_path),
                       csv_field(r.input.string()), status_name(r.status), r.width, r.height,
                       number_or_empty(r.psnr_db, 4), number_or_empty(r.ssim, 6), r.seconds,
                       csv_field(r.error));
    nlohmann::json j = {{"index", r.index},
                        {"path", r.relative_path},
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
  nlohmann::json j = {
      {"settings", settings},
      {"dataset", {{"images", s.dataset_images}, {"fingerprint", s.dataset_fingerprint}}},
      {"images", images},
      {"rendered", s.rendered},
      {"skipped", s.skipped},
      {"failed", s.failed},
      {"interrupted", s.interrupted},
      {"failed_inputs", failed},
      {"mean_psnr_db", number_or_null(s.mean_psnr_db)},
      {"mean_ssim", number_or_null(s.mean_ssim)},
      {"metrics",
       "PSNR (dB, peak 1) and SSIM (11x11 Gaussian window, sigma 1.5) "
       "between each input and its blurred image, before relative "
       "illumination and distortion"}};
  if (shard_count > 1) j["shard"] = {{"index", shard_index}, {"count", shard_count}};
  write_file_atomic(s.csv_path, csv);
  write_file_atomic(s.json_path,
                    j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) + "\n");
}

}  // namespace

std::string metrics_stem(int shard_index, int shard_count) {
  return shard_count > 1 ? fmt::format("{}-shard{}of{}", kMetricsStem, shard_index, shard_count)
                         : std::string(kMetricsStem);
}

const char* status_name(ImageRecord::Status status) {
  switch (status) {
    case ImageRecord::Status::kRendered:
      return "rendered";
    case ImageRecord::Status::kSkipped:
      return "skipped";
    case ImageRecord::Status::kFailed:
      return "failed";
    case ImageRecord::Status::kInterrupted:
      return "interrupted";
  }
  return "?";
}

void DatasetOptions::validate() const {
  if (inputs.empty()) throw Error("render: no input image or directory given");
  if (output_dir.empty()) throw Error("render: no output directory given (-o OUT)");
  if (jobs < 0 || jobs > 1024) throw Error(fmt::format("jobs = {} must be in [0, 1024]", jobs));
  if (shard_count < 1 || shard_index < 1 || shard_index > shard_count)
    throw Error(SourceLocation{"--shard"},
                fmt::format("shard {}/{}: need 1 <= I <= N", shard_index, shard_count));
}

void ensure_writable_directory(const fs::path& dir) {
  check_output_dir(dir);
}

RenderResult render_file(const Renderer& renderer, const fs::path& input, const fs::path& output,
                         int threads) {
  if (!image_format_name(input).empty() && image_format_name(input) != image_format_name(output)) {
    throw Error(SourceLocation{output.string()}, "the output must have the input's format");
  }
  if (same_file(input, output))
    throw Error(SourceLocation{output.string()},
                "refusing to write the rendered image over its input");
  LoadedImage loaded = read_image(input);
  RenderResult result;
  try {
    // The input's memory becomes the output's (render/render.h).
    result = renderer.render(std::move(loaded.image), threads);
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

namespace {

// The append-only completion records (kJournalName). Appends are serialized by the caller.
class Journal {
 public:
  explicit Journal(fs::path path) : path_(std::move(path)) {}
  ~Journal() { close(); }
  Journal(const Journal&) = delete;
  Journal& operator=(const Journal&) = delete;

  // Appends one line; on failure remembers the first error (the final metrics write reports
  // the run's outcome) and returns false.
  bool append(const nlohmann::json& record) {
    if (fd_ < 0 && !failed_) {
      fd_ = ::open(path_.c_str(), O_RDWR | O_CREAT | O_APPEND | O_CLOEXEC, 0666);
      if (fd_ < 0) fail(std::strerror(errno));
    }
    if (fd_ < 0) return false;
    std::string line = record.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace) + "\n";
    // A line torn by a kill of an earlier run is ended first, so it cannot swallow this one.
    if (!checked_end_) {
      checked_end_ = true;
      const off_t size = ::lseek(fd_, 0, SEEK_END);
      char last = '\n';
      if (size > 0 && ::pread(fd_, &last, 1, size - 1) == 1 && last != '\n') line = "\n" + line;
    }
    std::size_t done = 0;
    while (done < line.size()) {
      const ssize_t n = ::write(fd_, line.data() + done, line.size() - done);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) {
        fail(n < 0 ? std::strerror(errno) : "short write");
        return false;
      }
      done += static_cast<std::size_t>(n);
    }
    return true;
  }
  void close() {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
  }
  // Removes the journal (after the metrics files hold everything it says).
  void remove() {
    close();
    std::error_code ec;
    fs::remove(path_, ec);
  }
  const std::string& error() const { return error_; }

 private:
  void fail(const std::string& why) {
    if (error_.empty()) error_ = fmt::format("{}: cannot write: {}", path_.string(), why);
    failed_ = true;
    close();
  }
  fs::path path_;
  int fd_ = -1;
  bool failed_ = false;
  bool checked_end_ = false;
  std::string error_;
};

}  // namespace

DatasetSummary render_dataset(const Renderer& renderer, const DatasetOptions& options,
                              const DatasetProgress& progress) {
  options.validate();
  const auto start = Clock::now();
  // Checks before any work: the output folder is writable and none of the inputs.
  check_output_dir(options.output_dir, options.inputs);
  DatasetSummary summary;
  const std::string stem = metrics_stem(options.shard_index, options.shard_count);
  summary.csv_path = options.output_dir / (stem + ".csv");
  summary.json_path = options.output_dir / (stem + ".json");
  const fs::path journal_path = journal_path_for(options.output_dir, stem);
  for (const fs::path& metrics : {summary.csv_path, summary.json_path})
    check_output_file(metrics, options.inputs);
  summary.records = collect_inputs(options);
  for (int i = 0; i < static_cast<int>(summary.records.size()); ++i) summary.records[i].index = i;
  summary.dataset_images = static_cast<int>(summary.records.size());
  summary.dataset_fingerprint = dataset_fingerprint(summary.records);

  // Two inputs must not write the same output, and no output may replace an input.
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
    if (r.relative_path == summary.csv_path.filename().string() ||
        r.relative_path == summary.json_path.filename().string())
      throw Error(fmt::format("input {} would overwrite the metrics file", r.input.string()));
    if (same_file(options.output_dir / r.relative_path, r.input))
      throw Error(SourceLocation{(options.output_dir / r.relative_path).string()},
                  fmt::format("refusing to write the rendered image over its input {}; choose "
                              "another output folder",
                              r.input.string()));
  }

  // A shard keeps its slice: positions k with k mod N = I - 1.
  if (options.shard_count > 1) {
    std::vector<ImageRecord> slice;
    for (ImageRecord& r : summary.records)
      if (r.index % options.shard_count == options.shard_index - 1) slice.push_back(std::move(r));
    summary.records = std::move(slice);
  }

  // Temporaries of a killed earlier run (a shard: only those of its own outputs).
  if (options.shard_count > 1) {
    std::set<fs::path> targets = {summary.csv_path.lexically_normal(),
                                  summary.json_path.lexically_normal()};
    for (const ImageRecord& r : summary.records)
      if (!r.relative_path.empty())
        targets.insert((options.output_dir / r.relative_path).lexically_normal());
    summary.stale_temp_files_removed = remove_temp_files_of(options.output_dir, targets);
  } else {
    summary.stale_temp_files_removed = remove_stale_temp_files(options.output_dir);
  }

  const PreviousMetrics previous = load_previous(options.output_dir);
  const nlohmann::json settings = settings_json(renderer);
  bool kept_other_settings = false;
  nlohmann::json other_settings;
  // Decide what to do with each record: an existing output is trusted only with a completion
  // record of the same size; anything else is rendered (again).
  std::vector<int> todo;
  for (int i = 0; i < static_cast<int>(summary.records.size()); ++i) {
    ImageRecord& r = summary.records[i];
    if (r.relative_path.empty()) continue;  // failed while listing
    if (!options.force) {
      auto it = previous.by_path.find(r.relative_path);
      if (it != previous.by_path.end() &&
          output_is_complete(options.output_dir / r.relative_path, it->second)) {
        r.status = ImageRecord::Status::kSkipped;
        r.psnr_db = it->second.psnr_db;
        r.ssim = it->second.ssim;
        r.width = it->second.width;
        r.height = it->second.height;
        r.seconds = it->second.seconds;
        if (it->second.settings != settings) {
          kept_other_settings = true;
          other_settings = it->second.settings;
        }
        continue;
      }
    }
    todo.push_back(i);
  }

  if (kept_other_settings) {
    summary.notes.push_back(fmt::format(
        "some existing outputs were rendered with other settings ({}); they are kept (use "
        "--force to render them again)",
        other_settings.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace)));
  }
  if (summary.stale_temp_files_removed > 0)
    summary.notes.push_back(fmt::format("removed {} temporary file(s) of an interrupted run",
                                        summary.stale_temp_files_removed));
  const int total = static_cast<int>(summary.records.size());
  int done = 0;
  std::mutex mutex;
  auto last_write = Clock::now();
  Journal journal(journal_path);
  auto report = [&](const ImageRecord& r) {  // caller holds the mutex
    ++done;
    if (progress) progress(r, done, total);
  };
  for (const ImageRecord& r : summary.records)
    if (r.status == ImageRecord::Status::kSkipped || r.relative_path.empty()) report(r);

  // Images of one size, one after the other: the freed buffers of an image (tens of MB) stay in
  // the heap for the next one instead of going back to the kernel (glibc returns chunks above
  // the mmap threshold at once, and a trimmed heap's pages fault in again, 4 KiB at a time: 5 to
  // 10 % of an image's CPU time). 32 MiB is the largest mmap threshold glibc accepts.
  if (todo.size() > 1) {
    mallopt(M_MMAP_THRESHOLD, 32 << 20);
    mallopt(M_TRIM_THRESHOLD, 512 << 20);
  }
  auto interrupted = [&] { return options.interrupt && options.interrupt->load(); };
  const int threads = options.jobs > 0 ? options.jobs : omp_get_max_threads();
  // Threads inside one image depend on the dataset alone, never on how many images are left: the
  // blur sums its patches in per-thread accumulators (patches dealt out dynamically) and the
  // metrics reduce per thread, so the bits of an image and its PSNR/SSIM depend on that count.
  // With one thread per image a resumed run or a shard renders each image exactly as one
  // uninterrupted run does (images run in parallel instead); a single image gets every thread.
  const int inner = summary.dataset_images > 1 ? 1 : threads;
  const int outer = std::max(1, std::min<int>(threads, static_cast<int>(todo.size())));
  auto work = [&](int k) {
    // The record is filled in a copy and stored under the mutex (the metrics writer reads all).
    ImageRecord r = summary.records[todo[k]];
    if (interrupted()) {
      r.status = ImageRecord::Status::kInterrupted;
      std::lock_guard<std::mutex> lock(mutex);
      summary.records[todo[k]] = r;
      return;
    }
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
      // A write error names the output; a read or render error the input (listed beside it).
      r.error =
          e.where().file.empty() || e.where().file == r.input.string() ? e.message() : e.what();
    } catch (const std::exception& e) {
      r.status = ImageRecord::Status::kFailed;
      r.error = e.what();
    }
    r.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
    std::lock_guard<std::mutex> lock(mutex);
    summary.records[todo[k]] = r;
    if (r.status == ImageRecord::Status::kRendered) {
      nlohmann::json line = {{"path", r.relative_path},
                             {"status", "rendered"},
                             {"width", r.width},
                             {"height", r.height},
                             {"psnr_db", number_or_null(r.psnr_db)},
                             {"ssim", number_or_null(r.ssim)},
                             {"seconds", r.seconds},
                             {"settings", settings}};
      if (r.psnr_db && std::isinf(*r.psnr_db)) line["psnr_identical"] = true;
      journal.append(line);
    }
    report(r);
    if (Clock::now() - last_write > std::chrono::seconds(10)) {
      try {
        write_metrics(settings, summary, options.shard_index, options.shard_count);
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
  summary.was_interrupted = summary.interrupted > 0 || interrupted();
  // Throws Error naming the file if it cannot.
  write_metrics(settings, summary, options.shard_index, options.shard_count);
  // The metrics files now hold every completion record.
  journal.remove();
  if (!journal.error().empty())
    summary.notes.push_back("the completion records could not be written (" + journal.error() +
                            "); the metrics files are complete");
  summary.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return summary;
}

namespace {

// One shard's metrics file, read for the merge.
struct ShardMetrics {
  fs::path dir, json_path;
  int index = 0, count = 0;
  nlohmann::json json;
};

ImageRecord::Status status_from_name(const std::string& name) {
  if (name == "rendered" || name == "skipped") return ImageRecord::Status::kRendered;
  if (name == "failed") return ImageRecord::Status::kFailed;
  return ImageRecord::Status::kInterrupted;
}

std::optional<double> optional_number(const nlohmann::json& img, const char* key) {
  if (img.contains(key) && img[key].is_number()) return img[key].get<double>();
  return std::nullopt;
}

}  // namespace

DatasetSummary merge_render_metrics(const std::vector<fs::path>& dirs, const fs::path& output_dir) {
  if (dirs.empty()) throw Error("render merge: no folder given");
  // The shards' metrics files, each shard once.
  std::vector<ShardMetrics> shards;
  for (const fs::path& dir : dirs) {
    std::error_code ec;
    if (!fs::is_directory(dir, ec))
      throw Error(SourceLocation{dir.string()}, "render merge: not a folder");
    std::vector<fs::path> found;
    for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec))
      if (std::regex_match(it->path().filename().string(), kShardJson)) found.push_back(it->path());
    std::sort(found.begin(), found.end());
    for (const fs::path& p : found) {
      ShardMetrics m;
      m.dir = dir;
      m.json_path = p;
      try {
        m.json = nlohmann::json::parse(read_file(p));
        m.index = m.json.at("shard").at("index").get<int>();
        m.count = m.json.at("shard").at("count").get<int>();
        m.json.at("dataset").at("images").get<int>();
        m.json.at("dataset").at("fingerprint").get<std::string>();
        if (!m.json.at("images").is_array()) throw std::runtime_error("images is not a list");
      } catch (const Error&) {
        throw;
      } catch (const std::exception& e) {
        throw Error(SourceLocation{p.string()},
                    fmt::format("not a render shard's metrics file: {}", e.what()));
      }
      shards.push_back(std::move(m));
    }
  }
  if (shards.empty())
    throw Error(
        "render merge: no shard metrics (render_metrics-shardIofN.json) in the folders "
        "given; render with --shard I/N first");
  const ShardMetrics& first = shards.front();
  const int count = first.count;
  const int images = first.json["dataset"]["images"].get<int>();
  const std::string fingerprint = first.json["dataset"]["fingerprint"].get<std::string>();
  std::map<int, const ShardMetrics*> by_index;
  for (const ShardMetrics& m : shards) {
    const SourceLocation where{m.json_path.string()};
    if (m.count != count || m.json["dataset"]["images"] != images ||
        m.json["dataset"]["fingerprint"] != fingerprint)
      throw Error(where, fmt::format("shard {}/{} of a dataset of {} images (fingerprint {}) is "
                                     "not of the dataset of {} ({}, {} images, {} shards)",
                                     m.index, m.count, m.json["dataset"]["images"].dump(),
                                     m.json["dataset"]["fingerprint"].get<std::string>(),
                                     first.json_path.string(), fingerprint, images, count));
    if (m.json.value("settings", nlohmann::json()) !=
        first.json.value("settings", nlohmann::json()))
      throw Error(where, fmt::format("rendered with other settings than {} ({} vs {})",
                                     first.json_path.string(), m.json["settings"].dump(),
                                     first.json.value("settings", nlohmann::json()).dump()));
    auto [it, fresh] = by_index.emplace(m.index, &m);
    if (!fresh)
      throw Error(where, fmt::format("shard {}/{} is given twice (also {})", m.index, m.count,
                                     it->second->json_path.string()));
    const std::string stem = metrics_stem(m.index, m.count);
    std::error_code ec;
    if (fs::exists(journal_path_for(m.dir, stem), ec))
      throw Error(where, fmt::format("shard {}/{} was stopped before its end (its journal {} is "
                                     "there): run it again to finish it",
                                     m.index, m.count, journal_path_for(m.dir, stem).string()));
  }
  std::vector<int> missing;
  for (int i = 1; i <= count; ++i) {
    if (by_index.count(i)) continue;
    missing.push_back(i);
    for (const fs::path& dir : dirs) {  // killed before it wrote its metrics
      const fs::path journal = journal_path_for(dir, metrics_stem(i, count));
      std::error_code ec;
      if (fs::exists(journal, ec))
        throw Error(SourceLocation{journal.string()},
                    fmt::format("shard {}/{} was stopped before its end (this journal is there): "
                                "run it again to finish it",
                                i, count));
    }
  }
  if (!missing.empty())
    throw Error(fmt::format("render merge: shard(s) {} of {} not found in the folders given",
                            fmt::join(missing, ", "), count));

  // The records in dataset order; every image must be done (rendered or failed).
  DatasetSummary summary;
  summary.dataset_images = images;
  summary.dataset_fingerprint = fingerprint;
  summary.records.resize(images);
  std::vector<const ShardMetrics*> source(images, nullptr);
  for (const ShardMetrics& m : shards) {
    const SourceLocation where{m.json_path.string()};
    for (const nlohmann::json& img : m.json["images"]) {
      const int index = img.value("index", -1);
      if (index < 0 || index >= images || index % count != m.index - 1 || source[index])
        throw Error(where, fmt::format("image {} has a position ({}) outside its shard",
                                       img.value("path", std::string("?")), index));
      ImageRecord& r = summary.records[index];
      source[index] = &m;
      r.index = index;
      r.relative_path = img.value("path", std::string());
      r.input = img.value("input", std::string());
      r.status = status_from_name(img.value("status", std::string()));
      if (r.status == ImageRecord::Status::kInterrupted)
        throw Error(where, fmt::format("{} was not rendered ({}): run shard {}/{} again to finish "
                                       "it",
                                       r.relative_path, img.value("status", std::string()), m.index,
                                       m.count));
      r.width = img.value("width", 0);
      r.height = img.value("height", 0);
      r.psnr_db = img.value("psnr_identical", false)
                      ? std::optional<double>(std::numeric_limits<double>::infinity())
                      : optional_number(img, "psnr_db");
      r.ssim = optional_number(img, "ssim");
      r.seconds = img.value("seconds", 0.0);
      r.error = img.value("error", std::string());
    }
  }
  for (int i = 0; i < images; ++i)
    if (!source[i])
      throw Error(
          fmt::format("render merge: image {} of {} is in no shard's metrics (shard {}/{}: "
                      "run it again)",
                      i, images, i % count + 1, count));

  // Images of a shard in another folder are copied; then the metrics, as one run writes them.
  check_output_dir(output_dir);
  summary.csv_path = output_dir / (std::string(kMetricsStem) + ".csv");
  summary.json_path = output_dir / (std::string(kMetricsStem) + ".json");
  for (int i = 0; i < images; ++i) {
    const ImageRecord& r = summary.records[i];
    if (r.status != ImageRecord::Status::kRendered || r.relative_path.empty() ||
        same_file(source[i]->dir, output_dir))
      continue;
    const fs::path from = source[i]->dir / r.relative_path;
    const fs::path to = output_dir / r.relative_path;
    std::error_code ec;
    fs::create_directories(to.parent_path(), ec);
    if (ec)
      throw Error(SourceLocation{to.string()},
                  fmt::format("cannot create directory: {}", ec.message()));
    write_file_atomic_with(to, [&](const fs::path& temp) {
      fs::copy_file(from, temp, fs::copy_options::overwrite_existing, ec);
      if (ec)
        throw Error(SourceLocation{from.string()}, fmt::format("cannot copy: {}", ec.message()));
    });
    ++summary.skipped;  // counted as copied
  }
  const int copied = summary.skipped;
  summarize(summary);
  write_metrics(first.json.value("settings", nlohmann::json::object()), summary);
  if (copied > 0)
    summary.notes.push_back(fmt::format("copied {} image(s) into {}", copied, output_dir.string()));
  return summary;
}

}  // namespace lensopt
