// Rendering image files and whole dataset trees (`lensopt render LENS INPUT... -o OUT`).
//
// Inputs are files or directories (searched recursively for .png .jpg .jpeg .tif .tiff .exr, any
// case; hidden files and folders and anything inside OUT are left out). A file inside a directory
// input D keeps its path relative to D under OUT; a file input goes to OUT/<name>. Each output has
// the input's format and pixel type and is written atomically. An output that already exists is
// skipped unless `force` (resume) if it is complete: a completion record of the previous run
// (render_metrics.json, or the journal .render_metrics.journal that gets one line per image right
// after its rename) names it with its size and the file opens as an image of that size; any other
// existing output is rendered again. Temporaries of a killed earlier run are removed. No output
// may replace an input (refused before any work). `interrupt` (set by SIGINT/SIGTERM) stops the
// run after the images in flight; the metrics of what is done are written. An input that cannot be
// read or rendered (missing, corrupt, empty, unsupported, smaller than the PSF) is recorded as
// failed and the run goes on. OUT/render_metrics.csv and OUT/render_metrics.json list every image
// with its status, PSNR and SSIM (input vs blurred, before relative illumination and distortion)
// and their means; they are rewritten atomically at least every 10 s and at the end (the journal
// covers the time between).
//
// Shards (`--shard I/N`): the whole dataset is listed and checked as above, then a run renders
// only the images whose position k in that list (input order) has k mod N = I - 1, and writes its
// metrics as render_metrics-shardIofN.csv/.json (journal .render_metrics-shardIofN.journal), with
// the position of each image, the dataset's size and fingerprint (FNV-1a 64 over the output
// paths in order). Shards may share one output folder or use one each; a shard resumes like a
// whole run, and removes only the temporaries of its own outputs (another shard may be writing
// beside it, on another machine). `merge_render_metrics` joins the shards' metrics in dataset
// order into render_metrics.csv/.json, byte for byte what one run writes (but the seconds),
// copying the images into the merged folder when a shard has its own.
#pragma once

#include <atomic>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "lensopt/render/render.h"

namespace lensopt {

struct DatasetOptions {
  std::vector<std::filesystem::path> inputs;
  std::filesystem::path output_dir;
  bool force = false;  // render even if the output exists
  int jobs = 0;  // threads in all (images in parallel; one image alone: inside it); 0: all cores
  const std::atomic<bool>* interrupt = nullptr;  // set: start no further image
  int shard_index = 1, shard_count = 1;          // render slice I of N (1 <= I <= N)

  // Throws Error if there is no input, no output directory, jobs < 0 or a bad shard.
  void validate() const;
};

struct ImageRecord {
  enum class Status { kRendered, kSkipped, kFailed, kInterrupted };
  std::filesystem::path input;
  int index = -1;             // position in the whole dataset (input order)
  std::string relative_path;  // output path relative to OUT ("" if it has none)
  Status status = Status::kFailed;
  std::optional<double> psnr_db;  // +inf when the blur changed nothing
  std::optional<double> ssim;
  int width = 0, height = 0;
  double seconds = 0;
  std::string error;  // for kFailed
};

const char* status_name(ImageRecord::Status status);

struct DatasetSummary {
  std::vector<ImageRecord> records;  // input order (a shard: its images only)
  int dataset_images = 0;            // images in the whole dataset (all shards)
  std::string dataset_fingerprint;   // FNV-1a 64 of the output paths, hex
  int rendered = 0, skipped = 0, failed = 0, interrupted = 0;
  bool was_interrupted = false;        // `interrupt` was set during the run
  int stale_temp_files_removed = 0;    // temporaries of an earlier run
  std::optional<double> mean_psnr_db;  // over images with a finite PSNR
  std::optional<double> mean_ssim;
  double seconds = 0;
  std::filesystem::path csv_path, json_path;
  std::vector<std::string> notes;  // e.g. previous metrics from other settings
};

// Called after each image (serialized), with the number done and the total.
using DatasetProgress = std::function<void(const ImageRecord& record, int done, int total)>;

// Renders every input. Throws Error only for problems with the run as a whole (no inputs, an
// output directory that cannot be created or written, two inputs with the same output path).
DatasetSummary render_dataset(const Renderer& renderer, const DatasetOptions& options,
                              const DatasetProgress& progress = {});

// The metrics files' name without extension: "render_metrics", or "render_metrics-shardIofN".
std::string metrics_stem(int shard_index, int shard_count);

// Joins the shard metrics (render_metrics-shardIofN.json) found in `dirs` into
// `output_dir`/render_metrics.csv/.json in dataset order, as one run over the whole dataset writes
// them (an image a resumed shard skipped counts as rendered); images of a shard in another folder
// are copied (atomically) to `output_dir`. Throws Error, before writing anything, naming what is
// wrong: shards of different datasets or settings, a shard missing or given twice, or one that
// has not finished (interrupted images or a journal left by a kill: run it again).
DatasetSummary merge_render_metrics(const std::vector<std::filesystem::path>& dirs,
                                    const std::filesystem::path& output_dir);

// Reads, renders and writes one image (atomically). Throws Error naming the file.
RenderResult render_file(const Renderer& renderer, const std::filesystem::path& input,
                         const std::filesystem::path& output, int threads = 0);

// Checks that `dir` exists or can be created and that a file can be written in it; throws Error
// saying why not.
void ensure_writable_directory(const std::filesystem::path& dir);

}  // namespace lensopt
