// lensopt._lensopt: registers each area's bindings and translates lensopt::Error.
#include <dlfcn.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <future>
#include <string>
#include <system_error>
#include <thread>

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

// Keeps a team of `threads` threads of an already loaded libgomp (`library`, its path) idle for
// the rest of the process: a thread of ours starts one parallel region of that many threads
// through the library's own GOMP_parallel and then sleeps. libgomp spins only briefly (100
// iterations, then sleeps) while it manages more threads than there are CPUs (the libgomp manual,
// GOMP_SPINCOUNT), so with threads = CPUs + 1 the threads of every team of that libgomp (torch's,
// loaded before lensopt could set OMP_WAIT_POLICY) wait as good as passively. __init__.py calls
// it only when libgomp was loaded first and the user set neither OMP_WAIT_POLICY nor
// GOMP_SPINCOUNT.
void park_gomp_threads(const std::string& library, int threads) {
  if (threads < 2 || threads > 4096)
    throw lensopt::Error("park_gomp_threads: " + std::to_string(threads) + " threads");
  void* handle = dlopen(library.c_str(), RTLD_NOW | RTLD_NOLOAD);
  if (!handle) throw lensopt::Error(library + ": not loaded");
  using Parallel = void (*)(void (*)(void*), void*, unsigned, unsigned);
  auto parallel = reinterpret_cast<Parallel>(dlsym(handle, "GOMP_parallel"));
  dlclose(handle);  // the library stays loaded (RTLD_NOLOAD took a reference to a loaded one)
  if (!parallel) throw lensopt::Error(library + ": no GOMP_parallel");
  // Returns once the team has run (its threads exist and count as libgomp's).
  std::promise<void> started;
  std::future<void> ran = started.get_future();
  std::thread([parallel, threads, started = std::move(started)]() mutable {
    parallel([](void*) {}, nullptr, static_cast<unsigned>(threads), 0);
    started.set_value();
    for (;;) pause();  // the team's threads stay in libgomp's pool while this thread lives
  }).detach();
  py::gil_scoped_release release;
  ran.wait();
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
  m.def("_park_gomp_threads", &park_gomp_threads, py::arg("library"), py::arg("threads"),
        "Keeps `threads` threads of the loaded libgomp at `library` idle, so that libgomp spins "
        "only briefly (lensopt/__init__.py; module.cpp says why).");
}
