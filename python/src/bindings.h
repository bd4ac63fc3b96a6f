// The Python extension module lensopt._lensopt: a thin pybind11 layer over lensopt_core, one file
// per area (lens.cpp, analysis.cpp, render.cpp, optimize.cpp, imaging.cpp), registered by
// module.cpp. Conventions of the layer:
//   - lensopt::Error becomes lensopt.LensoptError (a ValueError) whose message is what() with the
//     file:line:column of the input; the exception object also carries .file, .line, .column.
//   - Calls that trace or render release the GIL (py::gil_scoped_release) while the core runs.
//   - Long calls with an interrupt hook (optimize) install a SIGINT handler for their duration
//     (InterruptScope): Ctrl-C stops them early, then KeyboardInterrupt is raised.
//   - Arrays: numpy in (converted to the core's layout with one copy where the layouts differ),
//     numpy out (owning the core's buffer, no further copy).
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <atomic>
#include <filesystem>
#include <vector>

#include "lensopt/core/interrupt.h"
#include "lensopt/lens/lens.h"
#include "lensopt/trace/system.h"

namespace lensopt::python {

namespace py = pybind11;

void bind_lens(py::module_& m);
void bind_analysis(py::module_& m);
void bind_render(py::module_& m);
void bind_optimize(py::module_& m);
void bind_imaging(py::module_& m);

// A numpy array that owns `values` (moved), with the given shape (C order).
template <typename T>
py::array_t<T> to_numpy(std::vector<T>&& values, std::vector<py::ssize_t> shape) {
  auto* heap = new std::vector<T>(std::move(values));
  py::capsule owner(heap, [](void* p) { delete static_cast<std::vector<T>*>(p); });
  return py::array_t<T>(shape, heap->data(), owner);
}

// Raises FileNotFoundError (errno ENOENT, the path as its filename) when `path` does not exist:
// every function that reads a file calls it first, as Python's open() would fail.
void require_file(const std::filesystem::path& path);

// TraceOptions from the common keyword arguments.
TraceOptions trace_options(int rings, int fields, bool ray_aiming, bool scale_to_spec, int threads);

}  // namespace lensopt::python
