// The output layer: every file lensopt writes goes through it (write_file_atomic and
// write_file_atomic_with in atomic_file.h, these checks beside them; both in atomic_file.cpp).
//
// 1. Before any work, a command checks each output with `check_output_file` /
//    `check_output_dir`: the folder exists and is writable, the path is not a folder, and it is
//    not one of the run's inputs (same path or same inode), else an Error naming the file.
// 2. `write_file_atomic_with` writes to a temporary file beside the target
//    (".<stem>.tmp<pid>-<n><ext>", so writers that pick a format by extension still work),
//    verifies it (it exists and is not empty, every byte written, fsync(2) succeeded), renames it
//    over the target and fsyncs the folder. A reader never sees a half-written lens, image or
//    report, and a full disk is an Error naming the file, never a truncated or 0-byte output.
// 3. `remove_stale_temp_files` deletes the temporaries a killed earlier run left (their pid is
//    no longer alive), so a resumed run leaves none behind.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

namespace lensopt {

// Whether a and b name the same file (same inode if both exist, else the same normal path).
bool same_file(const std::filesystem::path& a, const std::filesystem::path& b);

// Throws Error naming `path` unless it can be written: its folder exists and is writable, it is
// not a folder, and it is none of `inputs`. Call it before any work.
void check_output_file(const std::filesystem::path& path,
                       const std::vector<std::filesystem::path>& inputs = {});

// Throws Error naming `dir` unless it is (or can be created as) a writable folder that is none of
// `inputs`. Creates it.
void check_output_dir(const std::filesystem::path& dir,
                      const std::vector<std::filesystem::path>& inputs = {});

// Whether `name` is a temporary of write_file_atomic_with; sets *pid to its writer's process id.
bool is_temp_file_name(const std::string& name, long* pid = nullptr);

// Removes the temporaries of processes that are no longer alive under `dir` (recursively if
// `recursive`). Returns how many were removed.
int remove_stale_temp_files(const std::filesystem::path& dir, bool recursive = true);

}  // namespace lensopt
