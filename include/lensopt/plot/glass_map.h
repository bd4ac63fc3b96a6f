// The glass map: nd against vd of catalog glasses, vd decreasing to the right as glass makers
// draw it, one colour per catalog; glasses without nd or vd (infrared materials) are left out.
#pragma once

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "lensopt/glass/glass.h"

namespace lensopt::plot {

struct GlassMapOptions {
  std::string title = "Glass map";
  bool label_glasses = false;  // write each glass's name beside its dot (small catalogs)
};

// Draws the glasses of `catalogs` (only those listed in `glasses`, by pointer, when it is not
// empty) and writes the picture to `path` (.svg or .png). Returns the number of glasses drawn.
int write_glass_map(const std::filesystem::path& path,
                    const std::vector<std::shared_ptr<const Catalog>>& catalogs,
                    const std::vector<const Glass*>& glasses, const GlassMapOptions& options);

}  // namespace lensopt::plot
