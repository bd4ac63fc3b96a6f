// Internal: the .zmx reader (formats/zmx.h). ZmxParser reads the file's lines into raw surfaces
// and system settings (zmx_lines.cpp), resolves glasses against the GCAT catalogs
// (zmx_glasses.cpp) and builds the lens in named steps (zmx_read.cpp).
#pragma once

#include <fmt/format.h>

#include <charconv>
#include <cmath>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "lensopt/core/error.h"
#include "lensopt/formats/zmx.h"
#include "lensopt/glass/glass.h"
#include "lensopt/lens/input_limits.h"
#include "lensopt/lens/validate.h"
#include "zmx_text.h"

namespace lensopt::zmx_detail {

// Relative agreement a lensopt note must have with the Zemax value it refines.
inline constexpr double kNoteTolerance = 1e-9;
// Line numbers listed per ignored keyword before "and N more".
inline constexpr std::size_t kListedLines = 6;

// A surface as the file gives it, before it becomes a lensopt Surface.
struct RawSurface {
  int number = 0;
  int line = 0;  // the SURF line
  double curvature_per_mm = 0.0;
  int curv_line = 0;
  double thickness_mm = 0.0;
  bool thickness_infinite = false;
  int disz_line = 0;
  std::string glass;  // "" = air
  bool model_glass = false;
  double model_nd = 0.0;
  double model_vd = 0.0;
  double model_dpgf = 0.0;  // GLAS ... nd vd dPgF of a model glass
  int glas_line = 0;
  int glas_column = 0;
  bool is_stop = false;
  int stop_line = 0;
  double semi_diameter_mm = 0.0;  // a fixed (user) DIAM: a clear aperture
  bool even_asphere = false;      // TYPE EVENASPH
  double conic = 0.0;             // CONI
  double parm[9] = {};            // PARM 1..8 of EVENASPH: a2, a4, ..., a16 (lens units)
  // TYPE COORDBRK: PARM 1..6 = decenter x, y (lens units), tilt x, y, z (deg), order.
  bool coordinate_break = false;
  int type_line = 0;
  bool mirror = false;  // GLAS MIRROR
  // CLAP rmin rmax (circular aperture), OBSC rmin rmax (circular obscuration), OBDC x y
  // (their decenter), lens units.
  double clap_min = 0.0, clap_max = 0.0;
  int clap_line = 0;
  double obsc_min = 0.0, obsc_max = 0.0;
  int obsc_line = 0;
  double obdc_x = 0.0, obdc_y = 0.0;
  // SCBD: a surface's own tilt/decenter (read on the image surface).
  int scbd_line = 0;
  double scbd[8] = {};
  // Solves and variables (lens.h): a curvature variable flag (CURV c 1 ...), a curvature pickup
  // (CURV c 4 source scale column), a thickness pickup (PZUP source scale offset column) and a
  // marginal-ray-height solve (MAZH height zone). Sources are .zmx surface numbers.
  bool curvature_variable = false;
  int curvature_pickup_source = -1;
  double curvature_pickup_scale = 1.0;
  int thickness_pickup_source = -1, pzup_line = 0;
  double thickness_pickup_scale = 1.0, thickness_pickup_offset = 0.0;
  bool marginal_height_solve = false;
  double marginal_height = 0.0;
  int mazh_line = 0;
  VaryFlags note_vary;  // NOTE 0 lensopt vary <surface> ... (what Zemax has no flag for here)
};

struct Wavelength {
  double um = 0.0;
  double nm = 0.0;  // the file's decimal read in nm (micrometres_to_nm)
  double weight = 1.0;
  int line = 0;
};

// A catalog the file's GCAT (or lensopt note) names, as loaded.
struct CatalogEntry {
  std::string requested;  // as the file names it
  std::string load_name;  // the name load_catalog finds it by ("" if not found)
  std::shared_ptr<const Catalog> catalog;
  std::string failure;  // why it was not found
};

class ZmxParser {
 public:
  explicit ZmxParser(std::string file) : file_(std::move(file)) {}

  ZmxImport parse(std::string_view bytes);

 private:
  [[noreturn]] void fail(const Line& line, std::size_t field, const std::string& message) const {
    const int column = field < line.columns.size() ? line.columns[field] : 1;
    throw Error(SourceLocation{file_, line.number, column}, message);
  }
  [[noreturn]] void fail_at(int line, int column, const std::string& message) const {
    throw Error(SourceLocation{file_, line, column}, message);
  }
  void warn(int line, const std::string& message) {
    warnings_.push_back(line > 0 ? fmt::format("{}:{}: {}", file_, line, message)
                                 : fmt::format("{}: {}", file_, message));
  }
  void ignore(const Line& line) { ignored_[upper(line.fields[0])].push_back(line.number); }

  double number(const Line& line, std::size_t field, std::string_view what) const {
    if (field >= line.fields.size())
      fail(line, line.fields.size() - 1,
           fmt::format("{} is missing: '{}' needs a number there", what, line.text));
    std::string_view text = line.fields[field];
    if (!text.empty() && text.front() == '+') text.remove_prefix(1);
    double value = 0.0;
    const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
    if (ec != std::errc() || end != text.data() + text.size() || !std::isfinite(value))
      fail(line, field,
           fmt::format("{} must be a finite number, not '{}'", what, line.fields[field]));
    return value;
  }

  int integer(const Line& line, std::size_t field, std::string_view what) const {
    const double value = number(line, field, what);
    if (value != std::floor(value) || std::abs(value) > 1e6)
      fail(line, field, fmt::format("{} must be an integer, not '{}'", what, line.fields[field]));
    return static_cast<int>(value);
  }

  // A per-field line (XFLN, FWGN, VDXN, ...) of more than kMaxFields values.
  void check_field_count(const Line& line) const {
    if (line.fields.size() > kMaxFields + 1)
      fail(line, kMaxFields + 1,
           fmt::format("{} has {} fields; lensopt reads at most {}", line.fields[0],
                       line.fields.size() - 1, kMaxFields));
  }

  RawSurface& surface(const Line& line) {
    if (surfaces_.empty())
      fail(line, 0, fmt::format("'{}' comes before the first SURF line", line.fields[0]));
    return surfaces_.back();
  }

  // parse()'s steps, in order.
  void read_lines(const std::vector<Line>& lines);
  void check_object_and_image() const;
  LensSourceLines build_surfaces(Lens& lens);
  void set_solves(Lens& lens, const std::vector<int>& lens_index);
  void set_wavelengths(Specs& specs);
  void set_fields(Specs& specs);
  void set_aperture(Lens& lens);
  // The summary specs the paper's machinery uses, from the paraxial system.
  void set_summary_specs(Lens& lens);
  void apply_lensopt_notes(Lens& lens) const;
  void validate(const Lens& lens, const LensSourceLines& source_lines) const;

  bool surface_line(const Line& line, const std::string& key);
  void system_line(const Line& line, const std::string& key);
  void note_line(const Line& line);
  std::vector<CatalogEntry> load_catalogs();
  Material resolve_glass(const RawSurface& raw, std::vector<CatalogEntry>& catalogs,
                         std::vector<std::string>& used_catalogs, DispersionModel dispersion);
  void report_ignored();

  std::string file_;
  int last_line_ = 1;  // the file's last line number, where "missing" errors point
  std::vector<std::string> warnings_;
  std::map<std::string, std::vector<int>> ignored_;

  std::string name_;
  bool has_name_ = false;
  bool breaks_symmetry_ = false;  // a COORDBRK, SCBD or aperture decenter (set_fields)
  double unit_mm_ = 1.0;
  std::optional<double> enpd_;
  std::optional<double> fnum_;
  std::optional<double> obna_;
  bool floa_ = false;
  int aperture_line_ = 0;
  int field_type_ = 0;
  std::vector<double> field_weights_;
  int fwgn_line_ = 0;
  std::map<std::string, std::vector<double>> vignetting_;
  std::map<int, Wavelength> wavm_;
  std::vector<Wavelength> wavl_;
  int wavelength_line_ = 0;
  bool has_ftyp_ = false;
  int ftyp_line_ = 0;
  bool ftyp_afocal_ = false;  // FTYP's seventh value: OpticStudio's "Afocal Image Space"
  int field_count_ = -1;
  int wavelength_count_ = -1;
  std::vector<double> xfln_;
  std::vector<double> yfln_;
  int yfln_line_ = 0;
  std::vector<std::pair<std::string, int>> gcat_;  // name, line
  int pwav_ = 0;
  int pwav_line_ = 0;
  std::vector<RawSurface> surfaces_;

  // lensopt notes.
  struct VaryNote {
    int surface;  // .zmx surface number
    VaryFlags flags;
    int line;
  };
  std::vector<VaryNote> note_vary_;  // NOTE 0 lensopt vary
  std::optional<std::string> note_catalog_;
  std::optional<double> note_sensor_mm_;
  std::optional<DispersionModel> note_dispersion_;
  std::optional<std::vector<int>> note_channels_;
  std::optional<std::vector<double>> note_wavelengths_nm_;
  std::optional<double> note_primary_nm_;
  bool note_mode_paper_ = false;
  bool note_model_glass_paper_ = false;  // "lensopt model_glass paper": ___BLANK is the paper's
  std::string note_toml_;
  int note_line_ = 0;
};

}  // namespace lensopt::zmx_detail
