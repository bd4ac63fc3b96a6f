// The designer's targets (optimize/targets.h).
#include "lensopt/optimize/targets.h"

#include <fmt/format.h>

#include <cctype>
#include <cmath>
#include <limits>

#include "lensopt/core/error.h"

namespace lensopt {
namespace {

struct QuantityName {
  TargetQuantity quantity;
  const char* name;
};
constexpr QuantityName kQuantityNames[] = {
    {TargetQuantity::kEflMm, "efl_mm"},
    {TargetQuantity::kFNumber, "f_number"},
    {TargetQuantity::kTotalTrackMm, "total_track_mm"},
    {TargetQuantity::kBflMm, "bfl_mm"},
    {TargetQuantity::kDistortionPercent, "distortion_percent"},
    {TargetQuantity::kRelativeIllumination, "relative_illumination"},
    {TargetQuantity::kRmsSpotUm, "rms_spot_um"},
    {TargetQuantity::kRmsWavefrontWaves, "rms_wavefront_waves"},
    {TargetQuantity::kMtf, "mtf"},
    {TargetQuantity::kAngularMagnification, "angular_magnification"},
};

std::string trimmed(const std::string& s) {
  std::size_t a = 0, b = s.size();
  while (a < b && std::isspace(static_cast<unsigned char>(s[a]))) ++a;
  while (b > a && std::isspace(static_cast<unsigned char>(s[b - 1]))) --b;
  return s.substr(a, b - a);
}

double parse_number(const std::string& text, const std::string& what, const SourceLocation& where) {
  const std::string t = trimmed(text);
  std::size_t used = 0;
  double v = 0.0;
  try {
    v = std::stod(t, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (t.empty() || used != t.size() || !std::isfinite(v))
    throw Error(where, fmt::format("target: {} '{}' is not a finite number", what, t));
  return v;
}

const char* relation_text(TargetRelation r) {
  switch (r) {
    case TargetRelation::kEqual:
      return "=";
    case TargetRelation::kAtMost:
      return "<=";
    case TargetRelation::kAtLeast:
      return ">=";
  }
  return "?";
}

// A default target (DesignTarget::is_default) that holds the lens's own `value`, put first.
void hold_as_written(std::vector<DesignTarget>& out, TargetQuantity quantity, double value,
                     const char* where) {
  DesignTarget t;
  t.quantity = quantity;
  t.value = value;
  t.is_default = true;
  t.where = where;
  out.insert(out.begin(), t);
}

}  // namespace

const char* target_quantity_name(TargetQuantity q) {
  for (const QuantityName& n : kQuantityNames)
    if (n.quantity == q) return n.name;
  return "?";
}

const char* target_quantity_names() {
  return "efl_mm, f_number, total_track_mm, bfl_mm, distortion_percent, relative_illumination, "
         "rms_spot_um, rms_wavefront_waves, mtf, angular_magnification (afocal lenses)";
}

const char* mtf_orientation_name(MtfOrientation o) {
  switch (o) {
    case MtfOrientation::kTangential:
      return "tangential";
    case MtfOrientation::kSagittal:
      return "sagittal";
    case MtfOrientation::kAverage:
      return "average";
  }
  return "?";
}

MtfOrientation parse_mtf_orientation(const std::string& name, const SourceLocation& where) {
  if (name == "tangential" || name == "t" || name == "T") return MtfOrientation::kTangential;
  if (name == "sagittal" || name == "s" || name == "S") return MtfOrientation::kSagittal;
  if (name == "average" || name == "a" || name == "A") return MtfOrientation::kAverage;
  throw Error(where, fmt::format("mtf orientation '{}': write tangential, sagittal or average "
                                 "(of the two)",
                                 name));
}

bool same_target(const DesignTarget& a, const DesignTarget& b) {
  return a.quantity == b.quantity && a.field == b.field &&
         (a.quantity != TargetQuantity::kMtf ||
          (a.frequency_cpmm == b.frequency_cpmm && a.orientation == b.orientation));
}

TargetQuantity parse_target_quantity(const std::string& name, const SourceLocation& where) {
  for (const QuantityName& n : kQuantityNames)
    if (name == n.name) return n.quantity;
  throw Error(
      where, fmt::format("unknown target quantity '{}'; known: {}", name, target_quantity_names()));
}

std::string target_text(const DesignTarget& t) {
  std::string out = target_quantity_name(t.quantity);
  if (t.quantity == TargetQuantity::kMtf)
    out += fmt::format("({:g} c/mm, {})", t.frequency_cpmm, mtf_orientation_name(t.orientation));
  if (t.field > 0) out += fmt::format("[field {}]", t.field);
  out += fmt::format(" {} {:g}", relation_text(t.relation), t.value);
  if (t.weight != 1.0 && !target_is_solved(t.quantity))
    out += fmt::format(" (weight {:g})", t.weight);
  if (t.is_default) out += " (the lens's own)";
  return out;
}

void validate_target(const DesignTarget& t, const SourceLocation& where) {
  const std::string name = target_quantity_name(t.quantity);
  if (!std::isfinite(t.value))
    throw Error(where, fmt::format("target {}: the value must be a finite number", name));
  if (!(t.weight > 0.0) || !std::isfinite(t.weight))
    throw Error(where,
                fmt::format("target {}: weight = {} must be a finite number > 0", name, t.weight));
  if (t.field < 0)
    throw Error(where, fmt::format("target {}: field = {} must be >= 1", name, t.field));
  if (t.field > 0 && !target_per_field(t.quantity))
    throw Error(where, fmt::format("target {}: a whole-lens quantity has no field (fields apply "
                                   "to distortion_percent, relative_illumination, rms_spot_um, "
                                   "rms_wavefront_waves, mtf)",
                                   name));
  if (t.quantity == TargetQuantity::kMtf) {
    if (!(t.frequency_cpmm > 0.0) || !std::isfinite(t.frequency_cpmm))
      throw Error(where, fmt::format("target mtf: give its frequency in cycles/mm > 0 (freq=30 "
                                     "on the command line, frequency_cpmm = 30 in "
                                     "[[optimize.targets]]); got {:g}",
                                     t.frequency_cpmm));
    if (t.value < 0.0 || t.value > 1.0)
      throw Error(where, fmt::format("target mtf {:g}: an MTF lies in [0, 1]", t.value));
  } else if (t.frequency_cpmm != 0.0) {
    throw Error(where, fmt::format("target {}: a frequency applies to mtf targets only", name));
  }
  // A negative focal length is a diverging lens (a valid target: apply_target_solves says what
  // optimize can do with it); 0 is no lens.
  if (t.quantity == TargetQuantity::kEflMm && t.value == 0.0)
    throw Error(where, fmt::format("target {} = 0: a focal length must be nonzero (negative: a "
                                   "diverging lens)",
                                   name));
  if (t.quantity == TargetQuantity::kAngularMagnification && t.value == 0.0)
    throw Error(where, fmt::format("target {} = 0: an afocal lens's angular magnification must be "
                                   "nonzero (negative: an inverted image, a Keplerian telescope)",
                                   name));
  if (t.quantity == TargetQuantity::kFNumber && !(t.value > 0.0))
    throw Error(where, fmt::format("target {} = {:g}: must be > 0", name, t.value));
  if (t.quantity == TargetQuantity::kFNumber && t.value < 0.5)
    throw Error(where, fmt::format("target f_number = {:g}: an F-number below 0.5 is not a lens "
                                   "in air (n sin U <= 1)",
                                   t.value));
}

DesignTarget parse_target(const std::string& text, const SourceLocation& where, bool validate) {
  // NAME OP VALUE [, key=value ...]
  std::vector<std::string> parts;
  std::size_t start = 0;
  for (std::size_t i = 0; i <= text.size(); ++i) {
    if (i == text.size() || text[i] == ',') {
      parts.push_back(trimmed(text.substr(start, i - start)));
      start = i + 1;
    }
  }
  const std::string& head = parts[0];
  std::size_t op = head.find_first_of("<>=");
  if (op == std::string::npos || op == 0)
    throw Error(where, fmt::format("target '{}': write NAME=VALUE, NAME<=VALUE or NAME>=VALUE "
                                   "(e.g. efl_mm=100, \"distortion_percent<=1\"), optionally "
                                   "followed by ,weight=W ,field=N; quantities: {}",
                                   text, target_quantity_names()));
  DesignTarget t;
  t.where = where.file.empty() ? std::string("--target") : where.file;
  t.quantity = parse_target_quantity(trimmed(head.substr(0, op)), where);
  std::string rest = head.substr(op);
  if (rest.rfind("<=", 0) == 0) {
    t.relation = TargetRelation::kAtMost;
    rest = rest.substr(2);
  } else if (rest.rfind(">=", 0) == 0) {
    t.relation = TargetRelation::kAtLeast;
    rest = rest.substr(2);
  } else if (rest.rfind("==", 0) == 0) {
    rest = rest.substr(2);
  } else if (rest[0] == '=') {
    rest = rest.substr(1);
  } else {
    throw Error(where, fmt::format("target '{}': the relation must be =, <= or >= (a strict < or "
                                   "> is not a target a design can be held to)",
                                   text));
  }
  t.value = parse_number(rest, "value", where);
  for (std::size_t i = 1; i < parts.size(); ++i) {
    const std::size_t eq = parts[i].find('=');
    const std::string key = trimmed(parts[i].substr(0, eq));
    const bool mtf_key = key == "freq" || key == "frequency_cpmm" || key == "orientation";
    if (eq == std::string::npos || (key != "weight" && key != "field" && !mtf_key))
      throw Error(where, fmt::format("target '{}': '{}' must be weight=W, field=N, or for mtf "
                                     "freq=NU (cycles/mm) and orientation=tangential|sagittal|"
                                     "average",
                                     text, parts[i]));
    if (key == "orientation") {
      t.orientation = parse_mtf_orientation(trimmed(parts[i].substr(eq + 1)), where);
      continue;
    }
    const double v = parse_number(parts[i].substr(eq + 1), key, where);
    if (key == "freq" || key == "frequency_cpmm") {
      t.frequency_cpmm = v;
    } else if (key == "weight") {
      t.weight = v;
    } else {
      if (v != std::floor(v) || v < 1 || v > 1e6)
        throw Error(where,
                    fmt::format("target '{}': field = {:g} must be a field number >= 1", text, v));
      t.field = static_cast<int>(v);
    }
  }
  if (validate) validate_target(t, where);
  return t;
}

std::vector<DesignTarget> targets_with_defaults(const Lens& lens,
                                                const std::vector<DesignTarget>& given) {
  std::vector<DesignTarget> out = given;
  if (lens.specs.afocal) {
    // An afocal lens (analysis/afocal.h): no focal length and no image plane; its angular
    // magnification is held (by default its own) and its merit is the angular spot.
    const std::string where = lens.source_path.empty() ? lens.name : lens.source_path;
    bool has_magnification = false;
    for (const DesignTarget& t : given) {
      switch (t.quantity) {
        case TargetQuantity::kAngularMagnification:
          has_magnification = true;
          break;
        case TargetQuantity::kTotalTrackMm:
          break;
        case TargetQuantity::kEflMm:
        case TargetQuantity::kFNumber:
        case TargetQuantity::kBflMm:
          throw Error(SourceLocation{t.where},
                      fmt::format("target {}: {} is afocal (image at infinity) and has no focal "
                                  "length, F-number or back focal distance; hold its "
                                  "angular_magnification instead",
                                  target_text(t), where));
        default:
          throw Error(SourceLocation{t.where},
                      fmt::format("target {}: it is measured on an image plane, and {} is afocal "
                                  "(image at infinity, measured in angle: its merit is the RMS "
                                  "angular spot); the targets of an afocal lens are "
                                  "angular_magnification and total_track_mm",
                                  target_text(t), where));
      }
    }
    if (!has_magnification) {
      const TraceLens<double> traced = make_trace_lens(lens);
      const double m = paraxial_angular_magnification(traced, traced.reference_nm());
      if (std::isfinite(m) && m != 0.0)
        hold_as_written(out, TargetQuantity::kAngularMagnification, m,
                        "the lens's own angular magnification");
    }
    return out;
  }
  for (const DesignTarget& t : given)
    if (t.quantity == TargetQuantity::kAngularMagnification)
      throw Error(SourceLocation{t.where},
                  fmt::format("target {}: the angular magnification is a target of an afocal "
                              "lens ([system] afocal = true); a focusing lens holds its efl_mm",
                              target_text(t)));
  bool has_efl = false;
  for (const DesignTarget& t : given) has_efl = has_efl || t.quantity == TargetQuantity::kEflMm;
  if (!has_efl && lens.specs.mode == SpecMode::kAsWritten) {
    const double f = design_focal_length_mm(lens);
    if (std::isfinite(f) && f != 0.0)  // either sign (a diverging lens's is negative)
      hold_as_written(out, TargetQuantity::kEflMm, f, "the lens's own focal length");
  }
  return out;
}

void check_target_fields(const Lens& lens, const std::vector<DesignTarget>& targets) {
  const bool written = lens.specs.mode != SpecMode::kPaper && !lens.specs.fields.empty();
  int count = 0;
  if (written) {
    // The fields as lens_setup traces them and analyze lists them: one per radial value and
    // azimuth (a field on x is its own; one on -y too when the lens is not rotationally
    // symmetric), not the distinct |y| values (which missed the x fields).
    count = static_cast<int>(
        specs_setup(lens.specs, TraceOptions{}, !lens.breaks_symmetry()).field_values.size());
  }
  for (const DesignTarget& t : targets) {
    if (t.field == 0) continue;
    if (!written)
      throw Error(SourceLocation{t.where},
                  fmt::format("target {}: the lens has no written fields to number (a lens in "
                              "the paper's spec mode samples 0..hfov at the optimization's "
                              "count); drop the field (a bound then holds at every field)",
                              target_text(t)));
    if (t.field > count)
      throw Error(SourceLocation{t.where},
                  fmt::format("target {}: the lens has {} field{}", target_text(t), count,
                              count == 1 ? "" : "s"));
  }
}

Lens apply_target_solves(const Lens& lens, const std::vector<DesignTarget>& targets) {
  Lens out = lens;
  // An afocal lens's angular magnification: the last curvature solved for it on the start (the
  // optimizer then holds it, optimize/variables.h); a bound moves it to the nearest bound.
  for (const DesignTarget& t : targets) {
    if (t.quantity != TargetQuantity::kAngularMagnification || t.is_default) continue;
    if (!out.specs.afocal)
      throw Error(SourceLocation{t.where},
                  fmt::format("target {}: the lens is not afocal", target_text(t)));
    const TraceLens<double> traced = make_trace_lens(out);
    const double nm = traced.reference_nm();
    const double m = paraxial_angular_magnification(traced, nm);
    double goal = m;
    if (t.relation == TargetRelation::kEqual) goal = t.value;
    if (t.relation == TargetRelation::kAtMost) goal = std::min(m, t.value);
    if (t.relation == TargetRelation::kAtLeast) goal = std::max(m, t.value);
    if (goal == m) continue;
    const int last = traced.surface_count() - 1;
    if (last < 1 || out.surfaces[last - 1].material.is_air())
      throw Error(SourceLocation{t.where},
                  fmt::format("target {}: the last surface must end a glass element (its "
                              "curvature is solved for the angular magnification)",
                              target_text(t)));
    const double c = solve_last_curvature_for_angular_magnification(traced, goal, nm);
    if (!std::isfinite(c))
      throw Error(SourceLocation{t.where},
                  fmt::format("target {}: the last curvature cannot give it (the paraxial chief "
                              "ray crosses the axis at the last surface)",
                              target_text(t)));
    out.surfaces[last].curvature_per_mm = c;
  }
  // efl_mm first (the F-number's EPD follows the focal length).
  for (const DesignTarget& t : targets) {
    if (t.quantity != TargetQuantity::kEflMm || t.is_default) continue;
    const double f = design_focal_length_mm(out);
    if (!std::isfinite(f) || f == 0.0)
      throw Error(SourceLocation{t.where},
                  fmt::format("target {}: the lens's focal length is {:g} mm (afocal: no focal "
                              "length to scale)",
                              target_text(t), f));
    double goal = f;
    if (t.relation == TargetRelation::kEqual) goal = t.value;
    if (t.relation == TargetRelation::kAtMost) goal = std::min(f, t.value);
    if (t.relation == TargetRelation::kAtLeast) goal = std::max(f, t.value);
    // A diverging lens reaches any negative focal length by scaling (optimize/virtual_image.h);
    // no scaling carries a lens's power through zero.
    if (!(goal * f > 0.0))
      throw Error(SourceLocation{t.where},
                  fmt::format("target {}: the lens's focal length is {:.6g} mm; a focal length of "
                              "the other sign would carry the lens's power through zero (no "
                              "continuous change of a {} lens reaches it); start from a {} lens",
                              target_text(t), f, f > 0.0 ? "converging" : "diverging",
                              f > 0.0 ? "diverging" : "converging"));
    if (out.specs.mode == SpecMode::kPaper) {
      // The paper's spec focal length is d / (2 tan hfov): the sensor diagonal follows it.
      out.specs.sensor_diagonal_mm = 2.0 * goal * std::tan(out.specs.half_field_deg * kPi / 180.0);
    } else if (goal != f) {
      out = scaled(out, goal / f);
    }
  }
  for (const DesignTarget& t : targets) {
    if (t.quantity != TargetQuantity::kFNumber) continue;
    const double f = design_focal_length_mm(out);
    if (f < 0.0)
      throw Error(SourceLocation{t.where},
                  fmt::format("target {}: the lens is diverging (EFL {:.6g} mm), its F-number "
                              "EFL / EPD is negative and no working F-number is defined for a "
                              "virtual image; set the entrance pupil diameter ([system] aperture "
                              "= \"epd\") instead",
                              target_text(t), f));
    double current = out.specs.f_number;
    if (out.specs.mode != SpecMode::kPaper) {
      const TraceSystem<double> sys = prepare_lens_system(out, TraceOptions{});
      current = sys.efl_mm / sys.epd_mm;
    }
    double goal = current;
    if (t.relation == TargetRelation::kEqual) goal = t.value;
    if (t.relation == TargetRelation::kAtMost) goal = std::min(current, t.value);
    if (t.relation == TargetRelation::kAtLeast) goal = std::max(current, t.value);
    if (out.specs.mode == SpecMode::kPaper) {
      out.specs.f_number = goal;
    } else if (out.specs.aperture_type == ApertureType::kFNumber) {
      out.specs.f_number = goal;  // EPD = EFL / N already
    } else if (goal != current) {
      // The pickup EPD = f / N (held with the focal length).
      out.specs.aperture_type = ApertureType::kEntrancePupilDiameter;
      out.specs.aperture_value = f / goal;
      out.specs.f_number = goal;
    }
  }
  return out;
}

int target_residual_count(const std::vector<DesignTarget>& targets, int field_count) {
  int n = 0;
  for (const DesignTarget& t : targets) n += target_residual_count(t, field_count);
  return n;
}

double target_unit_mm(TargetQuantity q, double signed_focal_length_mm, double wave_unit_mm) {
  const double focal_length_mm = std::abs(signed_focal_length_mm);  // a diverging lens's |f|
  switch (q) {
    case TargetQuantity::kEflMm:
    case TargetQuantity::kTotalTrackMm:
    case TargetQuantity::kBflMm:
    case TargetQuantity::kAngularMagnification:  // solved: no residual
      return 1.0;
    case TargetQuantity::kFNumber:
      return focal_length_mm / 100.0;
    case TargetQuantity::kDistortionPercent:
      return focal_length_mm / 100.0;
    case TargetQuantity::kRelativeIllumination:
      return focal_length_mm;
    case TargetQuantity::kRmsSpotUm:
      return 1e-3;
    case TargetQuantity::kRmsWavefrontWaves:
      return wave_unit_mm > 0.0 ? wave_unit_mm : 1e-3;
    case TargetQuantity::kMtf:
      return 1e-3;  // per target: 1 / (frequency), set by target_unit_mm(DesignTarget, ...)
  }
  return 1.0;
}

double target_unit_mm(const DesignTarget& t, double focal_length_mm, double wave_unit_mm) {
  // An MTF change of 0.1 at nu weighs as 0.1 / nu mm of spot: one cycle's length per unit.
  if (t.quantity == TargetQuantity::kMtf) return 1.0 / t.frequency_cpmm;
  return target_unit_mm(t.quantity, focal_length_mm, wave_unit_mm);
}

bool target_passes(const DesignTarget& t, double value) {
  if (!std::isfinite(value)) return false;
  switch (t.relation) {
    case TargetRelation::kEqual:
      return std::abs(value - t.value) <= target_tolerance(t);
    case TargetRelation::kAtMost:
      return value <= t.value;
    case TargetRelation::kAtLeast:
      return value >= t.value;
  }
  return false;
}

bool TargetReport::all_pass() const {
  for (const TargetRow& r : rows)
    if (!r.pass) return false;
  return true;
}

TargetReport check_targets(const Lens& lens, const std::vector<DesignTarget>& targets,
                           const TraceOptions& sampling) {
  TargetReport report;
  if (targets.empty()) return report;
  TargetValues<double> values;
  bool traced = true;
  try {
    const TraceSystem<double> sys = prepare_lens_system(lens, sampling);
    TargetSampling ts;
    ts.wavefront_grid = make_pupil_grid(32);
    ts.threads = sampling.threads;
    values = measure_targets(sys, targets, ts);
  } catch (const Error&) {
    traced = false;
  }
  for (std::size_t i = 0; i < targets.size(); ++i) {
    TargetRow row;
    row.target = targets[i];
    double v = std::numeric_limits<double>::quiet_NaN();
    if (traced) {
      bool known = false;
      for (char k : values.item_known[i]) known = known || k;
      if (known) v = values.value[i];
    }
    row.value = v;
    row.pass = target_passes(row.target, v);
    // A per-field bound holds at every known field (the value is the worst of them).
    if (traced && row.pass && values.items[i].size() > 1) {
      for (std::size_t j = 0; j < values.items[i].size(); ++j)
        if (values.item_known[i][j] && !target_passes(row.target, values.items[i][j]))
          row.pass = false;
    }
    report.rows.push_back(row);
  }
  return report;
}

}  // namespace lensopt
