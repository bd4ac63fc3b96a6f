// Zemax .zmx import and export (include/lensopt/formats/zmx.h states the mapping).
//
// Exact numbers. Curvatures, thicknesses, semi-diameters, the F/# and the field are written with
// fmt "{}", the shortest decimal that reads back to the same double, and read with from_chars
// (correctly rounded). Wavelengths go in micrometres as the nm decimal with its point moved three
// places ("584.1" nm -> "0.5841"), and are read back by moving it again, so they are exact too.
#include "lensopt/formats/zmx.h"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <charconv>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <set>

#include "lensopt/analysis/apertures.h"
#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/core/text.h"
#include "lensopt/glass/dispersion.h"
#include "lensopt/glass/glass.h"
#include "lensopt/lens/validate.h"
#include "lensopt/paraxial/paraxial.h"
#include "lensopt/trace/system.h"
#include "lensopt/trace/trace_lens.h"

namespace lensopt {
namespace {

constexpr std::array<char, 3> kChannelLetters = {'R', 'G', 'B'};
// Relative agreement a lensopt note must have with the Zemax value it refines.
constexpr double kNoteTolerance = 1e-9;
// Line numbers listed per ignored keyword before "and N more".
constexpr std::size_t kListedLines = 6;

std::string upper(std::string_view text) {
  std::string out(text);
  for (char& ch : out) ch = static_cast<char>(std::toupper(static_cast<unsigned char>(ch)));
  return out;
}

// A decimal field, or nothing when it is not one.
std::optional<double> parse_double(std::string_view text) {
  double value = 0.0;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (ec != std::errc() || end != text.data() + text.size() || !std::isfinite(value))
    return std::nullopt;
  return value;
}

bool is_blank(char ch) {
  return ch == ' ' || ch == '\t' || ch == '\r' || ch == '\f' || ch == '\v';
}

// One line of the file: its blank-separated fields and their 1-based columns.
struct Line {
  int number = 0;
  std::string_view text;  // the whole line, without its line end
  std::vector<std::string_view> fields;
  std::vector<int> columns;

  // The text from field i to the end of the line ("" past the last field).
  std::string_view rest(std::size_t i) const {
    if (i >= fields.size()) return {};
    std::string_view out = text.substr(static_cast<std::size_t>(columns[i] - 1));
    while (!out.empty() && is_blank(out.back())) out.remove_suffix(1);
    return out;
  }
};

std::vector<Line> split_lines(std::string_view text) {
  std::vector<Line> lines;
  int number = 0;
  std::size_t start = 0;
  while (start <= text.size()) {
    std::size_t end = text.find('\n', start);
    if (end == std::string_view::npos) end = text.size();
    ++number;
    std::string_view raw = text.substr(start, end - start);
    if (!raw.empty() && raw.back() == '\r') raw.remove_suffix(1);
    Line line;
    line.number = number;
    line.text = raw;
    std::size_t i = 0;
    while (i < raw.size()) {
      while (i < raw.size() && is_blank(raw[i])) ++i;
      const std::size_t field_start = i;
      while (i < raw.size() && !is_blank(raw[i])) ++i;
      if (i > field_start) {
        line.fields.push_back(raw.substr(field_start, i - field_start));
        line.columns.push_back(static_cast<int>(field_start) + 1);
      }
    }
    lines.push_back(std::move(line));
    if (end == text.size()) break;
    start = end + 1;
  }
  return lines;
}

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
  int glas_line = 0;
  int glas_column = 0;
  bool is_stop = false;
  int stop_line = 0;
  double semi_diameter_mm = 0.0;  // a fixed (user) DIAM: a clear aperture
  bool even_asphere = false;  // TYPE EVENASPH
  double conic = 0.0;         // CONI
  double parm[9] = {};        // PARM 1..8 of EVENASPH: a2, a4, ..., a16 (lens units)
};

struct Wavelength {
  double um = 0.0;
  double nm = 0.0;  // the file's decimal read in nm (micrometres_to_nm)
  double weight = 1.0;
  int line = 0;
};

// A wavelength written in micrometres, in nm: the decimal with its point moved three places right
// ("0.5875618" -> 587.5618), read correctly rounded, so the nm value is the double nearest the
// file's decimal (fl(um * 1000) can be an ulp off); exponent forms use um * 1000.
double micrometres_to_nm(std::string_view text, double um) {
  if (!text.empty() && text.front() == '+') text.remove_prefix(1);
  if (text.empty() || text.find_first_not_of("0123456789.") != std::string_view::npos)
    return um * 1000.0;
  const std::size_t point = text.find('.');
  std::string integer(text.substr(0, point));
  std::string fraction = point == std::string_view::npos ? "" : std::string(text.substr(point + 1));
  while (fraction.size() < 3) fraction += '0';
  const std::string shifted = integer + fraction.substr(0, 3) + "." + fraction.substr(3) + "0";
  double nm = 0.0;
  const auto [end, ec] = std::from_chars(shifted.data(), shifted.data() + shifted.size(), nm);
  return ec == std::errc() ? nm : um * 1000.0;
}

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

  RawSurface& surface(const Line& line) {
    if (surfaces_.empty())
      fail(line, 0, fmt::format("'{}' comes before the first SURF line", line.fields[0]));
    return surfaces_.back();
  }

  bool surface_line(const Line& line, const std::string& key);
  void system_line(const Line& line, const std::string& key);
  void note_line(const Line& line);
  std::vector<CatalogEntry> load_catalogs();
  Material resolve_glass(const RawSurface& raw, std::vector<CatalogEntry>& catalogs,
                         std::vector<std::string>& used_catalogs, DispersionModel dispersion);
  void report_ignored();

  std::string file_;
  std::vector<std::string> warnings_;
  std::map<std::string, std::vector<int>> ignored_;

  std::string name_;
  bool has_name_ = false;
  double unit_mm_ = 1.0;
  std::optional<double> enpd_;
  std::optional<double> fnum_;
  std::optional<double> obna_;
  bool floa_ = false;
  int aperture_line_ = 0;
  int field_type_ = 0;
  std::vector<double> field_weights_;
  std::map<std::string, std::vector<double>> vignetting_;
  int vdxn_line_ = 0;
  std::map<int, Wavelength> wavm_;
  std::vector<Wavelength> wavl_;
  int wavelength_line_ = 0;
  bool has_ftyp_ = false;
  int ftyp_line_ = 0;
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
  std::optional<std::string> note_catalog_;
  std::optional<double> note_sensor_mm_;
  std::optional<DispersionModel> note_dispersion_;
  std::optional<std::vector<int>> note_channels_;
  std::optional<std::vector<double>> note_wavelengths_nm_;
  std::optional<double> note_primary_nm_;
  bool note_mode_paper_ = false;
  std::string note_toml_;
  int note_line_ = 0;
};

// Keywords of OpticStudio's system and surface settings that do not change a sequential spherical
// prescription at infinity as lensopt models it (display, analysis and environment defaults,
// tolerances, coatings, drawing). They are reported together, by keyword and line.
bool is_setting_keyword(const std::string& key) {
  static const std::set<std::string> kSettings = {
      "PFIL", "LANG", "GFAC", "RAIM", "PUSH", "SDMA", "ROPD", "PICB", "POLS", "GLRS",
      "GSTD", "NSCD", "COFN", "SUMM", "DMFS", "BLNK", "RWRE", "TOL",  "MNUM", "MOFF",
      "OPDX", "SCOL", "SQFN", "VANN", "HIDE", "MIRR", "SLAB", "POPS", "FLAP", "MEMA",
      "COAT", "TCE",  "ENVD", "EFFL", "ZVDX", "ZVDY", "ZVCX", "ZVCY", "ZVAN", "WAVN",
      "XFLD", "YFLD", "FIMP", "BLAN", "CONF", "DESC"};
  return kSettings.count(key) > 0;
}

bool ZmxParser::surface_line(const Line& line, const std::string& key) {
  if (key == "TYPE") {
    RawSurface& s = surface(line);
    const std::string type = line.fields.size() > 1 ? upper(line.fields[1]) : "";
    if (type != "STANDARD" && type != "EVENASPH")
      fail(line, 1,
           fmt::format("surface {} has type {}, which lensopt does not support; it imports "
                       "STANDARD (sphere or conic) and EVENASPH surfaces only",
                       s.number, type.empty() ? std::string("(none)") : type));
    s.even_asphere = type == "EVENASPH";
    return true;
  }
  if (key == "CURV") {
    RawSurface& s = surface(line);
    s.curvature_per_mm = number(line, 1, "CURV (curvature, 1/lens unit)");
    s.curv_line = line.number;
    return true;
  }
  if (key == "DISZ") {
    RawSurface& s = surface(line);
    s.disz_line = line.number;
    const std::string value = line.fields.size() > 1 ? upper(line.fields[1]) : "";
    if (value == "INFINITY" || value == "INF" || value == "1.#INF") {
      s.thickness_infinite = true;
    } else {
      s.thickness_mm = number(line, 1, "DISZ (thickness)");
      if (std::abs(s.thickness_mm) >= 1e10) s.thickness_infinite = true;
    }
    return true;
  }
  if (key == "GLAS") {
    RawSurface& s = surface(line);
    if (line.fields.size() < 2) fail(line, 0, "GLAS without a glass name");
    const std::string name(line.fields[1]);
    s.glas_line = line.number;
    s.glas_column = line.columns[1];
    if (upper(name) == "MIRROR")
      fail(line, 1,
           fmt::format("surface {} is a mirror; lensopt models refracting lenses only", s.number));
    if (name == "___BLANK") {
      s.model_glass = true;
      s.model_nd = number(line, 4, "the model glass's nd (GLAS ___BLANK 1 0 nd vd)");
      s.model_vd = number(line, 5, "the model glass's vd (GLAS ___BLANK 1 0 nd vd)");
      if (!(s.model_nd > 1.0))
        fail(line, 4, fmt::format("model glass nd = {} must be > 1", s.model_nd));
      if (!(s.model_vd > 0.0))
        fail(line, 5, fmt::format("model glass vd = {} must be > 0", s.model_vd));
      s.glass = name;
    } else if (upper(name) != "AIR") {
      s.glass = name;
      // "GLAS name 0 0 nd vd ...": the index data OpticStudio saved with a catalog glass, used
      // only to suggest the nearest glasses when the name is in none of the catalogs.
      if (line.fields.size() > 5) {
        const auto nd = parse_double(line.fields[4]);
        const auto vd = parse_double(line.fields[5]);
        if (nd && vd && *nd > 1.0 && *vd > 0.0) {
          s.model_nd = *nd;
          s.model_vd = *vd;
        }
      }
    }
    return true;
  }
  if (key == "STOP") {
    RawSurface& s = surface(line);
    s.is_stop = true;
    s.stop_line = line.number;
    return true;
  }
  if (key == "DIAM") {
    // "DIAM r flag": flag 1 is a fixed (user) semi-diameter, a clear aperture that clips rays;
    // otherwise OpticStudio computed it from the beam (automatic) and lensopt computes its own.
    RawSurface& s = surface(line);
    const double r = std::abs(number(line, 1, "DIAM (semi-diameter)"));
    if (line.fields.size() > 2 && line.fields[2] == "1") s.semi_diameter_mm = r;
    return true;
  }
  if (key == "CONI") {
    RawSurface& s = surface(line);
    s.conic = number(line, 1, "CONI (conic constant)");
    if (!std::isfinite(s.conic)) fail(line, 1, "CONI must be finite");
    return true;
  }
  if (key == "COMM") {
    surface(line);  // a surface comment: nothing to keep
    return true;
  }
  if (key == "PARM" && surface(line).even_asphere) {
    // EVENASPH: PARM i a_{2i}, i = 1..8 (PARM 1 is the r^2 term).
    RawSurface& s = surface(line);
    const int index = integer(line, 1, "the PARM number");
    const double value = number(line, 2, "the PARM value");
    if (index >= 1 && index <= 8) {
      if (!std::isfinite(value)) fail(line, 2, "PARM must be finite");
      s.parm[index] = value;
    } else if (value != 0.0) {
      fail(line, 1,
           fmt::format("surface {}: EVENASPH has PARM 1..8 (r^2 .. r^16); PARM {} = {} is not "
                       "supported",
                       s.number, index, line.fields[2]));
    } else {
      ignore(line);
    }
    return true;
  }
  if (key == "PARM" || key == "XDAT") {
    RawSurface& s = surface(line);
    bool all_zero = true;
    for (std::size_t i = 2; i < line.fields.size(); ++i) {
      double value = 0.0;
      const auto [end, ec] = std::from_chars(line.fields[i].data(),
                                             line.fields[i].data() + line.fields[i].size(), value);
      if (ec != std::errc() || value != 0.0) all_zero = false;
    }
    if (all_zero) {
      ignore(line);
    } else {
      warn(line.number, fmt::format("surface {}: '{}' ignored (a STANDARD surface has no "
                                    "parameters)",
                                    s.number, line.text));
    }
    return true;
  }
  if (key == "CLAP" || key == "SQAP" || key == "ELAP" || key == "OBSC" || key == "OBSQ" ||
      key == "OBEL" || key == "OBDC" || key == "UDAD" || key == "FLOP") {
    RawSurface& s = surface(line);
    warn(line.number, fmt::format("surface {}: the surface aperture '{}' is ignored (lensopt "
                                  "limits rays by the stop only)",
                                  s.number, line.text));
    return true;
  }
  return false;
}

void ZmxParser::note_line(const Line& line) {
  // "NOTE n lensopt key value..." carries lensopt data; any other NOTE is a comment.
  if (line.fields.size() < 3) return;
  if (line.fields[2] == "lensopt-toml") {
    std::string_view rest = line.rest(3);
    note_toml_ += std::string(rest) + "\n";
    note_line_ = note_line_ == 0 ? line.number : note_line_;
    return;
  }
  if (line.fields[2] != "lensopt" || line.fields.size() < 5) return;
  note_line_ = note_line_ == 0 ? line.number : note_line_;
  const std::string_view key = line.fields[3];
  if (key == "catalog") {
    note_catalog_ = std::string(line.rest(4));
  } else if (key == "sensor_diagonal_mm") {
    note_sensor_mm_ = number(line, 4, "sensor_diagonal_mm");
  } else if (key == "dispersion") {
    if (line.fields[4] == "abbe") note_dispersion_ = DispersionModel::kAbbe;
    if (line.fields[4] == "catalog") note_dispersion_ = DispersionModel::kCatalog;
  } else if (key == "channels") {
    std::vector<int> channels;
    for (const char ch : line.fields[4]) {
      const auto it = std::find(kChannelLetters.begin(), kChannelLetters.end(), ch);
      if (it == kChannelLetters.end()) return;
      channels.push_back(static_cast<int>(it - kChannelLetters.begin()));
    }
    note_channels_ = channels;
  } else if (key == "primary_wavelength_nm") {
    note_primary_nm_ = number(line, 4, "primary_wavelength_nm");
  } else if (key == "mode") {
    note_mode_paper_ = line.fields[4] == "paper";
  } else if (key == "wavelengths_nm") {
    std::vector<double> values;
    for (std::size_t i = 4; i < line.fields.size(); ++i)
      values.push_back(number(line, i, "a wavelength (nm)"));
    note_wavelengths_nm_ = values;
  } else {
    warn(line.number, fmt::format("unknown lensopt note '{}' ignored", key));
  }
}

void ZmxParser::system_line(const Line& line, const std::string& key) {
  if (key == "MODE") {
    const std::string mode = line.fields.size() > 1 ? upper(line.fields[1]) : "";
    if (mode != "SEQ")
      fail(line, 1,
           fmt::format("MODE {}: lensopt imports sequential systems only (MODE SEQ)", mode));
  } else if (key == "NAME") {
    name_ = std::string(line.rest(1));
    has_name_ = true;
  } else if (key == "NOTE") {
    note_line(line);
  } else if (key == "UNIT") {
    const std::string unit = line.fields.size() > 1 ? upper(line.fields[1]) : "";
    if (unit == "MM") {
      unit_mm_ = 1.0;
    } else if (unit == "CM") {
      unit_mm_ = 10.0;
    } else if (unit == "IN") {
      unit_mm_ = 25.4;
    } else if (unit == "METER" || unit == "M") {
      unit_mm_ = 1000.0;
    } else {
      fail(line, 1, fmt::format("lens unit '{}' is not MM, CM, IN or METER", unit));
    }
    if (unit != "MM")
      warn(line.number,
           fmt::format("lens units are {}; lengths converted to mm (x {})", unit, unit_mm_));
  } else if (key == "ENPD") {
    enpd_ = number(line, 1, "ENPD (entrance pupil diameter)");
    if (!(*enpd_ > 0.0)) fail(line, 1, "ENPD must be > 0");
    aperture_line_ = line.number;
  } else if (key == "FNUM") {
    fnum_ = number(line, 1, "FNUM (image-space F/#)");
    if (!(*fnum_ > 0.0)) fail(line, 1, "FNUM must be > 0");
    aperture_line_ = line.number;
    if (line.fields.size() > 2 && line.fields[2] != "0")
      warn(line.number, "FNUM with a non-zero flag: taken as the image-space F/# (EFL / EPD)");
  } else if (key == "OBNA") {
    obna_ = number(line, 1, "OBNA (object-space NA)");
    if (!(*obna_ > 0.0 && *obna_ < 1.0)) fail(line, 1, "OBNA must be in (0, 1)");
    aperture_line_ = line.number;
  } else if (key == "FLOA") {
    floa_ = true;
    aperture_line_ = line.number;
  } else if (key == "OBSA" || key == "PWFN" || key == "FNUO") {
    fail(line, 0,
         fmt::format("aperture type {} is not supported; lensopt takes the entrance pupil "
                     "diameter (ENPD), the image-space F/# (FNUM), the object-space NA (OBNA) "
                     "or float by stop size (FLOA)",
                     key));
  } else if (key == "WAVM") {
    const int index = integer(line, 1, "the wavelength number");
    Wavelength w;
    w.um = number(line, 2, "the wavelength (um)");
    w.nm = micrometres_to_nm(line.fields[2], w.um);
    if (line.fields.size() > 3) w.weight = number(line, 3, "the wavelength weight");
    w.line = line.number;
    wavm_[index] = w;
    if (wavelength_line_ == 0) wavelength_line_ = line.number;
  } else if (key == "WAVL") {
    for (std::size_t i = 1; i < line.fields.size(); ++i) {
      const double um = number(line, i, "a wavelength (um)");
      wavl_.push_back({um, micrometres_to_nm(line.fields[i], um), 1.0, line.number});
    }
    if (wavelength_line_ == 0) wavelength_line_ = line.number;
  } else if (key == "FTYP") {
    has_ftyp_ = true;
    ftyp_line_ = line.number;
    const int type = integer(line, 1, "the field type");
    if (type < 0 || type > 3)
      fail(line, 1,
           fmt::format("field type {} is not supported; lensopt takes angle (0), object height "
                       "(1), paraxial image height (2) and real image height (3)",
                       type));
    field_type_ = type;
    if (line.fields.size() > 3) field_count_ = integer(line, 3, "the number of fields");
    if (line.fields.size() > 4) wavelength_count_ = integer(line, 4, "the number of wavelengths");
  } else if (key == "VDXN" || key == "VDYN" || key == "VCXN" || key == "VCYN") {
    std::vector<double>& values = vignetting_[key];
    values.clear();
    for (std::size_t i = 1; i < line.fields.size(); ++i)
      values.push_back(number(line, i, "a vignetting factor"));
    if (key == "VDXN") vdxn_line_ = line.number;
  } else if (key == "FWGN") {
    field_weights_.clear();
    for (std::size_t i = 1; i < line.fields.size(); ++i)
      field_weights_.push_back(number(line, i, "a field weight"));
  } else if (key == "XFLN" || key == "YFLN") {
    std::vector<double>& values = key == "XFLN" ? xfln_ : yfln_;
    values.clear();
    for (std::size_t i = 1; i < line.fields.size(); ++i)
      values.push_back(number(line, i, "a field value"));
    if (key == "YFLN") yfln_line_ = line.number;
  } else if (key == "VERS") {
    // The version stamp of the program that wrote the file: nothing to keep.
  } else if (key == "PWAV") {
    pwav_ = integer(line, 1, "the primary wavelength number");
    pwav_line_ = line.number;
  } else if (key == "FWGT" || key == "WWGT") {
    // Old-style weight lines (FWGN and WAVM carry the weights OpticStudio uses).
    ignore(line);
  } else if (key == "GCAT") {
    for (std::size_t i = 1; i < line.fields.size(); ++i)
      gcat_.emplace_back(std::string(line.fields[i]), line.number);
  } else if (is_setting_keyword(key) || key.rfind("TOL", 0) == 0) {
    ignore(line);
  } else {
    warn(line.number, fmt::format("unknown line '{}' ignored", line.text));
  }
}

std::vector<CatalogEntry> ZmxParser::load_catalogs() {
  std::vector<CatalogEntry> out;
  std::set<std::string> paths;
  auto add = [&](CatalogEntry entry) {
    if (entry.catalog && !paths.insert(entry.catalog->path).second) return;
    out.push_back(std::move(entry));
  };
  auto try_load = [&](const std::string& requested, const std::string& name) -> bool {
    try {
      add({requested, name, load_catalog(name), ""});
      return true;
    } catch (const Error& error) {
      return false;
    }
  };
  std::vector<std::string> names;
  if (note_catalog_) names.push_back(*note_catalog_);
  for (const auto& [name, line] : gcat_) names.push_back(name);
  for (const std::string& name : names) {
    bool found = try_load(name, name);
    // OpticStudio names catalogs by family ("SCHOTT"); vendor files are often dated
    // ("SCHOTT_202002.AGF"): take those in the search path as well.
    for (const auto& folder : catalog_search_path()) {
      std::error_code ec;
      std::filesystem::directory_iterator it(folder, ec);
      if (ec) continue;
      std::vector<std::filesystem::path> matches;
      for (const auto& entry : it) {
        const std::string stem = upper(entry.path().stem().string());
        if (upper(entry.path().extension().string()) != ".AGF") continue;
        const std::string wanted = upper(name);
        if (stem == wanted || stem.rfind(wanted + "_", 0) == 0) matches.push_back(entry.path());
      }
      std::sort(matches.begin(), matches.end());
      for (const auto& path : matches) found = try_load(name, path.stem().string()) || found;
    }
    if (!found) {
      std::vector<std::string> folders;
      for (const auto& folder : catalog_search_path()) folders.push_back(folder.string());
      add({name, "", nullptr,
           fmt::format("not found in {}", folders.empty()
                                              ? "(no folders)"
                                              : fmt::format("{}", fmt::join(folders, ", ")))});
    }
  }
  return out;
}

Material ZmxParser::resolve_glass(const RawSurface& raw, std::vector<CatalogEntry>& catalogs,
                                  std::vector<std::string>& used_catalogs,
                                  DispersionModel dispersion) {
  if (raw.glass.empty()) return Material::air();
  if (raw.model_glass) return Material::model(raw.model_nd, raw.model_vd);
  for (const CatalogEntry& entry : catalogs) {
    if (!entry.catalog) continue;
    const Glass* glass = entry.catalog->find(raw.glass);
    if (glass == nullptr) continue;
    if (dispersion == DispersionModel::kCatalog && !glass->formula_supported)
      fail_at(raw.glas_line, raw.glas_column,
              fmt::format("glass '{}' (catalog {}) uses dispersion formula {}, which lensopt "
                          "cannot evaluate",
                          glass->name, entry.catalog->name, formula_name(glass->formula)));
    if (std::find(used_catalogs.begin(), used_catalogs.end(), entry.load_name) ==
        used_catalogs.end())
      used_catalogs.push_back(entry.load_name);
    return Material::from_catalog(*glass);
  }
  std::vector<std::string> searched;
  // Nearest glasses over all catalogs searched: by name (edit distance) and, when the GLAS line
  // carries the glass's nd and vd, on the glass map.
  std::vector<std::pair<std::size_t, std::string>> by_name;  // (rank in its catalog, name)
  std::vector<std::pair<double, std::string>> by_index;      // (map distance, "NAME (nd, vd)")
  for (const CatalogEntry& entry : catalogs) {
    if (entry.catalog) {
      searched.push_back(fmt::format("{} ({})", entry.requested, entry.catalog->path));
      const auto names = entry.catalog->closest_names(raw.glass, 3);
      for (std::size_t k = 0; k < names.size(); ++k) by_name.emplace_back(k, names[k]);
      if (raw.model_nd > 0.0)
        for (const Glass* g : entry.catalog->closest_by_index(raw.model_nd, raw.model_vd, 3)) {
          const double dn = 100.0 * (g->nd - raw.model_nd);
          const double dv = g->vd - raw.model_vd;
          by_index.emplace_back(
              std::sqrt(dn * dn + dv * dv),
              fmt::format("{} {} ({}, {})", entry.catalog->name, g->name, g->nd, g->vd));
        }
    } else {
      searched.push_back(fmt::format("{} ({})", entry.requested, entry.failure));
    }
  }
  std::stable_sort(by_name.begin(), by_name.end(),
                   [](const auto& a, const auto& b) { return a.first < b.first; });
  std::stable_sort(by_index.begin(), by_index.end(),
                   [](const auto& a, const auto& b) { return a.first < b.first; });
  std::vector<std::string> closest;
  for (std::size_t k = 0; k < by_name.size() && k < 3; ++k) closest.push_back(by_name[k].second);
  std::vector<std::string> nearest;
  for (std::size_t k = 0; k < by_index.size() && k < 3; ++k) nearest.push_back(by_index[k].second);
  fail_at(
      raw.glas_line, raw.glas_column,
      fmt::format("surface {}: unknown glass '{}': not in the catalogs searched: {}{}{}",
                  raw.number, raw.glass,
                  searched.empty() ? std::string("none (the file has no GCAT line)")
                                   : fmt::format("{}", fmt::join(searched, "; ")),
                  closest.empty() ? std::string()
                                  : fmt::format("; closest by name: {}", fmt::join(closest, ", ")),
                  nearest.empty() ? std::string()
                                  : fmt::format("; nearest to nd = {}, vd = {}: {}", raw.model_nd,
                                                raw.model_vd, fmt::join(nearest, ", "))));
}

void ZmxParser::report_ignored() {
  if (ignored_.empty()) return;
  std::vector<std::string> parts;
  for (const auto& [key, lines] : ignored_) {
    std::vector<std::string> numbers;
    for (std::size_t i = 0; i < lines.size() && i < kListedLines; ++i)
      numbers.push_back(std::to_string(lines[i]));
    std::string part =
        fmt::format("{} (line{} {}", key, lines.size() > 1 ? "s" : "", fmt::join(numbers, ", "));
    if (lines.size() > kListedLines)
      part += fmt::format(" and {} more", lines.size() - kListedLines);
    parts.push_back(part + ")");
  }
  warn(0, fmt::format("ignored settings that do not change the prescription: {}",
                      fmt::join(parts, ", ")));
}

ZmxImport ZmxParser::parse(std::string_view bytes) {
  const std::string text = decode_text(bytes);
  const std::vector<Line> lines = split_lines(text);
  for (const Line& line : lines) {
    if (line.fields.empty()) continue;
    const char first = line.fields[0].front();
    if (first == '!' || first == '#') continue;  // a comment line
    const std::string key = upper(line.fields[0]);
    if (key == "SURF") {
      RawSurface s;
      s.number = integer(line, 1, "the surface number");
      s.line = line.number;
      if (s.number != static_cast<int>(surfaces_.size()))
        fail(line, 1,
             fmt::format("SURF {} is out of order: surface {} was expected", s.number,
                         surfaces_.size()));
      surfaces_.push_back(s);
      continue;
    }
    if (surface_line(line, key)) continue;
    system_line(line, key);
  }

  const int last_line = lines.empty() ? 1 : lines.back().number;
  if (surfaces_.size() < 4)
    fail_at(last_line, 1,
            fmt::format("{} SURF block{}: a lens needs the object surface, at least two lens "
                        "surfaces and the image surface",
                        surfaces_.size(), surfaces_.size() == 1 ? "" : "s"));

  // Object and image.
  const RawSurface& object = surfaces_.front();
  if (!object.thickness_infinite && !(object.thickness_mm > 0.0))
    fail_at(object.disz_line > 0 ? object.disz_line : object.line, 1,
            fmt::format("the object is at {} mm; lensopt needs a positive object distance or "
                        "INFINITY",
                        object.thickness_mm * unit_mm_));
  if (!object.glass.empty())
    fail_at(object.glas_line, object.glas_column, "the object space must be air");
  if (object.is_stop) fail_at(object.stop_line, 1, "the object surface cannot be the stop");
  const RawSurface& image = surfaces_.back();
  if (image.curvature_per_mm != 0.0)
    fail_at(image.curv_line, 1, "the image surface is curved; lensopt's image plane is flat");
  if (image.is_stop) fail_at(image.stop_line, 1, "the image surface cannot be the stop");

  // Specs that decide how glasses resolve.
  std::vector<CatalogEntry> catalogs = load_catalogs();
  for (const CatalogEntry& entry : catalogs)
    if (!entry.catalog)
      warn(0, fmt::format("glass catalog '{}' {}", entry.requested, entry.failure));
  bool has_catalog_glass = false;
  for (std::size_t k = 1; k + 1 < surfaces_.size(); ++k)
    has_catalog_glass =
        has_catalog_glass || (!surfaces_[k].glass.empty() && !surfaces_[k].model_glass);
  const DispersionModel dispersion =
      note_dispersion_ ? *note_dispersion_
                       : (has_catalog_glass ? DispersionModel::kCatalog : DispersionModel::kAbbe);

  ZmxImport result;
  Lens& lens = result.lens;
  lens.source_path = file_;
  lens.name = has_name_ && !name_.empty() ? name_ : std::filesystem::path(file_).stem().string();
  lens.specs.dispersion = dispersion;

  LensSourceLines source_lines;
  std::vector<std::string> used_catalogs;
  int stop_count = 0;
  for (std::size_t k = 1; k + 1 < surfaces_.size(); ++k) {
    const RawSurface& raw = surfaces_[k];
    if (raw.thickness_infinite)
      fail_at(raw.disz_line, 1, fmt::format("surface {} has an infinite thickness", raw.number));
    Surface surface;
    surface.curvature_per_mm = raw.curvature_per_mm / unit_mm_;
    surface.thickness_mm = raw.thickness_mm * unit_mm_;
    surface.semi_diameter_mm = raw.semi_diameter_mm * unit_mm_;
    surface.conic = raw.conic;
    if (raw.even_asphere) {
      // a_{2i} in lens units^(1-2i).
      double unit_power = unit_mm_;  // unit^(2i-1)
      surface.asphere_r2_per_mm = raw.parm[1] / unit_power;
      for (int j = 0; j < kAsphereOrders; ++j) {
        unit_power *= unit_mm_ * unit_mm_;
        surface.asphere[j] = raw.parm[j + 2] / unit_power;
      }
    }
    surface.material = resolve_glass(raw, catalogs, used_catalogs, dispersion);
    if (raw.is_stop) {
      if (++stop_count > 1)
        fail_at(
            raw.stop_line, 1,
            fmt::format("surface {} is a second STOP; a lens has one aperture stop", raw.number));
      if (surface.curvature_per_mm != 0.0 || !surface.is_spherical()) {
        // A flat stop at the vertex of the curved surface, in the medium before it.
        Surface stop;
        stop.is_stop = true;
        stop.thickness_mm = 0.0;
        stop.material = lens.surfaces.empty() ? Material::air() : lens.surfaces.back().material;
        stop.semi_diameter_mm = surface.semi_diameter_mm;
        lens.surfaces.push_back(stop);
        source_lines.surfaces.push_back(raw.line);
        warn(raw.stop_line,
             fmt::format("the stop is on curved surface {}; lensopt's stop is flat, so a flat "
                         "stop surface is inserted at its vertex (0 mm before it)",
                         raw.number));
      } else {
        surface.is_stop = true;
      }
    }
    lens.surfaces.push_back(surface);
    source_lines.surfaces.push_back(raw.line);
  }
  if (stop_count == 0) {
    // OpticStudio's default stop is surface 1.
    warn(surfaces_[1].line, "no STOP line: surface 1 is the stop (OpticStudio's default)");
    if (lens.surfaces.front().curvature_per_mm == 0.0 && lens.surfaces.front().is_spherical()) {
      lens.surfaces.front().is_stop = true;
    } else {
      Surface stop;
      stop.is_stop = true;
      lens.surfaces.insert(lens.surfaces.begin(), stop);
    }
  }
  if (!lens.surfaces.back().material.is_air()) {
    const RawSurface& raw = surfaces_[surfaces_.size() - 2];
    fail_at(raw.glas_line, raw.glas_column,
            fmt::format("surface {} (the last before the image) must be followed by air, not {}",
                        raw.number, raw.glass));
  }
  if (!used_catalogs.empty()) {
    lens.catalog_name = note_catalog_ && std::find(used_catalogs.begin(), used_catalogs.end(),
                                                   *note_catalog_) != used_catalogs.end()
                            ? *note_catalog_
                            : used_catalogs.front();
    if (used_catalogs.size() > 1)
      warn(0, fmt::format("glasses come from {} catalogs ({}); a lensopt TOML lens names one "
                          "(catalog = \"{}\"), so written as TOML the others would not resolve",
                          used_catalogs.size(), fmt::join(used_catalogs, ", "), lens.catalog_name));
  } else if (note_catalog_) {
    lens.catalog_name = *note_catalog_;
  }

  // Wavelengths: the active ones (FTYP's count), in um.
  std::vector<Wavelength> waves;
  if (!wavm_.empty()) {
    for (const auto& [index, w] : wavm_) {
      if (wavelength_count_ >= 0 && index > wavelength_count_) continue;
      waves.push_back(w);
    }
  } else {
    waves = wavl_;
    if (wavelength_count_ >= 0 && static_cast<int>(waves.size()) > wavelength_count_)
      waves.resize(static_cast<std::size_t>(wavelength_count_));
  }
  if (waves.empty())
    fail_at(wavelength_line_ > 0 ? wavelength_line_ : last_line, 1,
            "no wavelength; the file needs WAVM lines");
  std::vector<double> wavelengths_nm;
  std::vector<double> weights;
  bool equal_weights = true;
  for (const Wavelength& w : waves) {
    const double nm = w.nm;
    if (!(nm > 200.0 && nm < 20000.0))
      fail_at(w.line, 1, fmt::format("wavelength {} um is out of range", w.um));
    if (!(w.weight >= 0.0)) fail_at(w.line, 1, "a wavelength weight must be >= 0");
    wavelengths_nm.push_back(nm);
    weights.push_back(w.weight);
    equal_weights = equal_weights && w.weight == waves.front().weight;
  }
  if (note_wavelengths_nm_) {
    bool agrees = note_wavelengths_nm_->size() == wavelengths_nm.size();
    for (std::size_t i = 0; agrees && i < wavelengths_nm.size(); ++i)
      agrees = std::abs((*note_wavelengths_nm_)[i] - wavelengths_nm[i]) <=
               kNoteTolerance * wavelengths_nm[i];
    if (agrees) {
      wavelengths_nm = *note_wavelengths_nm_;
    } else {
      warn(note_line_, "the lensopt wavelengths note disagrees with the WAVM lines; ignored");
    }
  }
  lens.specs.wavelengths_nm = wavelengths_nm;
  if (!equal_weights) lens.specs.wavelength_weights = weights;
  // The primary wavelength: PWAV's (OpticStudio's paraxial reference), else the note's.
  if (pwav_ > 0 && static_cast<std::size_t>(pwav_) <= wavelengths_nm.size()) {
    lens.specs.primary_wavelength_nm = wavelengths_nm[static_cast<std::size_t>(pwav_) - 1];
  } else if (pwav_ > 0) {
    fail_at(pwav_line_, 2,
            fmt::format("PWAV {} names no active wavelength ({} are active)", pwav_,
                        wavelengths_nm.size()));
  } else {
    lens.specs.primary_wavelength_nm = wavelengths_nm.front();
  }
  if (note_primary_nm_) lens.specs.primary_wavelength_nm = *note_primary_nm_;
  if (note_channels_ && note_channels_->size() == wavelengths_nm.size()) {
    lens.specs.wavelength_channels = *note_channels_;
  } else {
    lens.specs.wavelength_channels = default_wavelength_channels(wavelengths_nm);
    std::vector<std::string> assigned;
    for (std::size_t i = 0; i < wavelengths_nm.size(); ++i)
      assigned.push_back(fmt::format(
          "{} nm {}", wavelengths_nm[i],
          kChannelLetters[static_cast<std::size_t>(lens.specs.wavelength_channels[i])]));
    warn(wavelength_line_,
         fmt::format("colour channels assigned by wavelength (< 500 nm B, < 600 nm G, else R; an "
                     "empty channel borrows the nearest wavelength): {}",
                     fmt::join(assigned, ", ")));
  }

  // Fields: the active ones, radial distance sqrt(x^2 + y^2) (the lens is rotationally
  // symmetric), with their weights and vignetting factors.
  std::size_t field_count = std::max(xfln_.size(), yfln_.size());
  if (field_count_ >= 0)
    field_count = std::min(field_count, static_cast<std::size_t>(field_count_));
  if (field_count == 0) field_count = 1;
  lens.specs.field_type = static_cast<FieldType>(field_type_);
  lens.specs.fields.clear();
  auto factor = [&](const char* key, std::size_t i) {
    const auto it = vignetting_.find(key);
    return it != vignetting_.end() && i < it->second.size() ? it->second[i] : 0.0;
  };
  bool dropped_vdx = false;
  for (std::size_t i = 0; i < field_count; ++i) {
    const double x = i < xfln_.size() ? xfln_[i] : 0.0;
    const double y = i < yfln_.size() ? yfln_[i] : 0.0;
    FieldPoint f;
    f.value = x == 0.0 ? std::abs(y) : std::hypot(x, y);
    f.weight = i < field_weights_.size() ? field_weights_[i] : 1.0;
    f.vignetting.vdy = factor("VDYN", i);
    f.vignetting.vcx = factor("VCXN", i);
    f.vignetting.vcy = factor("VCYN", i);
    if (factor("VDXN", i) != 0.0) dropped_vdx = true;
    if (!(f.vignetting.vcx < 1.0) || !(f.vignetting.vcy < 1.0))
      fail_at(yfln_line_ > 0 ? yfln_line_ : last_line, 1,
              fmt::format("field {}: vignetting compression VCX, VCY must be < 1", i + 1));
    lens.specs.fields.push_back(f);
  }
  if (dropped_vdx)
    warn(vdxn_line_,
         "x-decentre vignetting factors (VDXN) ignored: lensopt traces half pupils "
         "symmetric in x");
  if (!object.thickness_infinite) lens.specs.object_distance_mm = object.thickness_mm * unit_mm_;
  if (lens.specs.field_type == FieldType::kObjectHeight && lens.specs.object_at_infinity())
    fail_at(ftyp_line_, 1, "object-height fields (FTYP 1) need a finite object distance");
  if (lens.specs.field_type == FieldType::kAngle) {
    for (const FieldPoint& f : lens.specs.fields)
      if (!(f.value < 89.0))
        fail_at(yfln_line_ > 0 ? yfln_line_ : last_line, 1,
                fmt::format("the field {} deg must be less than 89", f.value));
  } else {
    for (FieldPoint& f : lens.specs.fields) f.value *= unit_mm_;
  }

  // Aperture.
  if (!fnum_ && !enpd_ && !obna_ && !floa_)
    fail_at(last_line, 1,
            "no aperture: the file needs ENPD, FNUM, OBNA or FLOA (float by stop size)");
  lens.specs.mode = SpecMode::kAsWritten;
  if (fnum_) {
    lens.specs.aperture_type = ApertureType::kFNumber;
    lens.specs.f_number = *fnum_;
  } else if (enpd_) {
    lens.specs.aperture_type = ApertureType::kEntrancePupilDiameter;
    lens.specs.aperture_value = *enpd_ * unit_mm_;
  } else if (obna_) {
    lens.specs.aperture_type = ApertureType::kObjectNA;
    lens.specs.aperture_value = *obna_;
    if (lens.specs.object_at_infinity())
      fail_at(aperture_line_, 1, "OBNA (object-space NA) needs a finite object distance");
  } else {
    lens.specs.aperture_type = ApertureType::kFloatByStop;
    const int stop = lens.stop_index();
    if (stop < 0 || !(lens.surfaces[stop].semi_diameter_mm > 0.0)) {
      // The stop's DIAM sets the aperture whatever its flag.
      for (const RawSurface& raw : surfaces_)
        if (raw.is_stop && raw.semi_diameter_mm > 0.0 && stop >= 0)
          lens.surfaces[stop].semi_diameter_mm = raw.semi_diameter_mm * unit_mm_;
    }
    if (stop < 0 || !(lens.surfaces[stop].semi_diameter_mm > 0.0))
      fail_at(aperture_line_, 1, "FLOA (float by stop size) needs the stop's DIAM");
  }
  lens.specs.half_field_deg =
      lens.specs.field_type == FieldType::kAngle ? lens.specs.max_field_value() : 0.0;
  try {
    validate_lens(lens, source_lines);
  } catch (const Error& error) {
    throw Error(SourceLocation{file_, error.where().line}, error.message());
  }
  // The summary specs the paper's machinery uses (optimize, tolerance): the chief-ray half field,
  // the image-space F/# and the sensor whose spec focal length is the lens's EFL.
  TraceOptions summary;
  summary.rings = 1;
  summary.ray_aiming = false;
  const TraceSystem<double> sys = prepare_lens_system(lens, summary);
  const double efl_mm = sys.efl_mm;
  double half_field_deg = 0.0;
  for (const double a : sys.fields_deg) half_field_deg = std::max(half_field_deg, std::abs(a));
  if (lens.specs.field_type == FieldType::kAngle) half_field_deg = lens.specs.max_field_value();
  if (!(half_field_deg < 89.0) || !std::isfinite(half_field_deg))
    fail_at(yfln_line_ > 0 ? yfln_line_ : last_line, 1,
            fmt::format("the largest field is {} deg; lensopt needs less than 89", half_field_deg));
  lens.specs.half_field_deg = half_field_deg;
  if (!(efl_mm > 0.0) || !std::isfinite(efl_mm))
    fail_at(
        aperture_line_, 1,
        fmt::format("the paraxial EFL is {} mm; lensopt needs a positive focal length", efl_mm));
  if (!fnum_) lens.specs.f_number = efl_mm / sys.epd_mm;
  if (note_sensor_mm_) {
    lens.specs.sensor_diagonal_mm = *note_sensor_mm_;
  } else if (half_field_deg > 0.0) {
    lens.specs.sensor_diagonal_mm = 2.0 * efl_mm * std::tan(half_field_deg * kPi / 180.0);
  }
  if (note_mode_paper_) {
    // Written by lensopt from a lens in the paper's mode: its specs are f/#, hfov and sensor.
    lens.specs.mode = SpecMode::kPaper;
    lens.specs.fields.clear();
    lens.specs.field_type = FieldType::kAngle;
    lens.specs.aperture_type = ApertureType::kFNumber;
    lens.specs.aperture_value = 0.0;
  }
  lens.extra_toml = note_toml_;
  try {
    validate_lens(lens, source_lines);
  } catch (const Error& error) {
    throw Error(SourceLocation{file_, error.where().line}, error.message());
  }

  report_ignored();
  result.warnings = std::move(warnings_);
  return result;
}

// The shortest decimal reading back as x.
std::string number_text(double x) {
  return fmt::format("{}", x);
}

// The micrometre text of a wavelength: the shortest decimal of nm with its point moved three
// places left ("584.1" -> "0.5841"), so micrometres_to_nm reads nm back exactly.
std::string micrometre_text(double nm) {
  const std::string text = number_text(nm);
  if (text.find_first_of("eEn") != std::string::npos || text.front() == '-')
    return number_text(nm / 1000.0);
  const std::size_t point = text.find('.');
  std::string integer = text.substr(0, point);
  const std::string fraction = point == std::string::npos ? "" : text.substr(point + 1);
  if (integer.size() < 4) integer = std::string(4 - integer.size(), '0') + integer;
  std::string out = integer.substr(0, integer.size() - 3);
  std::string decimals = integer.substr(integer.size() - 3) + fraction;
  while (!decimals.empty() && decimals.back() == '0') decimals.pop_back();
  return decimals.empty() ? out : out + "." + decimals;
}

}  // namespace

std::string zemax_catalog_name(std::string_view catalog_name) {
  if (upper(catalog_name) == "OHARA") return "OHARA";
  const std::filesystem::path path{std::string(catalog_name)};
  if (path.has_parent_path() || path.has_extension()) return path.stem().string();
  return std::string(catalog_name);
}

ZmxImport parse_zmx(std::string_view bytes, const std::string& source_name) {
  return ZmxParser(source_name).parse(bytes);
}

ZmxImport read_zmx(const std::filesystem::path& path) {
  return parse_zmx(read_file(path), path.string());
}

std::string format_zmx(const Lens& lens) {
  std::string out;
  auto line = [&out](const std::string& text) { out += text + "\r\n"; };
  const Specs& specs = lens.specs;
  if (specs.wavelengths_nm.size() != specs.wavelength_channels.size())
    throw Error(fmt::format("lens '{}': {} wavelengths but {} channels", lens.name,
                            specs.wavelengths_nm.size(), specs.wavelength_channels.size()));

  line("VERS 190513 80 123457 L123457");
  line("MODE SEQ");
  std::string name = lens.name;
  std::replace(name.begin(), name.end(), '\n', ' ');
  std::replace(name.begin(), name.end(), '\r', ' ');
  line("NAME " + name);
  line("NOTE 0 Written by lensopt; the lensopt notes below keep what Zemax has no field for");
  if (!lens.catalog_name.empty()) line("NOTE 0 lensopt catalog " + lens.catalog_name);
  line("NOTE 0 lensopt sensor_diagonal_mm " + number_text(specs.sensor_diagonal_mm));
  line(std::string("NOTE 0 lensopt dispersion ") +
       (specs.dispersion == DispersionModel::kCatalog ? "catalog" : "abbe"));
  std::string channels;
  for (const int channel : specs.wavelength_channels) {
    if (channel < 0 || channel > 2)
      throw Error(
          fmt::format("lens '{}': wavelength channel {} is not R, G or B", lens.name, channel));
    channels += kChannelLetters[static_cast<std::size_t>(channel)];
  }
  line("NOTE 0 lensopt channels " + channels);
  std::vector<std::string> nm_texts;
  for (const double nm : specs.wavelengths_nm) nm_texts.push_back(number_text(nm));
  line(fmt::format("NOTE 0 lensopt wavelengths_nm {}", fmt::join(nm_texts, " ")));
  if (!lens.extra_toml.empty()) {
    std::size_t start = 0;
    const std::string& extra = lens.extra_toml;
    while (start < extra.size()) {
      std::size_t end = extra.find('\n', start);
      if (end == std::string::npos) end = extra.size();
      std::string text = extra.substr(start, end - start);
      if (!text.empty() && text.back() == '\r') text.pop_back();
      line(text.empty() ? "NOTE 0 lensopt-toml" : "NOTE 0 lensopt-toml " + text);
      start = end + 1;
    }
  }
  if (specs.mode == SpecMode::kPaper) line("NOTE 0 lensopt mode paper");
  line("NOTE 0 lensopt primary_wavelength_nm " + number_text(specs.primary_wavelength_nm));
  line("UNIT MM X W X CM MR CPMM");
  const bool as_written = specs.mode == SpecMode::kAsWritten;
  switch (as_written ? specs.aperture_type : ApertureType::kFNumber) {
    case ApertureType::kFNumber:
      line(fmt::format("FNUM {} 0", number_text(specs.f_number)));
      break;
    case ApertureType::kEntrancePupilDiameter:
      line(fmt::format("ENPD {}", number_text(specs.aperture_value)));
      break;
    case ApertureType::kObjectNA:
      line(fmt::format("OBNA {}", number_text(specs.aperture_value)));
      break;
    case ApertureType::kFloatByStop:
      line("FLOA");
      break;
  }

  // Catalogs: the lens's, then any other its glasses come from.
  std::vector<std::string> gcat;
  auto add_catalog = [&gcat](const std::string& zemax_name) {
    if (!zemax_name.empty() && std::find(gcat.begin(), gcat.end(), zemax_name) == gcat.end())
      gcat.push_back(zemax_name);
  };
  bool has_catalog_glass = false;
  for (const Surface& s : lens.surfaces)
    has_catalog_glass = has_catalog_glass || s.material.kind == Material::Kind::kCatalog;
  if (has_catalog_glass) {
    if (!lens.catalog_name.empty()) add_catalog(zemax_catalog_name(lens.catalog_name));
    for (const Surface& s : lens.surfaces)
      if (s.material.kind == Material::Kind::kCatalog && s.material.glass &&
          lens.catalog_name.empty())
        add_catalog(zemax_catalog_name(s.material.glass->catalog));
    if (!gcat.empty()) line(fmt::format("GCAT {}", fmt::join(gcat, " ")));
  }

  // Fields: the written ones, else 0, 0.7 and 1 of the half field (one on axis when it is 0).
  std::vector<FieldPoint> fields;
  if (as_written && !specs.fields.empty()) {
    fields = specs.fields;
  } else {
    fields.push_back({});
    if (specs.half_field_deg != 0.0)
      for (const double f : {0.7, 1.0}) fields.push_back({f * specs.half_field_deg, 1.0, {}});
  }
  const int field_type =
      as_written && !specs.fields.empty() ? static_cast<int>(specs.field_type) : 0;
  std::vector<std::string> x_texts, y_texts, weight_texts, vdy, vcx, vcy;
  bool vignetting = false;
  for (const FieldPoint& f : fields) {
    x_texts.push_back("0");
    y_texts.push_back(number_text(f.value));
    weight_texts.push_back(number_text(f.weight));
    vdy.push_back(number_text(f.vignetting.vdy));
    vcx.push_back(number_text(f.vignetting.vcx));
    vcy.push_back(number_text(f.vignetting.vcy));
    vignetting = vignetting || f.vignetting.any();
  }
  line(
      fmt::format("FTYP {} 0 {} {} 0 0 0", field_type, fields.size(), specs.wavelengths_nm.size()));
  line(fmt::format("XFLN {}", fmt::join(x_texts, " ")));
  line(fmt::format("YFLN {}", fmt::join(y_texts, " ")));
  line(fmt::format("FWGN {}", fmt::join(weight_texts, " ")));
  if (vignetting) {
    line(fmt::format("VDYN {}", fmt::join(vdy, " ")));
    line(fmt::format("VCXN {}", fmt::join(vcx, " ")));
    line(fmt::format("VCYN {}", fmt::join(vcy, " ")));
  }
  std::size_t primary = 0;
  for (std::size_t i = 0; i < specs.wavelengths_nm.size(); ++i) {
    const double weight = specs.wavelength_weights.size() == specs.wavelengths_nm.size()
                              ? specs.wavelength_weights[i]
                              : 1.0;
    line(fmt::format("WAVM {} {} {}", i + 1, micrometre_text(specs.wavelengths_nm[i]),
                     number_text(weight)));
    if (std::abs(specs.wavelengths_nm[i] - specs.primary_wavelength_nm) <
        std::abs(specs.wavelengths_nm[primary] - specs.primary_wavelength_nm))
      primary = i;
  }
  line(fmt::format("PWAV {}", primary + 1));

  line("SURF 0");
  line("  TYPE STANDARD");
  line("  CURV 0");
  line(specs.object_at_infinity()
           ? std::string("  DISZ INFINITY")
           : fmt::format("  DISZ {}", number_text(specs.object_distance_mm)));
  // Surfaces without a clear aperture get OpticStudio's automatic semi-diameter ("DIAM r 0",
  // not an aperture when read back); none if the lens cannot be traced.
  std::vector<double> automatic;
  try {
    automatic = automatic_semi_diameters(lens);
  } catch (const Error&) {
    automatic.clear();
  }
  int number = 1;
  for (const Surface& s : lens.surfaces) {
    line(fmt::format("SURF {}", number++));
    line(s.has_asphere() ? "  TYPE EVENASPH" : "  TYPE STANDARD");
    line(fmt::format("  CURV {}", number_text(s.curvature_per_mm)));
    if (s.has_asphere()) {
      line(fmt::format("  PARM 1 {}", number_text(s.asphere_r2_per_mm)));
      for (int j = 0; j < kAsphereOrders; ++j)
        line(fmt::format("  PARM {} {}", j + 2, number_text(s.asphere[j])));
    }
    line(fmt::format("  DISZ {}", number_text(s.thickness_mm)));
    switch (s.material.kind) {
      case Material::Kind::kAir:
        break;
      case Material::Kind::kCatalog:
        line(fmt::format("  GLAS {} 0 0 {} {} 0 0 0 0 0 0", s.material.glass_name,
                         number_text(s.material.nd), number_text(s.material.vd)));
        break;
      case Material::Kind::kModel:
        line(fmt::format("  GLAS ___BLANK 1 0 {} {} 0 0 0 0 0 0", number_text(s.material.nd),
                         number_text(s.material.vd)));
        break;
    }
    if (s.is_stop) line("  STOP");
    if (s.semi_diameter_mm != 0.0) {
      line(fmt::format("  DIAM {} 1", number_text(s.semi_diameter_mm)));
    } else if (static_cast<std::size_t>(number - 2) < automatic.size() &&
               std::isfinite(automatic[static_cast<std::size_t>(number - 2)])) {
      line(
          fmt::format("  DIAM {} 0", number_text(automatic[static_cast<std::size_t>(number - 2)])));
    }
    if (s.conic != 0.0) line(fmt::format("  CONI {}", number_text(s.conic)));
  }
  line(fmt::format("SURF {}", number));
  line("  TYPE STANDARD");
  line("  CURV 0");
  line("  DISZ 0");
  return out;
}

void write_zmx(const Lens& lens, const std::filesystem::path& path) {
  write_file_atomic(path, format_zmx(lens));
}

}  // namespace lensopt
