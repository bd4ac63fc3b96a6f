// Zemax .zmx import (include/lensopt/formats/zmx.h states the mapping): parse() builds the lens
// from the file's lines in named steps: the surfaces and their glasses, the wavelengths, the
// fields, the aperture, and the summary specs from the paraxial system.
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <filesystem>

#include "lensopt/core/atomic_file.h"
#include "lensopt/core/text.h"
#include "lensopt/trace/system.h"
#include "zmx_parser.h"

namespace lensopt {
namespace zmx_detail {

ZmxImport ZmxParser::parse(std::string_view bytes) {
  const std::string text = decode_text(bytes);
  const std::vector<Line> lines = split_lines(text);  // views into `text`
  read_lines(lines);
  last_line_ = lines.empty() ? 1 : lines.back().number;
  check_object_and_image();

  ZmxImport result;
  Lens& lens = result.lens;
  lens.source_path = file_;
  lens.name = has_name_ && !name_.empty() ? name_ : std::filesystem::path(file_).stem().string();
  const LensSourceLines source_lines = build_surfaces(lens);
  set_wavelengths(lens.specs);
  set_fields(lens.specs);
  set_aperture(lens);
  lens.specs.afocal = ftyp_afocal_;
  lens.specs.half_field_deg =
      lens.specs.field_type == FieldType::kAngle ? lens.specs.max_field_value() : 0.0;
  validate(lens, source_lines);
  set_summary_specs(lens);
  apply_lensopt_notes(lens);
  validate(lens, source_lines);

  report_ignored();
  result.warnings = std::move(warnings_);
  return result;
}

// Every line: SURF opens a surface block; a surface's keys go to it, the rest are system keys.
void ZmxParser::read_lines(const std::vector<Line>& lines) {
  for (const Line& line : lines) {
    if (line.fields.empty()) continue;
    const char first = line.fields[0].front();
    if (first == '!' || first == '#') continue;  // a comment line
    const std::string key = upper(line.fields[0]);
    if (key == "SURF") {
      RawSurface s;
      s.number = integer(line, 1, "the surface number");
      s.line = line.number;
      if (s.number > static_cast<int>(kMaxSurfaces) + 1)
        fail(line, 1,
             fmt::format("SURF {}: lensopt reads at most {} lens surfaces (between the object, "
                         "SURF 0, and the image)",
                         s.number, kMaxSurfaces));
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
}

// The object must be air at a positive distance or at infinity; the image a flat plane; neither
// the stop.
void ZmxParser::check_object_and_image() const {
  if (surfaces_.size() < 4)
    fail_at(last_line_, 1,
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
}

// The lens surfaces (SURF 1 .. N-1) in mm, with their glasses resolved; a STOP on a curved
// surface becomes a flat stop surface before it. Returns the file lines of the lens's surfaces.
LensSourceLines ZmxParser::build_surfaces(Lens& lens) {
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
  lens.specs.dispersion = dispersion;

  LensSourceLines source_lines;
  std::vector<std::string> used_catalogs;
  int stop_count = 0;
  // The lens surface of each .zmx surface (-1: the object, the image), for pickups.
  std::vector<int> lens_index(surfaces_.size(), -1);
  for (std::size_t k = 1; k + 1 < surfaces_.size(); ++k) {
    const RawSurface& raw = surfaces_[k];
    if (raw.thickness_infinite)
      fail_at(raw.disz_line, 1, fmt::format("surface {} has an infinite thickness", raw.number));
    Surface surface;
    const Material before = lens.surfaces.empty() ? Material::air() : lens.surfaces.back().material;
    if (raw.scbd_line > 0)
      fail_at(raw.scbd_line, 1,
              fmt::format("surface {}: a surface's own tilt/decenter (SCBD) is read on the image "
                          "surface only; write it as COORDBRK surfaces around surface {}",
                          raw.number, raw.number));
    if (raw.coordinate_break) {
      // COORDBRK: a dummy surface that moves the frame of what follows (lens.h Placement).
      if (raw.is_stop)
        fail_at(raw.stop_line, 1,
                fmt::format("surface {} is a coordinate break and cannot be the stop", raw.number));
      surface.coordinate_break = true;
      surface.placement = Placement{
          raw.parm[1] * unit_mm_, raw.parm[2] * unit_mm_, raw.parm[3], raw.parm[4], raw.parm[5],
          raw.parm[6] != 0.0};
      surface.thickness_mm = raw.thickness_mm * unit_mm_;
      surface.material = before;
      breaks_symmetry_ = true;
      lens_index[k] = static_cast<int>(lens.surfaces.size());
      lens.surfaces.push_back(surface);
      source_lines.surfaces.push_back(raw.line);
      continue;
    }
    surface.curvature_per_mm = raw.curvature_per_mm / unit_mm_;
    surface.thickness_mm = raw.thickness_mm * unit_mm_;
    surface.semi_diameter_mm = raw.semi_diameter_mm * unit_mm_;
    // Surface apertures: CLAP (a circular aperture: rmax clips, rmin > 0 obscures the centre),
    // OBSC (a circular obscuration from the centre), OBDC their decenter.
    if (raw.clap_line > 0) {
      surface.semi_diameter_mm = raw.clap_max * unit_mm_;
      surface.obscuration_mm = raw.clap_min * unit_mm_;
    }
    if (raw.obsc_line > 0) {
      if (raw.obsc_min > 0.0)
        fail_at(raw.obsc_line, 1,
                fmt::format("surface {}: an annular obscuration (OBSC with a minimum radius {}) "
                            "is not supported; lensopt's obscuration is central",
                            raw.number, raw.obsc_min));
      surface.obscuration_mm = std::max(surface.obscuration_mm, raw.obsc_max * unit_mm_);
    }
    surface.aperture_decenter_x_mm = raw.obdc_x * unit_mm_;
    surface.aperture_decenter_y_mm = raw.obdc_y * unit_mm_;
    if (raw.obdc_x != 0.0 || raw.obdc_y != 0.0) breaks_symmetry_ = true;
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
    if (raw.mirror) {
      // GLAS MIRROR: the medium before continues, traversed backwards (thicknesses negative).
      surface.mirror = true;
      surface.material = before;
    }
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
    lens_index[k] = static_cast<int>(lens.surfaces.size());
    lens.surfaces.push_back(surface);
    source_lines.surfaces.push_back(raw.line);
  }
  if (const RawSurface& image = surfaces_.back(); image.scbd_line > 0) {
    // The image surface's own tilt/decenter: "SCBD 1 order 0 dx dy tx ty tz" (the form
    // OpticStudio writes for a before-surface tilt), a coordinate break at the image vertex.
    const double* v = image.scbd;
    if (v[0] != 1.0 || v[2] != 0.0)
      fail_at(image.scbd_line, 1,
              fmt::format("image surface: SCBD {} {} {} ... is a form lensopt does not read (it "
                          "reads 'SCBD 1 order 0 dx dy tx ty tz')",
                          v[0], v[1], v[2]));
    if (Placement p{v[3] * unit_mm_, v[4] * unit_mm_, v[5], v[6], v[7], v[1] != 0.0}; p.any()) {
      Surface cb;
      cb.coordinate_break = true;
      cb.placement = p;
      cb.material = lens.surfaces.back().material;
      lens.surfaces.push_back(cb);
      source_lines.surfaces.push_back(image.line);
      breaks_symmetry_ = true;
    }
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
      for (int& i : lens_index)
        if (i >= 0) ++i;
    }
  }
  set_solves(lens, lens_index);
  if (!lens.surfaces.back().material.is_air()) {
    const RawSurface& raw = surfaces_[surfaces_.size() - 2];
    fail_at(raw.glas_line, raw.glas_column,
            fmt::format("surface {} (the last before the image) must be followed by air, not {}",
                        raw.number, raw.glass));
  }
  if (gcat_.empty() && !note_catalog_ && !used_catalogs.empty())
    warn(0, fmt::format("the file has no GCAT line: its glasses come from {}, OpticStudio's "
                        "default catalog",
                        used_catalogs.front()));
  if (!used_catalogs.empty()) {
    lens.catalog_name = note_catalog_ && std::find(used_catalogs.begin(), used_catalogs.end(),
                                                   *note_catalog_) != used_catalogs.end()
                            ? *note_catalog_
                            : used_catalogs.front();
    // Glasses of the other catalogs keep theirs (a TOML material { glass, catalog }).
  } else if (note_catalog_) {
    lens.catalog_name = *note_catalog_;
  }
  return source_lines;
}

void ZmxParser::set_wavelengths(Specs& specs) {
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
    fail_at(wavelength_line_ > 0 ? wavelength_line_ : last_line_, 1,
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
  if (std::all_of(weights.begin(), weights.end(), [](double w) { return w == 0.0; }))
    fail_at(waves.front().line, 1,
            "every active wavelength has weight 0: no wavelength would count; give at least one "
            "a positive weight");
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
  specs.wavelengths_nm = wavelengths_nm;
  if (!equal_weights) specs.wavelength_weights = weights;
  // The primary wavelength: PWAV's (OpticStudio's paraxial reference), else the note's.
  if (pwav_ > 0 && static_cast<std::size_t>(pwav_) <= wavelengths_nm.size()) {
    specs.primary_wavelength_nm = wavelengths_nm[static_cast<std::size_t>(pwav_) - 1];
  } else if (pwav_ > 0) {
    fail_at(pwav_line_, 2,
            fmt::format("PWAV {} names no active wavelength ({} are active)", pwav_,
                        wavelengths_nm.size()));
  } else {
    specs.primary_wavelength_nm = wavelengths_nm.front();
  }
  if (note_primary_nm_) specs.primary_wavelength_nm = *note_primary_nm_;
  if (note_channels_ && note_channels_->size() == wavelengths_nm.size()) {
    specs.wavelength_channels = *note_channels_;
  } else {
    specs.wavelength_channels = default_wavelength_channels(wavelengths_nm);
    std::vector<std::string> assigned;
    for (std::size_t i = 0; i < wavelengths_nm.size(); ++i)
      assigned.push_back(
          fmt::format("{} nm {}", wavelengths_nm[i],
                      kChannelLetters[static_cast<std::size_t>(specs.wavelength_channels[i])]));
    warn(wavelength_line_,
         fmt::format("colour channels assigned by wavelength (< 500 nm B, < 600 nm G, else R; an "
                     "empty channel borrows the nearest wavelength): {}",
                     fmt::join(assigned, ", ")));
  }
}

void ZmxParser::set_fields(Specs& specs) {
  const RawSurface& object = surfaces_.front();
  // Fields: the active ones, (x, y) as written (on the y axis of a rotationally symmetric lens
  // |y|), with their weights and vignetting factors.
  std::size_t field_count = std::max(xfln_.size(), yfln_.size());
  if (field_count_ >= 0)
    field_count = std::min(field_count, static_cast<std::size_t>(field_count_));
  if (field_count == 0) field_count = 1;
  specs.field_type = static_cast<FieldType>(field_type_);
  specs.fields.clear();
  auto factor = [&](const char* key, std::size_t i) {
    const auto it = vignetting_.find(key);
    return it != vignetting_.end() && i < it->second.size() ? it->second[i] : 0.0;
  };
  for (std::size_t i = 0; i < field_count; ++i) {
    const double x = i < xfln_.size() ? xfln_[i] : 0.0;
    const double y = i < yfln_.size() ? yfln_[i] : 0.0;
    // A field off the y axis keeps its x and y (FieldPoint: traced in the frame turned about z
    // to put it on +y); on the y axis a rotationally symmetric lens takes |y| (a field on -y is
    // the mirror of one on +y), a lens without that symmetry keeps y < 0 (turned by 180 deg).
    FieldPoint f;
    const bool turned = x != 0.0 || (breaks_symmetry_ && y < 0.0);
    f.value = turned ? y : std::abs(y);
    f.x = x;
    f.weight = i < field_weights_.size() ? field_weights_[i] : 1.0;
    // OpticStudio's factors are in the pupil's x, y; lensopt's in the frame where the field lies
    // on +y (lens.h: the pupil ellipse D + R(VAN) C, D = (VDX, VDY), C = diag(1 - VCX, 1 - VCY)).
    // A field on -y mirrors y (M = diag(1, -1): M D, and M R(a) C = R(-a) C M, so VAN -> -VAN);
    // a field on +-x turns the pupil by a quarter turn Q (y' = +-x, x' = -+y: VDY' = +-VDX,
    // VDX' = -+VDY; Q R(a) C = R(a) Q C Q^T Q with Q C Q^T = diag(1 - VCY, 1 - VCX): VCX and VCY
    // swap, VAN stays); a field off the axes (or on -y of a lens without rotational symmetry)
    // turns by the angle b that takes it to +y (R(b): D' = R(b) D, VAN' = VAN + b, C stays).
    // zmx_write.cpp inverts this.
    const double vdx = factor("VDXN", i), vdy = factor("VDYN", i);
    const double vcx = factor("VCXN", i), vcy = factor("VCYN", i);
    const double van = factor("VANN", i);
    if (x == 0.0 && !turned) {
      f.vignetting.vdx = vdx;
      f.vignetting.vdy = y < 0.0 ? -vdy : vdy;
      f.vignetting.vcx = vcx;
      f.vignetting.vcy = vcy;
      f.vignetting.van_deg = y < 0.0 ? -van : van;
    } else if (y == 0.0) {
      const double s = x > 0.0 ? 1.0 : -1.0;
      f.vignetting.vdx = -s * vdy;
      f.vignetting.vdy = s * vdx;
      f.vignetting.vcx = vcy;
      f.vignetting.vcy = vcx;
      f.vignetting.van_deg = van;
    } else {
      f.vignetting.vcx = vcx;
      f.vignetting.vcy = vcy;
      f.vignetting.van_deg = van;
      f.vignetting.vdx = vdx;
      f.vignetting.vdy = vdy;
      if (f.vignetting.any()) {
        const double b = kPi / 2.0 - std::atan2(y, x);  // R(b) (x, y) = (0, hypot(x, y))
        const double c = std::cos(b), sb = std::sin(b);
        f.vignetting.vdx = c * vdx - sb * vdy;
        f.vignetting.vdy = sb * vdx + c * vdy;
        f.vignetting.van_deg = van + b * 180.0 / kPi;
      }
    }
    if (!(f.vignetting.vcx < 1.0) || !(f.vignetting.vcy < 1.0))
      fail_at(yfln_line_ > 0 ? yfln_line_ : last_line_, 1,
              fmt::format("field {}: vignetting compression VCX, VCY must be < 1", i + 1));
    specs.fields.push_back(f);
  }
  if (std::all_of(specs.fields.begin(), specs.fields.end(),
                  [](const FieldPoint& f) { return f.weight == 0.0; }))
    fail_at(fwgn_line_ > 0 ? fwgn_line_ : last_line_, 1,
            "every active field has weight 0 (FWGN): no field would count; give at least one a "
            "positive weight");
  if (!object.thickness_infinite) specs.object_distance_mm = object.thickness_mm * unit_mm_;
  if (specs.field_type == FieldType::kObjectHeight && specs.object_at_infinity())
    fail_at(ftyp_line_, 1, "object-height fields (FTYP 1) need a finite object distance");
  if (specs.field_type == FieldType::kAngle) {
    for (const FieldPoint& f : specs.fields)
      if (!(f.radius() < 89.0))
        fail_at(yfln_line_ > 0 ? yfln_line_ : last_line_, 1,
                fmt::format("the field {} deg must be less than 89", f.radius()));
  } else {
    for (FieldPoint& f : specs.fields) {
      f.value *= unit_mm_;
      f.x *= unit_mm_;
    }
  }
}

void ZmxParser::set_aperture(Lens& lens) {
  // Aperture.
  if (!fnum_ && !enpd_ && !obna_ && !floa_)
    fail_at(last_line_, 1,
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
}

void ZmxParser::set_summary_specs(Lens& lens) {
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
    fail_at(yfln_line_ > 0 ? yfln_line_ : last_line_, 1,
            fmt::format("the largest field is {} deg; lensopt needs less than 89", half_field_deg));
  lens.specs.half_field_deg = half_field_deg;
  // Any sign of power: a diverging lens (EFL < 0, a virtual image) is as valid as a converging
  // one; the summary F-number and sensor use |EFL|. An afocal lens (FTYP's afocal flag, or no
  // finite focal length: |EFL| beyond kMaxFocalLengthMm) has neither: its image space is in
  // angle (analysis/afocal.h). A file that does not set the flag is read as afocal when its
  // paraxial EFL says so (OpticStudio would measure it on the image surface as written, where
  // its collimated output has no focus), and a warning says so.
  const bool afocal_power = !std::isfinite(efl_mm) || !(std::abs(efl_mm) <= kMaxFocalLengthMm);
  if (lens.specs.afocal || afocal_power) {
    if (!lens.specs.afocal) {
      warn(ftyp_line_ > 0 ? ftyp_line_ : aperture_line_,
           fmt::format("the lens is afocal (paraxial EFL {:g} mm, beyond {:g} mm) but the file "
                       "does not set Afocal Image Space (FTYP's seventh value): read in afocal "
                       "mode, image space in angle",
                       efl_mm, kMaxFocalLengthMm));
      lens.specs.afocal = true;
      if (lens.specs.aperture_type == ApertureType::kFNumber)
        fail_at(aperture_line_, 1,
                fmt::format("the lens is afocal (paraxial EFL {:g} mm) and has no F-number: "
                            "its aperture must be ENPD, OBNA or FLOA",
                            efl_mm));
    }
    return;
  }
  const double abs_efl_mm = std::abs(efl_mm);
  if (!fnum_) lens.specs.f_number = abs_efl_mm / sys.epd_mm;
  if (note_sensor_mm_) {
    lens.specs.sensor_diagonal_mm = *note_sensor_mm_;
  } else if (half_field_deg > 0.0) {
    lens.specs.sensor_diagonal_mm = 2.0 * abs_efl_mm * std::tan(half_field_deg * kPi / 180.0);
  }
}

// What lensopt wrote in NOTE lines and Zemax cannot say: the paper's spec mode, extra TOML.
void ZmxParser::apply_lensopt_notes(Lens& lens) const {
  if (note_mode_paper_) {
    // Written by lensopt from a lens in the paper's mode: its specs are f/#, hfov and sensor.
    lens.specs.mode = SpecMode::kPaper;
    lens.specs.fields.clear();
    lens.specs.field_type = FieldType::kAngle;
    lens.specs.aperture_type = ApertureType::kFNumber;
    lens.specs.aperture_value = 0.0;
  }
  lens.extra_toml = note_toml_;
}

// validate_lens, its errors at the .zmx file's lines.
void ZmxParser::validate(const Lens& lens, const LensSourceLines& source_lines) const {
  try {
    validate_lens(lens, source_lines);
  } catch (const Error& error) {
    throw Error(SourceLocation{file_, error.where().line}, error.message());
  }
}

// Variables, pickups and solves of the .zmx surfaces onto the lens surfaces (RawSurface).
// What lensopt cannot represent is said (file:line) and the written value kept, fixed.
void ZmxParser::set_solves(Lens& lens, const std::vector<int>& lens_index) {
  const int raw_count = static_cast<int>(surfaces_.size());
  const int last = static_cast<int>(lens.surfaces.size()) - 1;
  auto source_of = [&](int raw_source, int line, int number, const char* what) {
    const int i = raw_source >= 0 && raw_source < raw_count ? lens_index[raw_source] : -1;
    if (i < 0)
      warn(line, fmt::format("surface {}: the {} pickup's source, surface {}, is {}; the written "
                             "value is kept, fixed",
                             number, what, raw_source,
                             raw_source == 0 ? "the object" : "not a lens surface"));
    return i;
  };
  for (int k = 1; k + 1 < raw_count; ++k) {
    const RawSurface& raw = surfaces_[k];
    const int i = lens_index[k];
    if (i < 0) continue;
    Surface& s = lens.surfaces[i];
    if (raw.curvature_variable && !raw.coordinate_break && !s.is_stop) s.vary.radius = true;
    if (raw.curvature_pickup_source >= 0) {
      const int source =
          source_of(raw.curvature_pickup_source, raw.curv_line, raw.number, "curvature");
      if (source >= 0 && source < i && !s.is_stop) {
        s.curvature_pickup.source = source;
        s.curvature_pickup.scale = raw.curvature_pickup_scale;
      } else if (source >= 0) {
        warn(raw.curv_line, fmt::format("surface {}: a curvature pickup from surface {} (not an "
                                        "earlier curved surface) is not supported; the written "
                                        "curvature is kept, fixed",
                                        raw.number, raw.curvature_pickup_source));
      }
    }
    if (raw.thickness_pickup_source >= 0) {
      const int source =
          source_of(raw.thickness_pickup_source, raw.pzup_line, raw.number, "thickness");
      if (source >= 0 && source < i) {
        s.thickness_pickup.source = source;
        s.thickness_pickup.scale = raw.thickness_pickup_scale;
        s.thickness_pickup.offset_mm = raw.thickness_pickup_offset * unit_mm_;
      } else if (source >= 0) {
        warn(raw.pzup_line, fmt::format("surface {}: a thickness pickup from a later surface ({}) "
                                        "is not supported; the written thickness is kept, fixed",
                                        raw.number, raw.thickness_pickup_source));
      }
    }
    if (raw.marginal_height_solve) {
      if (s.thickness_pickup.active()) {
        warn(raw.mazh_line, fmt::format("surface {}: the thickness has a pickup and a marginal-"
                                        "ray-height solve; the solve is ignored",
                                        raw.number));
      } else if (raw.marginal_height != 0.0 && i != last) {
        warn(raw.mazh_line,
             fmt::format("surface {}: a marginal-ray-height solve with a nonzero height is read "
                         "on the last thickness only; the written thickness is kept, fixed",
                         raw.number));
      } else {
        s.thickness_solve.kind = ThicknessSolve::Kind::kMarginalHeight;
        s.thickness_solve.height_mm = raw.marginal_height * unit_mm_;
      }
    }
  }
  for (const VaryNote& note : note_vary_) {
    const int i = note.surface >= 0 && note.surface < raw_count ? lens_index[note.surface] : -1;
    if (i < 0) {
      warn(note.line,
           fmt::format("a lensopt vary note names surface {}, not a lens surface; ignored",
                       note.surface));
      continue;
    }
    VaryFlags& f = lens.surfaces[i].vary;
    f.radius = f.radius || note.flags.radius;
    f.thickness = f.thickness || note.flags.thickness;
    f.conic = f.conic || note.flags.conic;
    f.glass = f.glass || note.flags.glass;
  }
}

}  // namespace zmx_detail

ZmxImport parse_zmx(std::string_view bytes, const std::string& source_name) {
  return zmx_detail::ZmxParser(source_name).parse(bytes);
}

ZmxImport read_zmx(const std::filesystem::path& path) {
  return parse_zmx(read_file(path), path.string());
}

}  // namespace lensopt
