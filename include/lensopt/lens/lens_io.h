// Reading and writing lens prescriptions.
//
// Native TOML (read and written losslessly):
//   [lens]     name = "...", catalog = "ohara"
//   [specs]    f_number, half_field_deg, sensor_diagonal_mm, wavelengths_nm = [...],
//              channels = ["R", ...] (optional), dispersion = "abbe" | "catalog"
//   [[surfaces]] radius_mm = 9.1 (or "inf" / inf for flat; or curvature_per_mm = 0.11),
//              thickness_mm = 2.4, material = "S-LAH64" | { nd = 1.7, vd = 48 } (absent = air),
//              stop = true, semi_diameter_mm = 5 (optional),
//              conic = -1.0 (k, optional), asphere = [a4, a6, ..., a16] (optional, up to 7 terms;
//              a_{2i} in mm^(1-2i): a4 in mm^-3, a6 in mm^-5, ...), asphere_r2 = a2 (optional,
//              1/mm: Zemax EVENASPH PARM 1, adds paraxial power 2 a2). Sag in lens/lens.h.
// Other tables (e.g. [optimize], [tolerance]) are kept verbatim on a round trip.
// The paper's YAML (stop_idx, sequence of G/A, hfov, f_number, c, t, nd, v) is read as is:
// model glasses, the paper's specs.
#pragma once

#include <filesystem>
#include <string>
#include <string_view>

#include "lensopt/lens/lens.h"

namespace lensopt {

// Reading a lens file by its extension (.toml, .yml/.yaml, .zmx) is formats/lens_file.h's
// read_lens: the Zemax reader needs paraxial optics, which sit above this module.
// Glass names resolve against the lens's catalog (load_catalog). Throws Error with file:line:col.
Lens parse_lens_toml(std::string_view text, const std::string& source_name);
Lens parse_lens_yaml(std::string_view text, const std::string& source_name);

// The native TOML text of a lens; parse_lens_toml(format_lens_toml(l)) == l, every number exact.
std::string format_lens_toml(const Lens& lens);

// Writes a lens as native TOML, atomically (formats/lens_file.h's write_lens picks by extension).
void write_lens_toml(const Lens& lens, const std::filesystem::path& path);

}  // namespace lensopt
