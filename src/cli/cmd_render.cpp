// lensopt render LENS INPUT... -o OUT: aberrated images for single files or whole dataset trees;
// `--shard I/N` renders a slice, `lensopt render merge DIR...` joins the slices' metrics;
// `--annotations FILE` writes the detection dataset's boxes as the rendered images show them.
#include <fmt/core.h>
#include <malloc.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "commands.h"
#include "lens_checks.h"
#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/core/image_limits.h"
#include "lensopt/core/interrupt.h"
#include "lensopt/core/output_checks.h"
#include "lensopt/detection/crop_boxes.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/render/chart.h"
#include "lensopt/render/dataset.h"
#include "lensopt/render/diffraction_psf.h"
#include "lensopt/search/search.h"

namespace lensopt::cli {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

struct RenderCommand {
  std::string lens_path;
  std::vector<std::string> inputs;
  std::string output_dir;
  int res_factor = 1;
  bool no_distortion = false;
  bool no_ri = false;
  int jobs = 0;
  bool force = false;
  bool quiet = false;
  std::string shard;
  std::string annotations;  // a COCO or BDD100K JSON of the inputs
  std::string classes;      // a TOML file with a [classes] map for the annotations
  std::string psf = "geometric";
  int pupil_samples = kRenderPupilSamples;
  long long max_image_pixels = 0;  // 0: core/image_limits.h's default
};

struct RenderMergeCommand {
  std::vector<std::string> dirs;
  std::string output_dir;
};

std::string clock_text(double seconds) {
  const long s = static_cast<long>(seconds + 0.5);
  return s >= 3600 ? fmt::format("{}:{:02d}:{:02d}", s / 3600, (s / 60) % 60, s % 60)
                   : fmt::format("{:02d}:{:02d}", s / 60, s % 60);
}

// A progress bar with ETA on stderr: redrawn in place on a terminal, a line every few seconds
// (and for every failure) otherwise.
class Progress {
 public:
  explicit Progress(bool quiet) : quiet_(quiet), tty_(::isatty(2) == 1), start_(Clock::now()) {}

  void update(const ImageRecord& r, int done, int total) {
    if (r.status == ImageRecord::Status::kRendered) ++rendered_;
    if (r.status == ImageRecord::Status::kFailed) {
      clear_line();
      fmt::print(stderr, "lensopt render: skipped {}: {}\n", r.input.string(), r.error);
    }
    if (quiet_) return;
    const double elapsed = std::chrono::duration<double>(Clock::now() - start_).count();
    // Remaining time from the rendering rate so far (skipped outputs cost nothing).
    const int left = total - done;
    const std::string eta =
        rendered_ > 0 ? clock_text(elapsed / rendered_ * left) : std::string("--:--");
    const std::string status =
        fmt::format("{}/{} images  {} elapsed  ETA {}", done, total, clock_text(elapsed), eta);
    if (tty_) {
      constexpr int kWidth = 30;
      const int filled = total > 0 ? kWidth * done / total : kWidth;
      fmt::print(stderr, "\r[{}{}] {}  {}", std::string(filled, '#'),
                 std::string(kWidth - filled, '.'), status, r.relative_path.substr(0, 40));
      fmt::print(stderr, "\033[K");  // clear the rest of the line
      drawn_ = true;
      if (done == total) finish();
    } else if (done == total || elapsed - last_line_ > 2.0) {
      fmt::print(stderr, "lensopt render: {}\n", status);
      last_line_ = elapsed;
    }
  }
  void finish() {
    if (tty_ && drawn_) fmt::print(stderr, "\n");
    drawn_ = false;
  }

 private:
  void clear_line() {
    if (tty_ && drawn_) fmt::print(stderr, "\r\033[K");
  }
  bool quiet_;
  bool tty_;
  Clock::time_point start_;
  int rendered_ = 0;
  bool drawn_ = false;
  double last_line_ = -1e9;
};

// Where --annotations writes: OUT/<the JSON's name> (a BDD100K input: OUT/<stem>.coco.json).
fs::path annotations_output(const RenderCommand& cmd, bool coco) {
  const fs::path in(cmd.annotations);
  return fs::path(cmd.output_dir) /
         (coco ? in.filename() : fs::path(in.stem().string() + ".coco.json"));
}

// The record of an annotated image: its output path relative to OUT is the file name, or ends
// with it (a dataset folder given as the input: OUT/images/NAME); nullptr if none or several.
const ImageRecord* record_of(const std::vector<ImageRecord>& records, const std::string& name) {
  const ImageRecord* found = nullptr;
  int matches = 0;
  for (const ImageRecord& r : records) {
    if (r.relative_path == name) return &r;
    const std::string& p = r.relative_path;
    if (p.size() > name.size() && p.compare(p.size() - name.size(), name.size(), name) == 0 &&
        p[p.size() - name.size() - 1] == '/') {
      found = &r;
      ++matches;
    }
  }
  return matches == 1 ? found : nullptr;
}

// --annotations: the boxes of the rendered images (detection/crop_boxes.h), written in COCO with
// the input's file names (relative to the folder the input JSON's names were relative to). An
// image that was not rendered (failed, interrupted, not in the inputs or in another shard) is
// left out with a note.
void write_rendered_annotations(const RenderCommand& cmd, const Renderer& renderer,
                                const RenderOptions& options, const DatasetSummary& summary,
                                const DetectionDataset& input, const fs::path& out_path) {
  DetectionDataset rendered = input;
  rendered.images.clear();
  int left_out = 0;
  for (const DetectionImage& image : input.images) {
    const ImageRecord* r = record_of(summary.records, image.file_name);
    if (!r || (r->status != ImageRecord::Status::kRendered &&
               r->status != ImageRecord::Status::kSkipped)) {
      ++left_out;
      continue;
    }
    DetectionImage kept = image;
    if (r->width > 0) kept.width = r->width;
    if (r->height > 0) kept.height = r->height;
    if (kept.width <= 0 || kept.height <= 0) {
      const FloatImage pixels = read_image(fs::path(cmd.output_dir) / r->relative_path).image;
      kept.width = pixels.width;
      kept.height = pixels.height;
    }
    rendered.images.push_back(kept);
  }
  const DetectionDataset out =
      rendered_annotations(rendered, renderer.model(), options.res_factor, options.distortion);
  write_coco(out, out_path);
  fmt::print(
      "annotations: {} ({} images, {} boxes{}{})\n", out_path.string(), out.images.size(),
      out.annotations.size(), options.distortion ? ", distorted as rendered" : "",
      left_out > 0 ? fmt::format("; {} annotated images not rendered, left out", left_out) : "");
}

void run_render(const RenderCommand& cmd) {
  // SIGINT / SIGTERM: start no further image, write the metrics of what is done, exit 130.
  const InterruptScope interrupt;
  if (cmd.max_image_pixels > 0) set_max_image_pixels(cmd.max_image_pixels);
  // Every image allocates and frees buffers of tens of megabytes; by default glibc maps each
  // with mmap and unmaps it when freed, so every image faults its pages in again (about a tenth
  // of the CPU time of a dataset run). Keep freed memory in the heap for reuse instead.
  mallopt(M_MMAP_THRESHOLD, 512 << 20);
  mallopt(M_TRIM_THRESHOLD, 1024 << 20);
  RenderOptions options;
  options.res_factor = cmd.res_factor;
  options.distortion = !cmd.no_distortion;
  options.relative_illumination = !cmd.no_ri;
  options.threads = cmd.jobs;
  options.validate();
  DatasetOptions dataset;
  dataset.output_dir = cmd.output_dir;
  dataset.force = cmd.force;
  dataset.jobs = cmd.jobs;
  dataset.interrupt = interrupt.flag();
  if (!cmd.shard.empty()) parse_shard(cmd.shard, dataset.shard_index, dataset.shard_count);
  for (const std::string& in : cmd.inputs) dataset.inputs.emplace_back(in);

  // No input: render the built-in test chart (written to a temporary folder first).
  fs::path chart_dir;
  struct RemoveDir {
    fs::path* dir;
    ~RemoveDir() {
      std::error_code ec;
      if (!dir->empty()) fs::remove_all(*dir, ec);
    }
  } remove_chart_dir{&chart_dir};
  if (dataset.inputs.empty()) {
    chart_dir = fs::temp_directory_path() / fmt::format("lensopt-chart-{}", ::getpid());
    fs::create_directories(chart_dir);
    const Chart chart = make_test_chart(ChartOptions{});
    write_image(chart_dir / "chart.png", chart.image);
    dataset.inputs.push_back(chart_dir / "chart.png");
    if (!cmd.quiet)
      fmt::print(stderr, "lensopt render: no input given: rendering the built-in test chart\n");
  }
  dataset.validate();
  // Before any work: the output folder is writable and is none of the inputs.
  std::vector<fs::path> run_inputs = dataset.inputs;
  run_inputs.emplace_back(cmd.lens_path);
  check_output_dir(dataset.output_dir, run_inputs);
  // --annotations: read (and so checked) before any work; its output is no input.
  DetectionDataset annotations;
  fs::path annotations_out;
  if (!cmd.classes.empty() && cmd.annotations.empty())
    throw Error(SourceLocation{"--classes"},
                "--classes maps the categories of --annotations: "
                "give --annotations too");
  if (!cmd.annotations.empty()) {
    ClassMap classes;
    if (!cmd.classes.empty()) classes = read_class_map(cmd.classes);
    annotations = read_detection_dataset(cmd.annotations, cmd.classes.empty() ? nullptr : &classes);
    for (const std::string& note : annotations.notes)
      fmt::print(stderr, "lensopt render: {}: {}\n", cmd.annotations, note);
    if (dataset.shard_count > 1)
      throw Error("--annotations needs the whole dataset: give it to a run without --shard");
    // COCO is a JSON object, BDD100K a list (detection/dataset.h).
    const std::string text = read_file(cmd.annotations);
    const std::size_t first = text.find_first_not_of(" \t\r\n");
    const bool coco = first != std::string::npos && text[first] == '{';
    annotations_out = annotations_output(cmd, coco);
    run_inputs.emplace_back(cmd.annotations);
    check_output_file(annotations_out, run_inputs);
  }

  const Lens lens = read_lens(cmd.lens_path);
  check_lens_warnings(lens, "render", false);
  const auto t0 = Clock::now();
  TraceOptions trace;
  trace.threads = cmd.jobs;
  ImagingModel model = build_imaging_model(lens, trace);
  for (const std::string& w : model.warnings)
    fmt::print(stderr, "lensopt render: warning: {}\n", w);
  // The geometric PSFs stay as they are; diffraction / auto replace them per field and channel.
  WaveOptions wave;
  wave.pupil_samples = cmd.pupil_samples;
  const PsfChoice choice = apply_psf_kind(model, lens, parse_psf_kind(cmd.psf), wave);
  if (choice.kind != PsfKind::kGeometric) {
    fmt::print(stderr,
               "lensopt render: --psf {}: diffraction PSFs ({} x {} pupil) in {} of {} field "
               "channels, geometric in the rest\n",
               psf_kind_name(choice.kind), cmd.pupil_samples, cmd.pupil_samples,
               choice.diffraction_channels, choice.channels);
    for (const std::string& w : choice.warnings)
      fmt::print(stderr, "lensopt render: warning: {}\n", w);
  }
  const Renderer renderer(std::move(model), options);
  if (!cmd.quiet) {
    fmt::print(stderr,
               "lensopt render: {}: PSFs of {} fields x {} wavelengths x {} rays sampled in {:.2f} "
               "s\n",
               lens.name, renderer.model().fields_deg.size(), lens.specs.wavelengths_nm.size(),
               2 * trace.rings * trace.rings,
               std::chrono::duration<double>(Clock::now() - t0).count());
  }
  Progress progress(cmd.quiet);
  const DatasetSummary summary = render_dataset(
      renderer, dataset,
      [&](const ImageRecord& r, int done, int total) { progress.update(r, done, total); });
  progress.finish();
  for (const std::string& note : summary.notes)
    fmt::print(stderr, "lensopt render: note: {}\n", note);
  if (dataset.shard_count > 1)
    fmt::print("shard {}/{}: {} of the dataset's {} images\n", dataset.shard_index,
               dataset.shard_count, summary.records.size(), summary.dataset_images);
  fmt::print("rendered {}, skipped {} (already there), failed {} in {:.2f} s\n", summary.rendered,
             summary.skipped, summary.failed, summary.seconds);
  if (summary.mean_psnr_db || summary.mean_ssim) {
    fmt::print(
        "mean PSNR {} dB, mean SSIM {} (input vs blurred, before illumination and "
        "distortion)\n",
        summary.mean_psnr_db ? fmt::format("{:.3f}", *summary.mean_psnr_db) : "n/a",
        summary.mean_ssim ? fmt::format("{:.4f}", *summary.mean_ssim) : "n/a");
  }
  fmt::print("metrics: {} and {}\n", summary.csv_path.string(), summary.json_path.string());
  if (!cmd.annotations.empty() && !summary.was_interrupted)
    write_rendered_annotations(cmd, renderer, options, summary, annotations, annotations_out);
  if (summary.was_interrupted) {
    fmt::print(stderr,
               "lensopt render: interrupted with {} image(s) not rendered; run the same command "
               "again to resume\n",
               summary.interrupted);
    throw ExitCode{130};
  }
  if (summary.failed > 0) {
    fmt::print(stderr, "lensopt render: {} input{} could not be rendered:\n", summary.failed,
               summary.failed == 1 ? "" : "s");
    for (const ImageRecord& r : summary.records)
      if (r.status == ImageRecord::Status::kFailed)
        fmt::print(stderr, "  {}: {}\n", r.input.string(), r.error);
    throw ExitCode{1};
  }
}

void run_render_merge(const RenderMergeCommand& cmd) {
  std::vector<fs::path> dirs(cmd.dirs.begin(), cmd.dirs.end());
  if (cmd.output_dir.empty() && dirs.size() > 1)
    throw Error("render merge: give -o OUT for the merged folder (shards in several folders)");
  const fs::path out = cmd.output_dir.empty() ? dirs.front() : fs::path(cmd.output_dir);
  const DatasetSummary summary = merge_render_metrics(dirs, out);
  for (const std::string& note : summary.notes)
    fmt::print(stderr, "lensopt render merge: note: {}\n", note);
  fmt::print("merged {} images: rendered {}, failed {}\n", summary.records.size(), summary.rendered,
             summary.failed);
  if (summary.mean_psnr_db || summary.mean_ssim) {
    fmt::print("mean PSNR {} dB, mean SSIM {}\n",
               summary.mean_psnr_db ? fmt::format("{:.3f}", *summary.mean_psnr_db) : "n/a",
               summary.mean_ssim ? fmt::format("{:.4f}", *summary.mean_ssim) : "n/a");
  }
  fmt::print("metrics: {} and {}\n", summary.csv_path.string(), summary.json_path.string());
  if (summary.failed > 0) throw ExitCode{1};
}

}  // namespace

void setup_render(CLI::App& app) {
  auto cmd = std::make_shared<RenderCommand>();
  auto merge = std::make_shared<RenderMergeCommand>();
  CLI::App* sub = app.add_subcommand(
      "render",
      "Aberrated images: spatially varying PSF blur, relative illumination and distortion of a "
      "lens, for image files or whole folders (PNG, JPEG, TIFF, EXR)");
  sub->add_option("LENS", cmd->lens_path, "lens file (.toml, the paper's .yml or Zemax .zmx)");
  sub->add_option("INPUT", cmd->inputs,
                  "image files or folders (searched recursively); none: the built-in test chart");
  sub->add_option("-o,--output", cmd->output_dir,
                  "output folder: same relative paths, names, formats and bit depths, plus "
                  "render_metrics.csv/.json (required)");
  sub->add_option("--res-factor", cmd->res_factor,
                  "simulated resolution factor: 1 (image diagonal = sensor diagonal) or 2 (the "
                  "image is a quadrant of a sensor twice as large)")
      ->check(CLI::IsMember({1, 2}));
  sub->add_flag("--no-distortion", cmd->no_distortion, "do not apply the distortion warp");
  sub->add_flag("--no-relative-illumination,--no-ri", cmd->no_ri,
                "do not apply relative illumination (--no-ri: old name)");
  sub->add_option("--threads,--jobs,-j", cmd->jobs,
                  "threads in all (0: all cores; --jobs: old name)")
      ->check(CLI::Range(0, 1024));
  sub->add_option("--psf", cmd->psf,
                  "PSF model: geometric (default: ray density), diffraction (FFT of the pupil "
                  "function) or auto (per field and colour channel the larger blur, by RMS "
                  "radius)")
      ->check(CLI::IsMember({"geometric", "diffraction", "auto"}));
  sub->add_option(
         "--pupil-samples", cmd->pupil_samples,
         fmt::format("pupil grid cells across the diameter for the diffraction PSFs (default {})",
                     kRenderPupilSamples))
      ->check(CLI::Range(8, 1024));
  sub->add_option("--max-image-pixels", cmd->max_image_pixels,
                  "refuse an input whose header says more pixels than this, before decoding it "
                  "(default 268435456 = 16384^2; also LENSOPT_MAX_IMAGE_PIXELS)")
      ->check(CLI::Range(1LL, 1LL << 40));
  sub->add_flag("--force", cmd->force, "render images whose output already exists");
  sub->add_flag("--quiet,-q", cmd->quiet, "no progress bar");
  sub->add_option("--annotations", cmd->annotations,
                  "detection annotations of the inputs (COCO or BDD100K JSON): also write them as "
                  "the rendered images show them (boxes distorted, clipped), as COCO, to "
                  "OUT/<its name>");
  sub->add_option("--classes", cmd->classes,
                  "with --annotations: a TOML file whose [classes] table gathers the "
                  "annotations' categories by name (docs/detection.md); the written COCO has the "
                  "map's classes. Default: COCO's categories as written, BDD100K's through the "
                  "paper's six classes");
  sub->add_option("--shard", cmd->shard,
                  "render slice I of N (1-based): the images at positions k (input order) with "
                  "k mod N = I-1; metrics in render_metrics-shardIofN.csv/.json; join them with "
                  "`lensopt render merge`");

  CLI::App* m = sub->add_subcommand(
      "merge",
      "Join the metrics of render shards (--shard I/N) into render_metrics.csv/.json, as one run "
      "writes them; images of shards in other folders are copied to the merged folder");
  m->add_option("DIR", merge->dirs, "output folders of the shards (one, if they share it)")
      ->required();
  m->add_option("-o,--output", merge->output_dir, "merged folder (default: the one DIR given)");
  m->callback([merge] { run_render_merge(*merge); });

  sub->callback([cmd, m] {
    if (m->parsed()) return;
    if (cmd->lens_path.empty()) throw Error("render: give a LENS file");
    if (cmd->output_dir.empty()) throw Error("render: give the output folder with -o OUT");
    run_render(*cmd);
  });
}

}  // namespace lensopt::cli
