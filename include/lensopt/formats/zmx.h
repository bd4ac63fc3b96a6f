// Zemax OpticStudio sequential lens files (.zmx): import and export of spherical systems.
//
// A .zmx file is a list of lines "KEY field field ...", UTF-16 LE with a BOM or ASCII / UTF-8,
// CRLF or LF. System lines come first, then one block per surface:
//   UNIT MM ...            lens units (CM, IN and METER are converted to mm)
//   ENPD d | FNUM F [t]    entrance-pupil diameter d, or image-space F/# F = EFL / EPD
//   WAVM i w_um weight     wavelength i in micrometres (WAVL w1 w2 ... in older files)
//   FTYP type flag nf nw   field type (0: angle, degrees), number of fields and wavelengths
//   XFLN / YFLN x1 x2 ...  field coordinates; GCAT A B ...  glass catalogs searched in order
//   SURF n                 surface n: 0 the object, the last one the image
//     TYPE STANDARD | EVENASPH, CURV c (1/mm), DISZ t (mm, INFINITY for the object), STOP,
//     GLAS name ... | GLAS ___BLANK 1 0 nd vd ... (a model glass), DIAM semi-diameter,
//     CONI k (conic constant), PARM i a (EVENASPH: i = 1..8 the coefficients of r^2, r^4, ...,
//     r^16 in lens units^(1-2i); lensopt's asphere_r2 and asphere = [a4, ..., a16])
//
// Mapping to lensopt's Lens (whose surfaces are the lens surfaces only):
//   surfaces       SURF 1 .. N-1; surface k's thickness is its DISZ, so the last lens surface's
//                  thickness is the distance to the image. The object must be at infinity.
//   stop           a STOP on a curved surface becomes a flat stop surface 0 mm before it (lensopt's
//                  stop is flat): the same paraxial pupil, reported as a warning.
//   f_number       FNUM F, or EFL / ENPD with the paraxial EFL at 587.6 nm.
//   half_field_deg the largest field sqrt(x^2 + y^2) among the active fields (FTYP 0 only).
//   wavelengths    the active WAVM (or WAVL) wavelengths in nm; channels by wavelength:
//                  < 490 nm B, < 580 nm G, else R (a warning says so).
//   sensor         2 EFL tan(half field), so the spec focal length is the lens's own EFL.
//   dispersion     "catalog" when the lens has catalog glasses (as OpticStudio computes), else
//                  "abbe".
// What lensopt has and Zemax lacks travels in NOTE lines ("NOTE 0 lensopt <key> <value>": catalog,
// sensor_diagonal_mm, dispersion, channels, wavelengths_nm, and the extra TOML tables), so
// TOML -> ZMX -> TOML is exact; a note contradicted by the Zemax data is ignored with a warning.
//
// Export writes TYPE EVENASPH with PARM 1..8 for a surface with asphere terms (else STANDARD)
// and CONI when k != 0.
// Errors (lensopt::Error at file:line:column, one line naming the feature): a surface type other
// than STANDARD or EVENASPH, an EVENASPH PARM beyond 8, a mirror, a finite object, a curved image,
// a field type other than angle, an unknown unit, a glass in none of the GCAT catalogs (naming
// them). Lines lensopt does not model are warnings with their line numbers, never dropped silently.
#pragma once

#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "lensopt/lens/lens.h"

namespace lensopt {

// A lens read from a .zmx file, with the warnings ("file:line: message") of lines it ignored.
struct ZmxImport {
  Lens lens;
  std::vector<std::string> warnings;
};

// Parses .zmx bytes (UTF-16 LE/BE with a BOM, or ASCII / UTF-8; CRLF or LF). `source_name`
// names the file in messages and becomes Lens::source_path.
ZmxImport parse_zmx(std::string_view bytes, const std::string& source_name);

// Reads a .zmx file (parse_zmx of its contents).
ZmxImport read_zmx(const std::filesystem::path& path);

// The .zmx text (ASCII, CRLF line ends) of a lens, as OpticStudio reads it; every number is the
// shortest decimal that reads back to the same double.
std::string format_zmx(const Lens& lens);

// Writes format_zmx(lens) atomically.
void write_zmx(const Lens& lens, const std::filesystem::path& path);

// The GCAT catalogs of a lens's .zmx: its own catalog (zemax_catalog_name), then every other
// catalog its glasses come from, so that each glass reads back from its own catalog (a reader
// takes a glass name from the first catalog, in this order, that has it). Empty without catalog
// glasses. Throws Error naming the surface when a glass would read back as another catalog's
// glass of the same name, or from no catalog.
std::vector<std::string> zmx_gcat_names(const Lens& lens);

// The Zemax catalog name (GCAT) for a lensopt catalog name: "ohara" -> "OHARA", a path -> its
// stem, otherwise the name as is.
std::string zemax_catalog_name(std::string_view catalog_name);

}  // namespace lensopt
