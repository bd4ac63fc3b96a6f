#include "lensopt/optimize/variables.h"

#include <fmt/format.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <numeric>

#include "lensopt/core/error.h"
#include "lensopt/core/text.h"
#include "lensopt/trace/system.h"

namespace lensopt {

GlassSpace::GlassSpace(const Catalog& catalog) : catalog_name_(catalog.name) {
  for (const Glass& g : catalog.glasses) {
    if (!(g.nd > 1.0) || !(g.vd > 0.0)) continue;
    names_.push_back(g.name);
    nd_.push_back(g.nd);
    vd_.push_back(g.vd);
  }
  if (names_.size() < 3) {
    throw Error(fmt::format("catalog {} has {} usable glasses; the glass space needs at least 3",
                            catalog.name, names_.size()));
  }
  const double n = static_cast<double>(names_.size());
  mean_ = Eigen::Vector2d::Zero();
  for (std::size_t i = 0; i < names_.size(); ++i) mean_ += Eigen::Vector2d(nd_[i], vd_[i]);
  mean_ /= n;
  Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
  for (std::size_t i = 0; i < names_.size(); ++i) {
    const Eigen::Vector2d d = Eigen::Vector2d(nd_[i], vd_[i]) - mean_;
    cov += d * d.transpose();
  }
  cov /= n;
  // PCA whitening: W = Lambda^{-1/2} E^T, so W cov W^T = I.
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(cov);
  const Eigen::Vector2d lambda = eig.eigenvalues();
  whitening_ = lambda.cwiseSqrt().cwiseInverse().asDiagonal() * eig.eigenvectors().transpose();
  inverse_ = whitening_.inverse();
  for (std::size_t i = 0; i < names_.size(); ++i) points_.push_back(whiten(nd_[i], vd_[i]));
}

Eigen::Vector2d GlassSpace::whiten(double nd, double vd) const {
  return whitening_ * (Eigen::Vector2d(nd, vd) - mean_);
}

int GlassSpace::nearest(const Eigen::Vector2d& g, const std::vector<int>& exclude) const {
  int best = -1;
  double best_d2 = 0;
  for (int i = 0; i < size(); ++i) {
    if (std::find(exclude.begin(), exclude.end(), i) != exclude.end()) continue;
    const double d2 = (points_[i] - g).squaredNorm();
    if (best < 0 || d2 < best_d2) {
      best = i;
      best_d2 = d2;
    }
  }
  return best;
}

std::vector<int> GlassSpace::by_distance(const Eigen::Vector2d& g) const {
  std::vector<int> order(size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    return (points_[a] - g).squaredNorm() < (points_[b] - g).squaredNorm();
  });
  return order;
}

double design_focal_length_mm(const Lens& lens) {
  if (lens.specs.mode != SpecMode::kAsWritten || lens.specs.half_field_deg == 0.0)
    return lens.specs.focal_length_mm();
  const TraceLens<double> trace = make_trace_lens(lens);
  return paraxial_data(trace, trace.reference_nm()).efl_mm;
}

double design_length_unit_mm(const Lens& lens) {
  if (!lens.specs.afocal) return std::abs(design_focal_length_mm(lens));
  double length = 0.0;
  for (std::size_t k = 0; k + 1 < lens.surfaces.size(); ++k)
    length += std::abs(lens.surfaces[k].thickness_mm);
  return length;
}

LensParameterization::LensParameterization(const Lens& lens, GlassSpace glasses,
                                           const std::vector<std::string>& profile_variables)
    : structure_(lens), glasses_(std::move(glasses)) {
  lens.validate();
  const std::string where = lens.source_path.empty() ? lens.name : lens.source_path;
  // An afocal lens (analysis/afocal.h) has no focal length: its lengths are normalized by
  // design_length_unit_mm (its vertex length) and its last curvature is solved for its angular
  // magnification (header).
  afocal_ = lens.specs.afocal;
  focal_length_mm_ = afocal_ ? design_length_unit_mm(lens) : design_focal_length_mm(lens);
  // Any sign of power: a diverging lens (EFL < 0, a virtual image) is normalized by |f| and its
  // last curvature solved for EFL = -1 (header); a lens without a focal length must say afocal.
  if (!afocal_ && lens.specs.mode == SpecMode::kAsWritten && lens.specs.half_field_deg != 0.0 &&
      !(std::isfinite(focal_length_mm_) && focal_length_mm_ != 0.0))
    throw Error(SourceLocation{where},
                fmt::format("the lens's paraxial focal length is {:.6g} mm: the lens has no "
                            "finite focal length (afocal: set [system] afocal = true, and it is "
                            "analysed and optimized in angle)",
                            focal_length_mm_));
  if (afocal_ && !(std::isfinite(focal_length_mm_) && focal_length_mm_ > 0.0))
    throw Error(SourceLocation{where},
                fmt::format("the afocal lens's vertex length (first to last surface) is {:.6g} mm; "
                            "the optimizer needs a lens of positive length",
                            focal_length_mm_));
  if (!afocal_ && (!std::isfinite(focal_length_mm_) || focal_length_mm_ == 0.0 ||
                   (lens.specs.mode != SpecMode::kAsWritten && !(focal_length_mm_ > 0.0)))) {
    // A lens traced as written has no sensor diagonal of its own (16 mm is a default): on axis
    // only, the message names what to add, not d / (2 tan 0).
    if (lens.specs.mode == SpecMode::kAsWritten && lens.specs.half_field_deg == 0.0)
      throw Error(SourceLocation{lens.source_path},
                  "the optimizer needs an off-axis field (it works at the spec focal length "
                  "d / (2 tan hfov), and every field of this lens is on axis); add a field "
                  "(a .zmx YFLN value or a TOML [system] fields entry above 0)");
    throw Error(
        SourceLocation{lens.source_path},
        fmt::format("the optimizer works at the spec focal length d / (2 tan hfov), which "
                    "is {} mm for half_field_deg = {} and sensor_diagonal_mm = {}; give "
                    "the lens a field",
                    focal_length_mm_, lens.specs.half_field_deg, lens.specs.sensor_diagonal_mm));
  }
  norm_mm_ = std::abs(focal_length_mm_);
  power_sign_ = focal_length_mm_ < 0.0 ? -1.0 : 1.0;
  const int k_count = static_cast<int>(lens.surfaces.size());
  const int last = k_count - 1;
  if (lens.surfaces[last - 1].material.is_air()) {
    throw Error(SourceLocation{lens.source_path},
                "the last surface must end a glass element: its curvature is solved for the focal "
                "length");
  }
  if (afocal_) {
    // The angular magnification the last curvature holds (paraxial/afocal.h), the lens's own as
    // traced (optimize applies an angular_magnification target to the start first, targets.h).
    const TraceLens<double> traced = make_trace_lens(lens);
    const double nm = traced.reference_nm();
    angular_magnification_ = paraxial_angular_magnification(traced, nm);
    const ParaxialRay<double> chief = afocal_chief_at_last_vertex(traced, nm);
    if (!(std::isfinite(angular_magnification_) && angular_magnification_ != 0.0))
      throw Error(SourceLocation{where},
                  fmt::format("the afocal lens's paraxial angular magnification is {:.6g}; the "
                              "optimizer holds it and needs it finite and not 0",
                              angular_magnification_));
    if (!(std::abs(chief.y) > 1e-9 * norm_mm_))
      throw Error(SourceLocation{where},
                  fmt::format("the paraxial chief ray crosses the axis at the last surface "
                              "(height {:.3g} mm there): its curvature, which the optimizer "
                              "solves for the angular magnification, has no lever on it; add a "
                              "surface or move the stop",
                              chief.y));
  }
  using Kind = LensVariable::Kind;
  for (int k = 0; k < k_count; ++k) {
    if (lens.surfaces[k].is_stop || k == last) continue;
    variables_.push_back({Kind::kCurvature, k, fmt::format("c{}", k + 1), "curvatures"});
  }
  for (int k = 0; k < last; ++k)
    variables_.push_back({Kind::kSpacing, k, fmt::format("s{}", k + 1), "spacings"});
  defocus_index_ = static_cast<int>(variables_.size());
  variables_.push_back({Kind::kDefocus, last, "defocus", "spacings"});
  int glass_count = 0;
  element_first_ = element_first_spaces(lens);
  for (int k = 0; k < k_count; ++k) {
    // One glass pair per element: a space after a dummy surface inside an element (a stop at the
    // vertex of a curved face) takes the element's (to_trace_lens, to_lens).
    if (lens.surfaces[k].material.is_air() || element_first_[k] != k) continue;
    ++glass_count;
    variables_.push_back({Kind::kGlass0, k, fmt::format("g{}.0", k + 1), "glasses"});
    variables_.push_back({Kind::kGlass1, k, fmt::format("g{}.1", k + 1), "glasses"});
  }
  if (glass_count == 0) throw Error(SourceLocation{lens.source_path}, "the lens has no glass");
  // Pickups and solves (header): the last curvature is the focal-length solve.
  solves_ = LensSolves::of(lens);
  has_solves_ = solves_.any();
  if (has_solves_) {
    // The file's millimetres in the normalized lens's unit: the structure is traced scaled by
    // the spec scale (the paper's mode; 1 as written), then normalized to f = 1.
    TraceOptions scale_only;
    scale_only.ray_aiming = false;
    scale_only.fields = 1;
    scale_only.rings = 1;
    const double scale = prepare_system(make_trace_lens(lens), lens.specs, scale_only).scale;
    solve_unit_ = scale / norm_mm_;
  }
  if (lens.surfaces[last].curvature_pickup.active())
    throw Error(SourceLocation{where},
                fmt::format("surface {} (the last) picks up its curvature from surface {}, but "
                            "the optimizer solves the last curvature for the focal length; put "
                            "the pickup on an earlier surface (or add a flat dummy surface "
                            "after it)",
                            k_count, lens.surfaces[last].curvature_pickup.source + 1));
  // The catalog model: each catalog glass's correction at the traced wavelengths, as
  // make_trace_lens computes it for a lens holding that glass.
  if (lens.specs.dispersion == DispersionModel::kCatalog) {
    std::shared_ptr<const Catalog> catalog;
    try {
      catalog = load_catalog(glasses_.catalog_name());
    } catch (const Error&) {
      catalog = nullptr;
    }
    if (catalog) {
      const std::vector<double> wavelengths = trace_wavelengths_nm(lens.specs);
      glass_offsets_.resize(glasses_.size());
      for (int j = 0; j < glasses_.size(); ++j) {
        const Glass* g = catalog->find(glasses_.name(j));
        glass_offsets_[j] =
            g && g->formula_supported
                ? catalog_offsets(*g, glasses_.nd(j), glasses_.vd(j), wavelengths, g->name)
                : std::vector<double>(wavelengths.size(), 0.0);
      }
    }
  }

  // Profile variables: the named ones, then the conic of every surface the file flags
  // (vary = ["conic"]). A name that is not a profile variable must be one of the variables
  // above (a vary list may free c3, s2, g2, defocus or a group: choose_variables).
  std::vector<std::string> profile_names = profile_variables;
  for (int k = 0; k < k_count; ++k)
    if (lens.surfaces[k].vary.conic) profile_names.push_back(fmt::format("k{}", k + 1));
  for (const std::string& name : profile_names) {
    if (name.empty()) continue;
    PrescriptionVariable pv;
    if (!parse_profile_variable(name, pv)) {
      bool known = name == "curvatures" || name == "spacings" || name == "glasses" ||
                   name == "conics" || name == "aspheres";
      for (const LensVariable& v : variables_)
        known = known || v.name == name || fmt::format("g{}", v.surface + 1) == name;
      if (known) continue;
      throw Error(SourceLocation{lens.source_path},
                  fmt::format("unknown variable '{}' to vary; write c<surface>, s<surface>, "
                              "g<surface>, defocus, a group (curvatures, spacings, glasses), "
                              "k<surface> (conic) or a<order>_<surface> (asphere term, order 2, "
                              "4, ..., 16), e.g. k3, a4_3",
                              name));
    }
    if (pv.surface >= k_count)
      throw Error(SourceLocation{lens.source_path},
                  fmt::format("profile variable '{}': the lens has {} surfaces", name, k_count));
    if (lens.surfaces[pv.surface].is_stop)
      throw Error(SourceLocation{lens.source_path},
                  fmt::format("profile variable '{}': surface {} is the (flat) stop", name,
                              pv.surface + 1));
    const bool conic = pv.kind == PrescriptionVariable::Kind::kConic;
    const LensVariable v{conic ? Kind::kConic : Kind::kAsphere, pv.surface, pv.name(),
                         conic ? "conics" : "aspheres", pv.term};
    bool duplicate = false;
    for (const LensVariable& u : variables_) duplicate = duplicate || u.name == v.name;
    if (!duplicate) variables_.push_back(v);
  }
  // The structure's placements are traced at the spec scale (to_trace_lens).
  if (lens.breaks_symmetry()) {
    TraceOptions scale_only;
    scale_only.ray_aiming = false;
    scale_only.fields = 1;
    scale_only.rings = 1;
    geometry_scale_ = prepare_system(make_trace_lens(lens), lens.specs, scale_only).scale;
  }
  // The structure's profiles, normalized to f = 1 (after scaling to the spec focal length).
  bool any_profile = false;
  for (const Surface& s : lens.surfaces) any_profile = any_profile || !s.is_spherical();
  for (const LensVariable& v : variables_)
    any_profile = any_profile || v.kind == Kind::kConic || v.kind == Kind::kAsphere;
  if (any_profile) {
    has_profiles_ = true;
    TraceOptions scale_only;
    scale_only.ray_aiming = false;
    scale_only.fields = 1;
    scale_only.rings = 1;
    const double scale = prepare_system(make_trace_lens(lens), lens.specs, scale_only).scale;
    const Lens normalized = scaled(lens, scale / norm_mm_);
    profile_kind_.assign(k_count, kProfileSphere);
    conic0_.assign(k_count, 0.0);
    asphere0_.assign(static_cast<std::size_t>(k_count) * kAsphereTerms, 0.0);
    for (int k = 0; k < k_count; ++k) {
      const Surface& s = normalized.surfaces[k];
      conic0_[k] = s.conic;
      asphere0_[static_cast<std::size_t>(k) * kAsphereTerms] = s.asphere_r2_per_mm;
      for (int j = 0; j < kAsphereOrders; ++j)
        asphere0_[static_cast<std::size_t>(k) * kAsphereTerms + j + 1] = s.asphere[j];
      if (s.conic != 0.0) profile_kind_[k] = kProfileConic;
      if (s.has_asphere()) profile_kind_[k] = kProfileAsphere;
    }
    for (const LensVariable& v : variables_) {
      if (v.kind == Kind::kConic && profile_kind_[v.surface] == kProfileSphere)
        profile_kind_[v.surface] = kProfileConic;
      if (v.kind == Kind::kAsphere) profile_kind_[v.surface] = kProfileAsphere;
    }
  }
}

double LensParameterization::profile_scale(int term) const {
  const double rho = 1.0 / (2.0 * structure_.specs.f_number);
  return std::pow(rho, 2 * term + 2);
}

std::vector<double> LensParameterization::from_lens(const Lens& lens_in) const {
  if (lens_in.surfaces.size() != structure_.surfaces.size())
    throw Error("lens structure differs from the parameterization's");
  // Scale to the spec focal length first, as analysis does.
  TraceOptions scale_only;
  scale_only.ray_aiming = false;
  scale_only.fields = 1;
  scale_only.rings = 1;
  const TraceSystem<double> sys =
      prepare_system(make_trace_lens(lens_in), lens_in.specs, scale_only);
  const Lens lens = scaled(lens_in, sys.scale);
  const double f = norm_mm_;  // |f|: the normalization (header)
  std::vector<double> x(variables_.size(), 0.0);
  for (int i = 0; i < size(); ++i) {
    const LensVariable& v = variables_[i];
    const Surface& s = lens.surfaces[v.surface];
    switch (v.kind) {
      case LensVariable::Kind::kCurvature:
        x[i] = s.curvature_per_mm * f;
        break;
      case LensVariable::Kind::kSpacing:
        x[i] = s.thickness_mm / f;
        break;
      case LensVariable::Kind::kDefocus:
        // An afocal lens: the last thickness as it is (no image solve, header).
        x[i] = paraxial_image_solve_ && !afocal_ ? (s.thickness_mm - sys.bfl_mm) / f
                                                 : s.thickness_mm / f;
        break;
      case LensVariable::Kind::kGlass0: {
        const Eigen::Vector2d g = glasses_.whiten(s.material.nd, s.material.vd);
        x[i] = g[0];
        x[i + 1] = g[1];
        break;
      }
      case LensVariable::Kind::kGlass1:
        break;
      case LensVariable::Kind::kConic:
        x[i] = s.conic;
        break;
      case LensVariable::Kind::kAsphere: {
        // a'_{2i} = a_{2i} f^(2i-1) of the f = 1 lens, times rho^(2i).
        const double a = v.term == 0 ? s.asphere_r2_per_mm : s.asphere[v.term - 1];
        x[i] = a * std::pow(f, 2 * v.term + 1) * profile_scale(v.term);
        break;
      }
    }
  }
  return x;
}

std::vector<int> LensParameterization::nearest_glasses(const double* x) const {
  std::vector<int> out;
  for (int i = 0; i < size(); ++i)
    if (variables_[i].kind == LensVariable::Kind::kGlass0)
      out.push_back(glasses_.nearest(Eigen::Vector2d(x[i], x[i + 1])));
  return out;
}

Lens LensParameterization::to_lens(const double* x, GlassMode mode,
                                   const std::vector<int>& fixed_glasses) const {
  const TraceLens<double> tl = to_trace_lens(x, mode, fixed_glasses);
  Lens lens = structure_;
  const std::vector<int> nearest = nearest_glasses(x);
  int glass_number = 0;
  for (std::size_t k = 0; k < lens.surfaces.size(); ++k) {
    Surface& s = lens.surfaces[k];
    s.curvature_per_mm = tl.curvature_per_mm[k];
    s.thickness_mm = tl.thickness_mm[k];
    s.written_as_radius = true;
    s.semi_diameter_mm = 0.0;
    if (tl.has_profiles()) {
      s.conic = tl.conic[k];
      s.asphere_r2_per_mm = tl.asphere[k * kAsphereTerms];
      for (int j = 0; j < kAsphereOrders; ++j) s.asphere[j] = tl.asphere[k * kAsphereTerms + j + 1];
    }
    if (s.material.is_air()) continue;
    if (element_first_[k] != static_cast<int>(k)) {  // a split element: its first space's glass
      s.material = lens.surfaces[element_first_[k]].material;
      continue;
    }
    if (mode == GlassMode::kContinuous) {
      // The structure's model glass keeps its model (a .zmx model glass stays OpticStudio's).
      const bool zemax =
          s.material.kind == Material::Kind::kModel && s.material.model_glass == ModelGlass::kZemax;
      const double dpgf = s.material.dpgf;
      s.material = zemax ? Material::zemax_model(tl.nd[k], tl.vd[k], dpgf)
                         : Material::model(tl.nd[k], tl.vd[k]);
    } else {
      const int j =
          mode == GlassMode::kFixed ? fixed_glasses.at(glass_number) : nearest[glass_number];
      Material m;
      m.kind = Material::Kind::kCatalog;
      m.glass_name = glasses_.name(j);
      m.nd = glasses_.nd(j);
      m.vd = glasses_.vd(j);
      // Keep the catalog entry when the structure's glass came from the same catalog.
      const std::shared_ptr<const Catalog> catalog = [&]() -> std::shared_ptr<const Catalog> {
        try {
          return load_catalog(glasses_.catalog_name());
        } catch (const Error&) {
          return nullptr;
        }
      }();
      if (catalog) {
        if (const Glass* g = catalog->find(m.glass_name)) m.glass = std::make_shared<Glass>(*g);
      }
      s.material = m;
    }
    ++glass_number;
  }
  return lens;
}

std::vector<int> LensParameterization::select(const std::vector<std::string>& names) const {
  std::vector<int> out;
  for (const std::string& raw : names) {
    if (raw.empty()) continue;
    bool found = false;
    for (int i = 0; i < size(); ++i) {
      const LensVariable& v = variables_[i];
      const std::string glass_pair = fmt::format("g{}", v.surface + 1);
      const bool glass =
          v.kind == LensVariable::Kind::kGlass0 || v.kind == LensVariable::Kind::kGlass1;
      if (raw == v.name || raw == v.group || (glass && raw == glass_pair)) {
        out.push_back(i);
        found = true;
      }
    }
    if (!found) {
      std::string known;
      for (const LensVariable& v : variables_) known += (known.empty() ? "" : ", ") + v.name;
      throw Error(
          fmt::format("unknown variable '{}'; known: curvatures, spacings, glasses, "
                      "conics, aspheres, {}",
                      raw, known));
    }
  }
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

std::string LensParameterization::dependent_reason(int i) const {
  const LensVariable& v = variables_.at(i);
  const Surface& s = structure_.surfaces[v.surface];
  switch (v.kind) {
    case LensVariable::Kind::kCurvature:
      if (s.curvature_pickup.active())
        return fmt::format("picked up: c{} = {:g} x c{}", v.surface + 1, s.curvature_pickup.scale,
                           s.curvature_pickup.source + 1);
      return {};
    case LensVariable::Kind::kSpacing:
    case LensVariable::Kind::kDefocus: {
      if (v.kind == LensVariable::Kind::kDefocus && afocal_)
        return fmt::format(
            "afocal: t{} (to the image plane) does not change the exit directions "
            "of an image at infinity",
            v.surface + 1);
      const std::string t = v.kind == LensVariable::Kind::kDefocus
                                ? fmt::format("t{} (defocus)", v.surface + 1)
                                : fmt::format("t{}", v.surface + 1);
      if (s.thickness_pickup.active())
        return fmt::format("picked up: {} = {:g} x t{} + {:g} mm", t, s.thickness_pickup.scale,
                           s.thickness_pickup.source + 1, s.thickness_pickup.offset_mm);
      if (s.thickness_solve.active())
        return fmt::format("solved: {} by the marginal ray height {:g} mm on surface {}", t,
                           s.thickness_solve.height_mm, v.surface + 2);
      return {};
    }
    default:
      return {};
  }
}

bool LensParameterization::flagged(int i) const {
  const LensVariable& v = variables_.at(i);
  const VaryFlags& f = structure_.surfaces[v.surface].vary;
  switch (v.kind) {
    case LensVariable::Kind::kCurvature:
      return f.radius;
    case LensVariable::Kind::kSpacing:
    case LensVariable::Kind::kDefocus:
      return f.thickness;
    case LensVariable::Kind::kGlass0:
    case LensVariable::Kind::kGlass1:
      return f.glass;
    case LensVariable::Kind::kConic:
      return f.conic;
    case LensVariable::Kind::kAsphere:
      return false;
  }
  return false;
}

VariableChoice choose_variables(const LensParameterization& param,
                                const std::vector<std::string>& freeze,
                                const std::vector<std::string>& vary, bool focus_only) {
  const int n = param.size();
  const Lens& lens = param.structure();
  const std::string where = lens.source_path.empty() ? lens.name : lens.source_path;
  // The vary list's names that are variables (profile names the constructor added are too).
  std::vector<std::string> vary_names;
  for (const std::string& name : vary)
    if (!name.empty()) vary_names.push_back(name);
  const std::vector<int> frozen = param.select(freeze);
  const std::vector<int> freed = param.select(vary_names);
  auto contains = [](const std::vector<int>& list, int i) {
    return std::find(list.begin(), list.end(), i) != list.end();
  };
  // The profile variables the vary list added are free by construction; named again they are
  // in `freed` too.
  for (int i : freed) {
    if (contains(frozen, i))
      throw Error(SourceLocation{where},
                  fmt::format("variable {} is both held (freeze) and freed (vary); name it in "
                              "one list",
                              param.variables()[i].name));
    const std::string dependent = param.dependent_reason(i);
    // A group ("spacings") may span dependent values: only a variable named alone is an error.
    bool named = false;
    for (const std::string& name : vary_names) named = named || name == param.variables()[i].name;
    if (named && !dependent.empty())
      throw Error(SourceLocation{where},
                  fmt::format("vary {}: it is not a variable ({}); remove the pickup or solve "
                              "from the lens file to vary it",
                              param.variables()[i].name, dependent));
  }
  if (focus_only && param.afocal())
    throw Error(SourceLocation{where},
                "--focus-only: an afocal lens has no image distance to refocus (its image is at "
                "infinity); hold the variables you want held with --freeze (e.g. --freeze "
                "curvatures,glasses to adjust its spacings only)");
  if (focus_only)
    for (int i = 0; i < n; ++i)
      if (param.variables()[i].kind == LensVariable::Kind::kDefocus &&
          !param.dependent_reason(i).empty())
        throw Error(SourceLocation{where},
                    fmt::format("--focus-only: the image distance is not a variable ({}); "
                                "remove that solve to refocus on the merit",
                                param.dependent_reason(i)));
  const bool flags = lens.has_vary_flags();
  VariableChoice out;
  std::vector<std::string> dependent, held_freeze, freed_list, flagged_free, unflagged_held,
      held_focus, free_focus, free_default;
  for (int i = 0; i < n; ++i) {
    const LensVariable& v = param.variables()[i];
    const std::string reason = param.dependent_reason(i);
    bool held = false;
    if (!reason.empty()) {
      held = true;
      dependent.push_back(reason);
    } else if (focus_only) {
      // The defocus alone is free, whatever the lists and flags say.
      held = v.kind != LensVariable::Kind::kDefocus;
      (held ? held_focus : free_focus).push_back(v.name);
    } else if (contains(frozen, i)) {
      held = true;
      held_freeze.push_back(v.name);
    } else if (contains(freed, i)) {
      freed_list.push_back(v.name);
    } else if (flags) {
      // The profile variables a vary list named were added to be free.
      bool named_profile = false;
      for (const std::string& name : vary_names) named_profile = named_profile || name == v.name;
      if (param.flagged(i) || named_profile) {
        (named_profile ? freed_list : flagged_free).push_back(v.name);
      } else {
        held = true;
        unflagged_held.push_back(v.name);
      }
    } else {
      free_default.push_back(v.name);
    }
    if (held) out.held.push_back(i);
  }
  auto line = [&](const std::string& what, const std::vector<std::string>& names,
                  const std::string& sep) {
    if (names.empty()) return;
    std::string text;
    for (const std::string& name : names) text += (text.empty() ? "" : sep) + name;
    out.report.push_back(fmt::format("variables {}: {}", what, text));
  };
  line("free (--focus-only)", free_focus, ", ");
  line("free (no vary flags in the lens file: every variable)", free_default, ", ");
  line("free (vary flags in the lens file)", flagged_free, ", ");
  line("free (named in vary: --vary / [optimize] vary)", freed_list, ", ");
  line("held (not flagged in the lens file, which flags others)", unflagged_held, ", ");
  line("held (named in freeze: --freeze / [optimize] freeze)", held_freeze, ", ");
  line("held (--focus-only)", held_focus, ", ");
  line("not variables (pickups and solves of the lens file)", dependent, "; ");
  if (param.afocal())
    out.report.push_back(
        fmt::format("variables: c{} is solved for the angular magnification {:.9g}",
                    lens.surfaces.size(), param.angular_magnification()));
  else
    out.report.push_back(fmt::format("variables: c{} is solved for the focal length {:.6g} mm",
                                     lens.surfaces.size(), param.focal_length_mm()));
  return out;
}

}  // namespace lensopt
