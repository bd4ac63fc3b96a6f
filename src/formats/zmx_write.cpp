// Zemax .zmx export (include/lensopt/formats/zmx.h): ASCII, CRLF line ends, every number the
// shortest decimal that reads back to the same double (zmx_text.h).
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <set>

#include "lensopt/analysis/apertures.h"
#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/formats/zmx.h"
#include "lensopt/glass/glass.h"
#include "zmx_text.h"

namespace lensopt {

using zmx_detail::kChannelLetters;
using zmx_detail::micrometre_text;
using zmx_detail::number_text;
using zmx_detail::upper;

std::string zemax_catalog_name(std::string_view catalog_name) {
  if (upper(catalog_name) == "OHARA") return "OHARA";
  const std::filesystem::path path{std::string(catalog_name)};
  if (path.has_parent_path() || path.has_extension()) return path.stem().string();
  return std::string(catalog_name);
}

std::vector<std::string> zmx_gcat_names(const Lens& lens) {
  std::vector<std::string> gcat;
  auto add_catalog = [&gcat](const std::string& zemax_name) {
    if (!zemax_name.empty() && std::find(gcat.begin(), gcat.end(), zemax_name) == gcat.end())
      gcat.push_back(zemax_name);
  };
  std::vector<const Surface*> glasses;
  for (const Surface& s : lens.surfaces)
    if (s.material.kind == Material::Kind::kCatalog) glasses.push_back(&s);
  if (glasses.empty()) return gcat;
  // The catalogs a reader searches, in order: the lens's own (the lensopt note names it, so
  // lensopt loads it under that name, "ohara" being the paper's 65 glasses), then the GCAT list.
  std::vector<std::shared_ptr<const Catalog>> searched;
  auto load = [](const std::string& name) -> std::shared_ptr<const Catalog> {
    try {
      return load_catalog(name);
    } catch (const Error&) {
      return nullptr;
    }
  };
  if (!lens.catalog_name.empty()) {
    add_catalog(zemax_catalog_name(lens.catalog_name));
    searched.push_back(load(lens.catalog_name));
    searched.push_back(load(gcat.back()));
  }
  for (const Surface* s : glasses) {
    const Glass* glass = s->material.glass.get();
    if (glass == nullptr) continue;
    // The glass's own catalog, unless one searched already holds this very glass.
    const bool found = std::any_of(searched.begin(), searched.end(), [&](const auto& catalog) {
      return catalog && catalog->name == glass->catalog && catalog->find(glass->name) != nullptr;
    });
    if (found) continue;
    const std::size_t before = gcat.size();
    add_catalog(zemax_catalog_name(glass->catalog));
    if (gcat.size() > before) searched.push_back(load(gcat.back()));
  }
  // Each glass must read back as itself: the first catalog searched that has its name is its own
  // (same catalog, same figures). A name that an earlier catalog also holds cannot be written.
  int number = 0;
  for (const Surface& s : lens.surfaces) {
    ++number;
    if (s.material.kind != Material::Kind::kCatalog || !s.material.glass) continue;
    const Glass& glass = *s.material.glass;
    const bool readable = std::any_of(searched.begin(), searched.end(), [&](const auto& catalog) {
      return catalog && catalog->find(glass.name) != nullptr;
    });
    if (!readable)
      throw Error(
          fmt::format("lens '{}': surface {}: glass {} of catalog {}: no catalog of GCAT "
                      "{} holds it, so the .zmx would not read back",
                      lens.name, number, glass.name, glass.catalog, fmt::join(gcat, " ")));
    for (const auto& catalog : searched) {
      if (!catalog) continue;
      const Glass* first = catalog->find(glass.name);
      if (first == nullptr) continue;
      if (catalog->name != glass.catalog || first->nd != glass.nd || first->vd != glass.vd ||
          first->coefficients != glass.coefficients)
        throw Error(fmt::format(
            "lens '{}': surface {}: glass {} of catalog {} would read back from catalog {} "
            "(GCAT {}), which has a glass of that name: a .zmx names glasses by name only",
            lens.name, number, glass.name, glass.catalog, catalog->name, fmt::join(gcat, " ")));
      break;
    }
  }
  return gcat;
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
  // The paper's model glasses: OpticStudio reads ___BLANK as its own model glass (nd exact at
  // 587.5618 nm); lensopt reading this file back keeps the paper's (nd at 587.6 nm).
  // (Only when every model glass is the paper's: a .zmx has no per-surface model.)
  const auto is_model = [](const Surface& s) { return s.material.kind == Material::Kind::kModel; };
  const bool paper_model_glass =
      std::any_of(lens.surfaces.begin(), lens.surfaces.end(), is_model) &&
      std::all_of(lens.surfaces.begin(), lens.surfaces.end(), [&](const Surface& s) {
        return !is_model(s) || s.material.model_glass == ModelGlass::kPaper;
      });
  if (paper_model_glass) line("NOTE 0 lensopt model_glass paper");
  line("NOTE 0 lensopt primary_wavelength_nm " + number_text(specs.primary_wavelength_nm));
  // Vary flags (lens.h): the curvature's is the CURV line's variable flag too; the others
  // have no field lensopt writes, so a note keeps them for the round trip.
  for (std::size_t k = 0; k < lens.surfaces.size(); ++k) {
    const VaryFlags& f = lens.surfaces[k].vary;
    if (!f.any()) continue;
    line(fmt::format("NOTE 0 lensopt vary {}{}{}{}{}", k + 1, f.radius ? " radius" : "",
                     f.thickness ? " thickness" : "", f.conic ? " conic" : "",
                     f.glass ? " glass" : ""));
  }
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

  // Catalogs: the lens's, then every other one its glasses come from (zmx_gcat_names).
  const std::vector<std::string> gcat = zmx_gcat_names(lens);
  if (!gcat.empty()) line(fmt::format("GCAT {}", fmt::join(gcat, " ")));

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
  std::vector<std::string> x_texts, y_texts, weight_texts, vdx, vdy, vcx, vcy, van;
  bool vignetting = false;
  for (const FieldPoint& f : fields) {
    x_texts.push_back(number_text(f.x));
    y_texts.push_back(number_text(f.value));
    weight_texts.push_back(number_text(f.weight));
    // The factors are in the frame where the field lies on +y (lens.h); OpticStudio's are in the
    // pupil's x, y: the inverse of the reader's turn (zmx_read.cpp set_fields).
    VignettingFactors v = f.vignetting;
    if (f.x != 0.0 && f.value == 0.0) {  // a quarter turn: VDX' = -s VDY, VDY' = s VDX, swap C
      const double s = f.x > 0.0 ? 1.0 : -1.0;
      v.vdx = s * f.vignetting.vdy;
      v.vdy = -s * f.vignetting.vdx;
      v.vcx = f.vignetting.vcy;
      v.vcy = f.vignetting.vcx;
    } else if ((f.x != 0.0 || f.value < 0.0) && v.any()) {  // R(-b) D', VAN' - b
      const double b = kPi / 2.0 - std::atan2(f.value, f.x);
      const double c = std::cos(b), sb = std::sin(b);
      v.vdx = c * f.vignetting.vdx + sb * f.vignetting.vdy;
      v.vdy = -sb * f.vignetting.vdx + c * f.vignetting.vdy;
      v.van_deg = f.vignetting.van_deg - b * 180.0 / kPi;
    }
    vdx.push_back(number_text(v.vdx));
    vdy.push_back(number_text(v.vdy));
    vcx.push_back(number_text(v.vcx));
    vcy.push_back(number_text(v.vcy));
    van.push_back(number_text(v.van_deg));
    vignetting = vignetting || f.vignetting.any();
  }
  line(fmt::format("FTYP {} 0 {} {} 0 0 {}", field_type, fields.size(), specs.wavelengths_nm.size(),
                   specs.afocal ? 1 : 0));
  line(fmt::format("XFLN {}", fmt::join(x_texts, " ")));
  line(fmt::format("YFLN {}", fmt::join(y_texts, " ")));
  line(fmt::format("FWGN {}", fmt::join(weight_texts, " ")));
  if (vignetting) {
    line(fmt::format("VDXN {}", fmt::join(vdx, " ")));
    line(fmt::format("VDYN {}", fmt::join(vdy, " ")));
    line(fmt::format("VCXN {}", fmt::join(vcx, " ")));
    line(fmt::format("VCYN {}", fmt::join(vcy, " ")));
    line(fmt::format("VANN {}", fmt::join(van, " ")));
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
  // not an aperture when read back); none if the lens cannot be traced, or where a marginal ray
  // misses the surface (apertures.h).
  std::vector<double> automatic;
  try {
    automatic = automatic_semi_diameters(lens);
  } catch (const Error&) {
    automatic.clear();
  }
  int number = 1;
  for (const Surface& s : lens.surfaces) {
    if (s.coordinate_break) {
      // TYPE COORDBRK, PARM 1..6: decenter x, y, tilt x, y, z, order.
      const Placement& p = s.placement;
      line(fmt::format("SURF {}", number++));
      line("  TYPE COORDBRK");
      line("  CURV 0");
      const double parm[6] = {p.decenter_x_mm, p.decenter_y_mm, p.tilt_x_deg,
                              p.tilt_y_deg,    p.tilt_z_deg,    p.tilt_first ? 1.0 : 0.0};
      for (int j = 0; j < 6; ++j) line(fmt::format("  PARM {} {}", j + 1, number_text(parm[j])));
      line(fmt::format("  DISZ {}", number_text(s.thickness_mm)));
      continue;
    }
    if (s.mirror && !s.material.is_air())
      throw Error(SourceLocation{lens.source_path},
                  fmt::format("surface {}: a mirror inside glass is not written to .zmx", number));
    if (s.placement.any() || s.restore_frame)
      throw Error(SourceLocation{lens.source_path},
                  fmt::format("surface {}: a surface's own decenter_tilt is not written to .zmx; "
                              "express it as coordinate breaks around the surface",
                              number));
    line(fmt::format("SURF {}", number++));
    line(s.has_asphere() ? "  TYPE EVENASPH" : "  TYPE STANDARD");
    // The curvature's solve: a pickup (4: source surface, scale on the curvature, column 0)
    // or a variable (1).
    if (s.curvature_pickup.active())
      line(fmt::format("  CURV {} 4 {} {} 0 \"\"", number_text(s.curvature_per_mm),
                       s.curvature_pickup.source + 1, number_text(s.curvature_pickup.scale)));
    else if (s.vary.radius)
      line(fmt::format("  CURV {} 1 0 0 0 \"\"", number_text(s.curvature_per_mm)));
    else
      line(fmt::format("  CURV {}", number_text(s.curvature_per_mm)));
    if (s.has_asphere()) {
      line(fmt::format("  PARM 1 {}", number_text(s.asphere_r2_per_mm)));
      for (int j = 0; j < kAsphereOrders; ++j)
        line(fmt::format("  PARM {} {}", j + 2, number_text(s.asphere[j])));
    }
    line(fmt::format("  DISZ {}", number_text(s.thickness_mm)));
    // The thickness's pickup (PZUP source scale offset column) or marginal-ray-height solve
    // (MAZH height zone).
    if (s.thickness_pickup.active())
      line(fmt::format("  PZUP {} {} {} 0", s.thickness_pickup.source + 1,
                       number_text(s.thickness_pickup.scale),
                       number_text(s.thickness_pickup.offset_mm)));
    if (s.thickness_solve.kind == ThicknessSolve::Kind::kMarginalHeight)
      line(fmt::format("  MAZH {} 0", number_text(s.thickness_solve.height_mm)));
    // GLAS MIRROR (a mirror in air: the switch below then writes no glass).
    if (s.mirror) line("  GLAS MIRROR 0 0 1.5 40 0 0 0 0 0 0");
    switch (s.material.kind) {
      case Material::Kind::kAir:
        break;
      case Material::Kind::kCatalog:
        line(fmt::format("  GLAS {} 0 0 {} {} 0 0 0 0 0 0", s.material.glass_name,
                         number_text(s.material.nd), number_text(s.material.vd)));
        break;
      case Material::Kind::kModel:
        line(fmt::format("  GLAS ___BLANK 1 0 {} {} {} 0 0 0 0 0", number_text(s.material.nd),
                         number_text(s.material.vd), number_text(s.material.dpgf)));
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
    // Surface apertures: CLAP rmin rmax (a clear aperture, rmin obscuring the centre) or OBSC
    // 0 r (an obscuration alone), OBDC their decenter.
    const bool decentred = s.aperture_decenter_x_mm != 0.0 || s.aperture_decenter_y_mm != 0.0;
    if (s.semi_diameter_mm > 0.0 && (s.obscuration_mm > 0.0 || decentred))
      line(fmt::format("  CLAP {} {} 0", number_text(s.obscuration_mm),
                       number_text(s.semi_diameter_mm)));
    else if (s.obscuration_mm > 0.0)
      line(fmt::format("  OBSC 0 {} 0", number_text(s.obscuration_mm)));
    if (decentred)
      line(fmt::format("  OBDC {} {}", number_text(s.aperture_decenter_x_mm),
                       number_text(s.aperture_decenter_y_mm)));
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
