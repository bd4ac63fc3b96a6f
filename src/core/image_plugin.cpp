// image_plugin: liblensopt_oiio.so loaded once, on first use (core/image_plugin.h).
#include "core/image_plugin.h"

#include <fmt/format.h>

#include <atomic>
#include <cstdlib>
#include <mutex>

#include "core/plugin.h"
#include "lensopt/core/error.h"

namespace lensopt {
namespace {

struct ImageLoad {
  const ImagePlugin* plugin = nullptr;
  std::string error;
};

std::atomic<bool> g_loaded{false};

std::string check_table(const void* table) {
  const auto* p = static_cast<const ImagePlugin*>(table);
  if (p->abi != kImagePluginAbi || p->decoded_size != sizeof(DecodedImage) ||
      p->request_size != sizeof(EncodeRequest) || !p->read || !p->read_size || !p->write ||
      !p->verify || !p->spec_type || !p->render_text || !p->text_size || !p->make_surface)
    return fmt::format(
        "built by another lensopt build (interface {} here, {} there); "
        "rebuild lensopt",
        kImagePluginAbi, p->abi);
  return "";
}

const ImageLoad& load() {
  static std::once_flag once;
  static ImageLoad loaded;
  std::call_once(once, [] {
#ifndef LENSOPT_WITH_OIIO
    loaded.error =
        "lensopt was built without OpenImageIO (LENSOPT_WITH_OIIO=OFF); rebuild with "
        "-DLENSOPT_WITH_OIIO=ON and Debian's libopenimageio-dev";
#else
    const LoadedPlugin p =
        load_plugin({kImagePluginFile, "LENSOPT_OIIO_PLUGIN", kImagePluginSymbol, check_table});
    loaded.plugin = static_cast<const ImagePlugin*>(p.table);
    if (!p.table)
      loaded.error =
          std::getenv("LENSOPT_OIIO_PLUGIN")
              ? p.error
              : fmt::format("lensopt's OpenImageIO module {} could not be loaded (set "
                            "LENSOPT_OIIO_PLUGIN to its path); {}",
                            kImagePluginFile, p.error);
#endif
    g_loaded.store(loaded.plugin != nullptr);
  });
  return loaded;
}

}  // namespace

const ImagePlugin& image_plugin(const std::string& what) {
  const ImageLoad& l = load();
  if (!l.plugin) throw Error(fmt::format("{}: {}", what, l.error));
  return *l.plugin;
}

bool image_plugin_loaded() {
  return g_loaded.load();
}

bool image_plugin_available() {
  return load().plugin != nullptr;
}

}  // namespace lensopt
