// The .zmx reader's line handlers: surface keys, system keys, lensopt's NOTE lines, and the report
// of ignored settings (zmx_parser.h).
#include <fmt/format.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <set>

#include "zmx_parser.h"

namespace lensopt::zmx_detail {

// Keywords of OpticStudio's system and surface settings that do not change a sequential spherical
// prescription at infinity as lensopt models it (display, analysis and environment defaults,
// tolerances, coatings, drawing). They are reported together, by keyword and line.
bool is_setting_keyword(const std::string& key) {
  static const std::set<std::string> kSettings = {
      "PFIL", "LANG", "GFAC", "RAIM", "PUSH", "SDMA", "ROPD", "PICB", "POLS",
      "GLRS", "GSTD", "NSCD", "COFN", "SUMM", "DMFS", "BLNK", "RWRE", "TOL",
      "MNUM", "MOFF", "OPDX", "SCOL", "SQFN", "HIDE", "MIRR", "SLAB", "POPS",
      "FLAP", "MEMA", "COAT", "TCE",  "ENVD", "EFFL", "ZVDX", "ZVDY", "ZVCX",
      "ZVCY", "ZVAN", "WAVN", "XFLD", "YFLD", "FIMP", "BLAN", "CONF", "DESC"};
  return kSettings.count(key) > 0;
}

bool ZmxParser::surface_line(const Line& line, const std::string& key) {
  if (key == "TYPE") {
    RawSurface& s = surface(line);
    const std::string type = line.fields.size() > 1 ? upper(line.fields[1]) : "";
    if (type != "STANDARD" && type != "EVENASPH" && type != "COORDBRK")
      fail(line, 1,
           fmt::format("surface {} has type {}, which lensopt does not support; it imports "
                       "STANDARD (sphere or conic), EVENASPH and COORDBRK surfaces only",
                       s.number, type.empty() ? std::string("(none)") : type));
    s.even_asphere = type == "EVENASPH";
    s.coordinate_break = type == "COORDBRK";
    s.type_line = line.number;
    return true;
  }
  if (key == "CURV") {
    RawSurface& s = surface(line);
    s.curvature_per_mm = number(line, 1, "CURV (curvature, 1/lens unit)");
    s.curv_line = line.number;
    // "CURV c solve p1 p2 p3 ...": the solve type (0 fixed, 1 variable, 4 pickup from surface p1
    // with scale p2 on the curvature, p3 the source column, 0 = the curvature).
    const int solve = line.fields.size() > 2 ? integer(line, 2, "the curvature solve type") : 0;
    if (solve == 1) {
      s.curvature_variable = true;
    } else if (solve == 4) {
      const double source = number(line, 3, "the curvature pickup's source surface");
      const double scale = line.fields.size() > 4 ? number(line, 4, "the pickup's scale") : 1.0;
      const double column = line.fields.size() > 5 ? number(line, 5, "the pickup's column") : 0.0;
      if (column != 0.0 || source != std::floor(source) || !std::isfinite(scale)) {
        warn(line.number,
             fmt::format("surface {}: a curvature pickup from column {:g} of surface {:g} is not "
                         "supported (lensopt picks up a curvature from a curvature); the "
                         "written curvature is kept, fixed",
                         s.number, column, source));
      } else {
        s.curvature_pickup_source = static_cast<int>(source);
        s.curvature_pickup_scale = scale;
      }
    } else if (solve != 0) {
      warn(line.number,
           fmt::format("surface {}: curvature solve type {} is not supported (lensopt reads "
                       "variables, 1, and pickups, 4); the written curvature is kept, fixed",
                       s.number, solve));
    }
    return true;
  }
  if (key == "PZUP") {
    // "PZUP source scale offset column": the thickness picked up from surface `source`.
    RawSurface& s = surface(line);
    const double source = number(line, 1, "the thickness pickup's source surface");
    const double scale = number(line, 2, "the thickness pickup's scale");
    const double offset = line.fields.size() > 3 ? number(line, 3, "the pickup's offset") : 0.0;
    const double column = line.fields.size() > 4 ? number(line, 4, "the pickup's column") : 0.0;
    if (column != 0.0 || source != std::floor(source) || !std::isfinite(scale) ||
        !std::isfinite(offset)) {
      warn(line.number,
           fmt::format("surface {}: a thickness pickup from column {:g} of surface {:g} is not "
                       "supported (lensopt picks up a thickness from a thickness); the written "
                       "thickness is kept, fixed",
                       s.number, column, source));
      return true;
    }
    s.thickness_pickup_source = static_cast<int>(source);
    s.thickness_pickup_scale = scale;
    s.thickness_pickup_offset = offset;
    s.pzup_line = line.number;
    return true;
  }
  if (key == "MAZH") {
    // "MAZH height zone": OpticStudio's marginal-ray-height solve on the thickness; zone 0 is the
    // paraxial marginal ray, any other zone a real ray.
    RawSurface& s = surface(line);
    const double height = number(line, 1, "the marginal ray height");
    const double zone = line.fields.size() > 2 ? number(line, 2, "the pupil zone") : 0.0;
    if (zone != 0.0 || !std::isfinite(height)) {
      warn(line.number,
           fmt::format("surface {}: a marginal-ray-height solve on a real ray (pupil zone {:g}) "
                       "is not supported (lensopt solves on the paraxial ray, zone 0); the "
                       "written thickness is kept, fixed",
                       s.number, zone));
      return true;
    }
    s.marginal_height_solve = true;
    s.marginal_height = height;
    s.mazh_line = line.number;
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
    if (upper(name) == "MIRROR") {
      // A reflecting surface; the medium before it continues (zmx_read.cpp).
      s.mirror = true;
      return true;
    }
    // "GLAS ___BLANK 1 0 nd vd dPgF ...": OpticStudio's model glass. (A named glass with the
    // same fields, "GLAS N-LAK9 1 0 nd vd", is a catalog glass: optiland's lens1.zmx.)
    if (name == "___BLANK") {
      s.model_glass = true;
      s.model_nd = number(line, 4, "the model glass's nd (GLAS ___BLANK 1 0 nd vd)");
      s.model_vd = number(line, 5, "the model glass's vd (GLAS ___BLANK 1 0 nd vd)");
      if (!(s.model_nd > 1.0))
        fail(line, 4, fmt::format("model glass nd = {} must be > 1", s.model_nd));
      if (!(s.model_vd > 0.0))
        fail(line, 5, fmt::format("model glass vd = {} must be > 0", s.model_vd));
      if (line.fields.size() > 6)
        s.model_dpgf = number(line, 6, "the model glass's dPgF (GLAS ___BLANK 1 0 nd vd dPgF)");
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
  if (key == "PARM" && surface(line).coordinate_break) {
    // COORDBRK: PARM 1 decenter x, 2 decenter y, 3 tilt about x, 4 about y, 5 about z (deg),
    // 6 order (0: decenter then tilt; otherwise tilt then decenter).
    RawSurface& s = surface(line);
    const int index = integer(line, 1, "the PARM number");
    const double value = number(line, 2, "the PARM value");
    if (index >= 1 && index <= 6) {
      s.parm[index] = value;
    } else if (value != 0.0) {
      fail(line, 1,
           fmt::format("surface {}: COORDBRK has PARM 1..6 (decenter x, y, tilt x, y, z, order); "
                       "PARM {} = {} is not one of them",
                       s.number, index, line.fields[2]));
    } else {
      ignore(line);
    }
    return true;
  }
  if (key == "CLAP" || key == "OBSC") {
    // "CLAP rmin rmax ..." a circular aperture, "OBSC rmin rmax ..." a circular obscuration.
    RawSurface& s = surface(line);
    const double r_min = number(line, 1, fmt::format("{} (minimum radius)", key));
    const double r_max = number(line, 2, fmt::format("{} (maximum radius)", key));
    if (!(r_min >= 0.0) || !(r_max > r_min))
      fail(line, 1,
           fmt::format("{} {} {}: the radii must satisfy 0 <= min < max", key, line.fields[1],
                       line.fields[2]));
    (key == "CLAP" ? s.clap_min : s.obsc_min) = r_min;
    (key == "CLAP" ? s.clap_max : s.obsc_max) = r_max;
    (key == "CLAP" ? s.clap_line : s.obsc_line) = line.number;
    return true;
  }
  if (key == "OBDC") {
    RawSurface& s = surface(line);
    s.obdc_x = number(line, 1, "OBDC (aperture decenter x)");
    s.obdc_y = number(line, 2, "OBDC (aperture decenter y)");
    return true;
  }
  if (key == "SCBD") {
    RawSurface& s = surface(line);
    s.scbd_line = line.number;
    for (std::size_t i = 0; i < 8; ++i) s.scbd[i] = number(line, i + 1, "an SCBD value");
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
  if (key == "vary") {
    // "NOTE 0 lensopt vary <surface> radius thickness conic glass": the vary flags of a surface
    // (the .zmx keeps a curvature flag of its own; the others have no field lensopt writes).
    const int number = integer(line, 4, "the surface of a vary note");
    VaryFlags flags;
    for (std::size_t i = 5; i < line.fields.size(); ++i) {
      const std::string_view name = line.fields[i];
      if (name == "radius")
        flags.radius = true;
      else if (name == "thickness")
        flags.thickness = true;
      else if (name == "conic")
        flags.conic = true;
      else if (name == "glass")
        flags.glass = true;
      else
        warn(line.number, fmt::format("unknown vary entry '{}' in a lensopt note ignored", name));
    }
    note_vary_.push_back({number, flags, line.number});
    return;
  }
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
  } else if (key == "model_glass") {
    note_model_glass_paper_ = line.fields[4] == "paper";
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
    if (index < 1 || index > static_cast<int>(kMaxWavelengths))
      fail(line, 1,
           fmt::format("wavelength number {} is out of range: lensopt reads wavelengths 1 to {}",
                       index, kMaxWavelengths));
    Wavelength w;
    w.um = number(line, 2, "the wavelength (um)");
    w.nm = micrometres_to_nm(line.fields[2], w.um);
    if (line.fields.size() > 3) w.weight = number(line, 3, "the wavelength weight");
    w.line = line.number;
    wavm_[index] = w;
    if (wavelength_line_ == 0) wavelength_line_ = line.number;
  } else if (key == "WAVL") {
    for (std::size_t i = 1; i < line.fields.size(); ++i) {
      if (wavl_.size() >= kMaxWavelengths)
        fail(line, i,
             fmt::format("more than {} wavelengths; lensopt reads at most {}", kMaxWavelengths,
                         kMaxWavelengths));
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
    // FTYP type telecentric fields wavelengths normalization ? afocal ...: the seventh value is
    // OpticStudio's "Afocal Image Space" check box (as optiland's reader takes it).
    if (line.fields.size() > 7) {
      const int afocal = integer(line, 7, "the afocal image space flag");
      if (afocal != 0 && afocal != 1)
        fail(line, 7, fmt::format("the afocal image space flag is {}; it must be 0 or 1", afocal));
      ftyp_afocal_ = afocal == 1;
    }
  } else if (key == "VDXN" || key == "VDYN" || key == "VCXN" || key == "VCYN" || key == "VANN") {
    check_field_count(line);
    std::vector<double>& values = vignetting_[key];
    values.clear();
    for (std::size_t i = 1; i < line.fields.size(); ++i)
      values.push_back(number(line, i, "a vignetting factor"));
  } else if (key == "FWGN") {
    check_field_count(line);
    field_weights_.clear();
    for (std::size_t i = 1; i < line.fields.size(); ++i) {
      field_weights_.push_back(number(line, i, "a field weight"));
      if (!(field_weights_.back() >= 0.0))
        fail(line, i, fmt::format("field weight {} must be >= 0", field_weights_.back()));
    }
    fwgn_line_ = line.number;
  } else if (key == "XFLN" || key == "YFLN") {
    check_field_count(line);
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

}  // namespace lensopt::zmx_detail
