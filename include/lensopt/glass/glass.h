// Optical glasses and glass catalogs (Zemax AGF).
//
// A glass's refractive index comes from one of the dispersion formulas of the AGF format, with
// the wavelength lambda in micrometres and coefficients c0..c9 as the file's CD line gives them:
//   1 Schott:      n^2 = c0 + c1 l^2 + c2 l^-2 + c3 l^-4 + c4 l^-6 + c5 l^-8
//   2 Sellmeier 1: n^2 - 1 = c0 l^2/(l^2-c1) + c2 l^2/(l^2-c3) + c4 l^2/(l^2-c5)
//   3 Herzberger:  n = A + B L + C L^2 + D l^2 + E l^4 + F l^6, L = 1/(l^2 - 0.028)
//   4 Sellmeier 2: n^2 - 1 = c0 + c1 l^2/(l^2-c2^2) + c3/(l^2-c4^2)
//   5 Conrady:     n = c0 + c1/l + c2/l^3.5
//   6 Sellmeier 3, 9 Sellmeier 4, 11 Sellmeier 5: Sellmeier 1 with 4, (special form), 5 terms
//   7 Handbook of Optics 1, 8 Handbook of Optics 2, 10/12/13 Extended 1/2/3
// (src/glass/glass.cpp states each one exactly). Indices are relative to air, as in AGF.
#pragma once

#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace lensopt {

// Zemax's dispersion formula ids, as written on an AGF NM line.
enum class DispersionFormula : int {
  kSchott = 1,
  kSellmeier1 = 2,
  kHerzberger = 3,
  kSellmeier2 = 4,
  kConrady = 5,
  kSellmeier3 = 6,
  kHandbook1 = 7,
  kHandbook2 = 8,
  kSellmeier4 = 9,
  kExtended1 = 10,
  kSellmeier5 = 11,
  kExtended2 = 12,
  kExtended3 = 13,
  // lensopt's extension, for catalogs made from the refractiveindex.info database
  // (tools/make-rii-catalogs.py; glass/formulas.h states each): its formulas 1..9, and a table.
  kRiiSellmeier = 101,
  kRiiSellmeier2 = 102,
  kRiiPolynomial = 103,
  kRiiInfo = 104,
  kRiiCauchy = 105,
  kRiiGases = 106,
  kRiiHerzberger = 107,
  kRiiRetro = 108,
  kRiiExotic = 109,
  kTable = 120,  // tabulated n: CD l1 n1 l2 n2 ... (um), interpolated
};

// Human-readable formula name ("Sellmeier 1"); "unknown (N)" for an id not listed above.
std::string formula_name(DispersionFormula formula);

// Zemax's glass status codes (NM line, 5th field).
enum class GlassStatus : int {
  kStandard = 0,
  kPreferred = 1,
  kObsolete = 2,
  kSpecial = 3,
  kMelt = 4
};
std::string status_name(GlassStatus status);

// One internal-transmission sample (AGF IT line).
struct TransmissionPoint {
  double wavelength_um = 0;
  double transmission = 0;  // internal transmission, 0..1
  double thickness_mm = 0;  // sample thickness the transmission refers to
};

// One glass of a catalog.
struct Glass {
  std::string name;
  std::string catalog;  // the catalog it came from ("OHARA" for OHARA_20200623.AGF)
  DispersionFormula formula = DispersionFormula::kSellmeier1;
  bool formula_supported = true;     // false: index() must not be trusted (reported by the reader)
  double nd = 1.0;                   // d-line index as the file states it
  double vd = 0.0;                   // Abbe number as the file states it
  std::vector<double> coefficients;  // CD line, c0..c9 (missing ones are 0; the database
                                     // formulas 101.. and the table keep the line's count)
  double min_wavelength_um = 0.0;    // LD line: valid range of the formula
  double max_wavelength_um = 0.0;
  GlassStatus status = GlassStatus::kStandard;
  std::vector<TransmissionPoint> transmission;  // IT lines, in file order
  int source_line = 0;                          // line of the NM entry in the file
  std::string comment;                          // GC line(s): where the data comes from

  // Refractive index at a wavelength (nm, in air) from the glass's own formula.
  double index(double wavelength_nm) const;

  // Whether the IT data (if any) says the glass transmits at this wavelength: the internal
  // transmission interpolated from the IT table is above 0 (true when there is no IT data or the
  // wavelength is outside the table).
  bool transmits(double wavelength_nm) const;
};

// A glass catalog: the glasses of one AGF file (or the project's built-in catalog).
struct Catalog {
  std::string name;  // catalog name: the file's stem less a date suffix ("OHARA" for
                     // OHARA_20200623.AGF, see catalog_family_name)
  std::string path;  // where it was read from
  std::vector<Glass> glasses;
  std::vector<std::string> warnings;  // e.g. unsupported formulas, with file:line

  // The glass of that name (case-insensitive), or nullptr.
  const Glass* find(std::string_view glass_name) const;

  // The glass of that name; throws Error "unknown glass 'X' in catalog C; closest: A, B, C".
  const Glass& at(std::string_view glass_name) const;

  // Up to `count` names closest to `glass_name` (edit distance, case-insensitive), best first.
  std::vector<std::string> closest_names(std::string_view glass_name, std::size_t count = 3) const;

  // Up to `count` glasses nearest to (nd, vd) on the glass map, best first, by the distance
  //   sqrt((100 (nd - nd_g))^2 + (vd - vd_g)^2)
  // (0.01 in nd weighs as much as 1 in vd); only glasses whose formula lensopt evaluates.
  std::vector<const Glass*> closest_by_index(double nd, double vd, std::size_t count = 3) const;
};

// The catalog name of an AGF file's stem: the vendor family without the date suffix that vendor
// files carry ("SCHOTT_202002" -> "SCHOTT", "OHARA_20200623" -> "OHARA"); other stems as they are.
std::string catalog_family_name(std::string_view stem);

// The vendor catalogs that ship in catalogs/ (complete, from the vendors' AGF files by
// tools/make-catalogs.py), in the order a search without a catalog name tries them.
const std::vector<std::string>& shipped_catalog_names();

// The catalogs lensopt makes from the refractiveindex.info database (catalogs/, from
// tools/make-rii-catalogs.py): HIKARI, SUMITA, LZOS, LIGHTPATH, CORNING, INFRARED, MISC.
const std::vector<std::string>& database_catalog_names();

// Every catalog that ships in catalogs/: the vendors' then the database's.
std::vector<std::string> all_shipped_catalog_names();

// The shipped catalog a Zemax GCAT name stands for, as OpticStudio users expect: NIKON-HIKARI
// and NIKON are HIKARI; a dated or versioned name (SUMITA_AUG2011, SCHOTT_2017) is its family
// (the stem before the last '_' when what follows holds a digit); other names as they are.
std::string zemax_catalog_alias(std::string_view name);

// Parses AGF text. `bytes` may be ASCII/UTF-8 or UTF-16 LE with a BOM, CRLF or LF line ends.
// Throws Error with file:line for malformed lines.
Catalog parse_agf(std::string_view bytes, const std::string& source_name);

// Reads an AGF file (parse_agf on its contents; the catalog is named after the file's stem).
Catalog read_agf(const std::filesystem::path& path);

// Loads a catalog by path (any existing file) or by name:
//  - "ohara" (exactly, lower case): the paper's 65 recommended Ohara glasses
//  (catalogs/ohara65.agf);
//  - any other name X: X.agf in the catalog search path (the LENSOPT_CATALOG_PATH environment
//    variable, colon-separated, then the project's catalogs/), the stem compared
//    case-insensitively; failing that, a vendor file of that family, X_<date>.agf (the newest
//    date). So "SCHOTT", "OHARA", "HOYA" and "CDGM" are the vendors' complete catalogs that ship in
//    catalogs/, unless a folder of LENSOPT_CATALOG_PATH holds the vendor's own file;
//  - failing both, the shipped catalog zemax_catalog_alias names ("NIKON-HIKARI" is HIKARI).
// Results are cached per resolved path. Throws Error naming what was searched.
std::shared_ptr<const Catalog> load_catalog(std::string_view name_or_path);

// The folders searched for catalogs by name, in order.
std::vector<std::filesystem::path> catalog_search_path();

}  // namespace lensopt
