// lensopt._lensopt: registers each area's bindings and translates lensopt::Error.
#include <cerrno>
#include <cstring>
#include <system_error>

#include "bindings.h"
#include "lensopt/core/error.h"

namespace lensopt::python {

void require_file(const std::filesystem::path& path) {
  std::error_code ec;
  if (std::filesystem::exists(path, ec)) return;
  // FileNotFoundError(errno, strerror, filename), as open() raises it.
  py::object type = py::module_::import("builtins").attr("FileNotFoundError");
  py::object instance = type(ENOENT, std::strerror(ENOENT), path.string());
  PyErr_SetObject(type.ptr(), instance.ptr());
  throw py::error_already_set();
}

TraceOptions trace_options(int rings, int fields, bool ray_aiming, bool scale_to_spec,
                           int threads) {
  TraceOptions o;
  o.rings = rings;
  o.fields = fields;
  o.ray_aiming = ray_aiming;
  o.scale_to_spec = scale_to_spec;
  o.threads = threads;
  o.validate();
  return o;
}

}  // namespace lensopt::python

PYBIND11_MODULE(_lensopt, m) {
  namespace py = pybind11;
  using namespace lensopt::python;
  m.doc() = "lensopt's C++ core (the Python API is the package lensopt; see its __init__).";
  static py::exception<lensopt::Error> error(m, "LensoptError", PyExc_ValueError);
  error.doc() =
      "Bad input or an I/O failure; str() reads 'file:line:column: message' as the CLI prints it. "
      "Attributes: file, line, column (0: unknown), message.";
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const lensopt::Error& e) {
      py::object type = error;
      py::object instance = type(e.what());
      instance.attr("file") = e.where().file;
      instance.attr("line") = e.where().line;
      instance.attr("column") = e.where().column;
      instance.attr("message") = e.message();
      PyErr_SetObject(error.ptr(), instance.ptr());
    }
  });
  bind_lens(m);
  bind_analysis(m);
  bind_render(m);
  bind_optimize(m);
  bind_imaging(m);
#ifndef LENSOPT_OPENMP_RUNTIME
#define LENSOPT_OPENMP_RUNTIME "libgomp"
#endif
  // Which OpenMP runtime runs lensopt's parallel loops (python/CMakeLists.txt): "libomp" (LLVM's,
  // private to the extension, passive whatever was imported before) or "libgomp" (shared with
  // torch: its wait policy is fixed by whoever loads it first).
  m.attr("openmp_runtime") = LENSOPT_OPENMP_RUNTIME;
}
