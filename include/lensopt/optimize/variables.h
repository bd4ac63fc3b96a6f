// The paper's lens variables ("Lens Variables", "Glass Variables") and the one mapping between a
// lens and them, shared by the Levenberg-Marquardt optimizer, the Adam joint optimizer and
// tolerancing.
//
// For a lens of K surfaces scaled to focal length f (mm; negative for a diverging lens, whose
// lengths are normalized by |f| and whose normalized EFL is -1):
//   c'_k = c_k |f|   for every surface but the stop and the last (the last is solved),
//   s'_k = t_k / |f| for k < K-1, and s'_{K-1} = (t_{K-1} - BFL) / |f|, the normalized defocus
//          (a diverging lens's BFL < 0: its image plane is virtual, before the last surface, and
//          the rays are traced back to it, trace/kernel.h),
//   g_m  = W (nd_m - mu_nd, vd_m - mu_vd)  for each glass m: the catalog's (nd, vd) whitened,
//          W = Lambda^{-1/2} E^T from the eigen-decomposition of the catalog covariance.
//          One glass m per physical element: a glass element split by a dummy or stop surface
//          (optimize/glass_elements.h) has one pair, named for its first space, which every
//          space of the element takes, so the dummy surface never refracts.
// Forward map x -> lens (templated, so Jets carry derivatives):
//   1. glasses: (nd, vd) = W^{-1} g + mu; quantized (default): the nearest catalog glass in
//      whitened space, with the straight-through gradient g_q = g + stopgrad(g* - g);
//   2. the normalized lens (|f| = 1): curvatures c', spacings s', the last curvature solved so
//      the paraxial focal length at 587.6 nm is exactly sign(f) = +-1 (solve_last_curvature);
//   3. the paraxial image solve: s_{K-1} = BFL' + s'_{K-1} (or, without it, s_{K-1} = s'_{K-1});
//   4. scale: c = c' / |f|, t = s' |f|, a_{2i} = a'_{2i} / |f|^(2i-1).
// An afocal lens (Specs::afocal, analysis/afocal.h: image at infinity, no focal length): its
// lengths are normalized by its vertex length L = sum_{k<K-1} |t_k| (design_length_unit_mm) in
// place of |f|; step 2 solves the last curvature for the lens's own paraxial angular
// magnification M (paraxial/afocal.h; OpticStudio's AMAG), so M is held exactly as the focal
// length of a focusing lens is (a requested M is applied to the start first: optimize/targets.h);
// step 3 does not apply: the last thickness (to an image plane at infinity) is the variable
// s'_{K-1} = t_{K-1} / L as it is, and it is held (it does not change the exit directions).
// Whether the lens stays afocal (no residual power) is left to the merit: the angular spot of
// the on-axis field is the spread of its exit directions, and a residual power P spreads a beam
// of radius r over angles of P r, so the merit itself collimates (design_loss.h).
// Surface profiles (optional variables, named in the constructor's `profile_variables`):
//   k_k  = the conic constant of surface k as it is (dimensionless, O(1));
//   x    = a'_{2i} rho^(2i) for an asphere term, rho = 1 / (2 N) the normalized entrance-pupil
//          radius: the term's sag at the pupil's edge height in units of f, so a4 .. a16 are all
//          O(sag / f) for LM and Adam. a'_{2i} = a_{2i} f^(2i-1) is the term of the f = 1 lens.
// Profile terms that are not variables keep the structure's values (scaled with the lens).
//
// Pickups and solves (lens.h, paraxial/solves.h) are functions of their sources, evaluated in
// the forward map on the normalized lens after step 2's variables are set and before the last
// curvature is solved (a pickup or solve on the last thickness after step 3, replacing the
// image solve), so the trace, the reports and the exact Jacobian all see them; the variable of
// a picked-up or solved value is held (choose_variables). The last curvature cannot be picked
// up (it is the focal-length solve): Error.
//
// Which variables are free (choose_variables), in order of precedence:
//   1. a picked-up or solved value is never free (c_k with a curvature pickup; s_k with a
//      thickness pickup or a marginal-ray-height solve; the defocus when the last thickness has
//      one); the last curvature is solved for the focal length; naming one in a vary list is an
//      Error;
//   2. an explicit list overrides the file: `vary` names (--vary, [optimize] vary, Python's
//      vary=) are free, `freeze` names (--freeze, [optimize] freeze) are held; a name in both
//      is an Error; --focus-only holds everything but the defocus;
//   3. the lens file's per-surface vary flags (TOML `vary = [...]`, .zmx variable flags): when
//      any surface carries one, a variable is free only if its surface flags it (radius -> c_k,
//      thickness -> s_k or, on the last surface, the defocus, glass -> g_k, conic -> k_k, which
//      the flag adds as a variable); asphere terms are free only when named in `vary`;
//   4. without flags every variable is free (the paper's setting).
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "lensopt/glass/glass.h"
#include "lensopt/lens/lens.h"
#include "lensopt/lens/trace_lens.h"
#include "lensopt/optimize/glass_elements.h"
#include "lensopt/paraxial/afocal.h"
#include "lensopt/paraxial/paraxial.h"
#include "lensopt/paraxial/solves.h"

namespace lensopt {

// The whitened (nd, vd) space of a catalog's glasses.
class GlassSpace {
 public:
  GlassSpace() = default;
  // Fits the whitening on the catalog's glasses (those with nd > 1 and vd > 0).
  explicit GlassSpace(const Catalog& catalog);

  int size() const { return static_cast<int>(names_.size()); }
  const std::string& name(int i) const { return names_[i]; }
  double nd(int i) const { return nd_[i]; }
  double vd(int i) const { return vd_[i]; }
  const std::string& catalog_name() const { return catalog_name_; }

  // Whitened coordinates of (nd, vd).
  Eigen::Vector2d whiten(double nd, double vd) const;
  // (nd, vd) of whitened coordinates, templated.
  template <typename T>
  void unwhiten(const T& g0, const T& g1, T& nd, T& vd) const {
    nd = K<T>(mean_[0]) + K<T>(inverse_(0, 0)) * g0 + K<T>(inverse_(0, 1)) * g1;
    vd = K<T>(mean_[1]) + K<T>(inverse_(1, 0)) * g0 + K<T>(inverse_(1, 1)) * g1;
  }
  // Index of the nearest catalog glass in whitened space; `exclude` glasses are skipped.
  int nearest(const Eigen::Vector2d& g, const std::vector<int>& exclude = {}) const;
  // Indices of catalog glasses ordered by whitened distance from g.
  std::vector<int> by_distance(const Eigen::Vector2d& g) const;
  // Whitened coordinates of catalog glass i.
  Eigen::Vector2d glass_point(int i) const { return points_[i]; }

 private:
  std::string catalog_name_;
  std::vector<std::string> names_;
  std::vector<double> nd_, vd_;
  std::vector<Eigen::Vector2d> points_;
  Eigen::Vector2d mean_ = Eigen::Vector2d::Zero();
  Eigen::Matrix2d whitening_ = Eigen::Matrix2d::Identity();
  Eigen::Matrix2d inverse_ = Eigen::Matrix2d::Identity();
};

// What a variable is.
struct LensVariable {
  enum class Kind { kCurvature, kSpacing, kDefocus, kGlass0, kGlass1, kConic, kAsphere };
  Kind kind;
  int surface;        // 0-based surface index
  std::string name;   // "c1", "s3", "defocus", "g2.0", "g2.1", "k3", "a4_3" (1-based surfaces)
  std::string group;  // "curvatures", "spacings", "glasses", "conics", "aspheres"
  int term = 0;       // kAsphere: 0 = a2, 1 = a4, ..., 7 = a16
};

// How glass variables enter the forward pass.
enum class GlassMode {
  kQuantized,   // nearest catalog glass, straight-through gradient (the paper)
  kContinuous,  // (nd, vd) straight from g (ablation; also LM's first phase)
  kFixed,       // each glass fixed to its assigned catalog glass (g has no effect)
};

// The focal length the optimizer holds (the last curvature is solved for it): in the paper's
// spec mode the spec focal length d / (2 tan hfov); for a lens traced as written (a .zmx, a TOML
// with [system]) its own paraxial EFL at its primary wavelength, so a lens of another project
// keeps its focal length (never the paper's 16 mm sensor and 25 deg defaults). An as-written
// lens with every field on axis has no field to design over: the spec value (refused below).
double design_focal_length_mm(const Lens& lens);

// The optimizer's length unit for `lens` (mm): |design_focal_length_mm|, or for an afocal lens
// (no focal length) its vertex length, the sum of |t_k| from the first to the last surface.
double design_length_unit_mm(const Lens& lens);

// The mapping lens <-> variables.
class LensParameterization {
 public:
  // `lens` fixes the structure (surfaces, stop, which spaces are glass) and the specs;
  // `glasses` is the catalog's whitened space. Throws Error if the last surface's medium before
  // it is air (the last curvature cannot be solved) or the lens has no glass.
  // `profile_variables` adds conic and asphere variables: "k3", "a4_3" (a4 of surface 3), ...
  // (1-based surfaces, TraceLens naming); throws Error for an unknown name or the stop.
  LensParameterization(const Lens& lens, GlassSpace glasses,
                       const std::vector<std::string>& profile_variables = {});

  const std::vector<LensVariable>& variables() const { return variables_; }
  int size() const { return static_cast<int>(variables_.size()); }
  // The focal length held (the length unit |f| of the normalized lens); for an afocal lens its
  // length unit, design_length_unit_mm (it has no focal length).
  double focal_length_mm() const { return focal_length_mm_; }
  // An afocal lens (Specs::afocal, header): the angular magnification its last curvature holds.
  bool afocal() const { return afocal_; }
  double angular_magnification() const { return angular_magnification_; }
  // The length unit of the normalized lens (mm): |f|, or an afocal lens's vertex length. The
  // afocal merit (design_loss.h) weighs its angles (rad) by it, as a spot in mm.
  double length_unit_mm() const { return norm_mm_; }
  const GlassSpace& glass_space() const { return glasses_; }
  const Lens& structure() const { return structure_; }

  // The variables of a lens with the same structure. The lens is first scaled to the spec focal
  // length (as analysis does). Glass variables start at the lens's (nd, vd) whitened.
  std::vector<double> from_lens(const Lens& lens) const;

  // The catalog glass index per glass variable pair (the nearest to each g), in surface order:
  // one per glass element (a split element has one).
  std::vector<int> nearest_glasses(const double* x) const;

  // The lens of variables x (double), with catalog glass names (quantized/fixed) or model glasses
  // (continuous). `fixed_glasses` gives the glass per element for kFixed.
  Lens to_lens(const double* x, GlassMode mode, const std::vector<int>& fixed_glasses = {}) const;

  // The TraceLens<T> of variables x: steps 1-4 of the header. Wavelengths and dispersion as
  // make_trace_lens builds them (trace_wavelengths_nm; with the catalog model, the catalog
  // correction of the chosen catalog glass in the quantized and fixed modes; continuous glasses
  // are model glasses, abbe model), so the optimizer traces what the reports trace.
  template <typename T>
  TraceLens<T> to_trace_lens(const T* x, GlassMode mode,
                             const std::vector<int>& fixed_glasses = {}) const {
    TraceLens<T> lens;
    const int k_count = static_cast<int>(structure_.surfaces.size());
    lens.wavelengths_nm = trace_wavelengths_nm(structure_.specs);
    const double reference_nm = lens.wavelengths_nm.back();
    if (!glass_offsets_.empty())
      lens.catalog_offset.assign(k_count, std::vector<double>(lens.wavelengths_nm.size(), 0.0));
    lens.stop = structure_.stop_index();
    lens.curvature_per_mm.assign(k_count, K<T>(0.0));
    lens.thickness_mm.assign(k_count, K<T>(0.0));
    lens.nd.assign(k_count, K<T>(1.0));
    lens.vd.assign(k_count, K<T>(0.0));
    lens.is_glass.assign(k_count, 0);
    // A quantized or fixed glass is the catalog glass to_lens writes, traced as make_trace_lens
    // traces a catalog glass (the paper's model, plus the catalog correction): a .zmx model glass
    // of the structure keeps OpticStudio's model only as a continuous glass. (Tracing the
    // structure's model here held the start's EFL to 1.6e-7 relative on the AC254-100, not
    // exactly.)
    const bool catalog_glasses = mode != GlassMode::kContinuous;
    lens.geometry = make_trace_geometry<T>(structure_);
    for (int k = 0; k < k_count; ++k) {
      const Material& m = structure_.surfaces[k].material;
      lens.is_glass[k] = catalog_glasses && !m.is_air() ? static_cast<char>(ModelGlass::kPaper)
                                                        : trace_glass_kind(m);
    }
    for (int k = 0; k < k_count && !catalog_glasses; ++k) {
      const Material& m = structure_.surfaces[k].material;
      if (m.kind != Material::Kind::kModel || m.model_glass != ModelGlass::kZemax || m.dpgf == 0.0)
        continue;
      if (lens.model_dpgf.empty()) lens.model_dpgf.assign(k_count, 0.0);
      lens.model_dpgf[k] = m.dpgf;
    }
    int glass_number = 0;
    for (int i = 0; i < size(); ++i) {
      const LensVariable& v = variables_[i];
      switch (v.kind) {
        case LensVariable::Kind::kCurvature:
          lens.curvature_per_mm[v.surface] = x[i];
          break;
        case LensVariable::Kind::kSpacing:
          lens.thickness_mm[v.surface] = x[i];
          break;
        case LensVariable::Kind::kDefocus:
          break;  // after the image solve
        case LensVariable::Kind::kGlass0: {
          T g0 = x[i], g1 = x[i + 1];
          if (mode == GlassMode::kQuantized || mode == GlassMode::kFixed) {
            int j = 0;
            if (mode == GlassMode::kFixed) {
              j = fixed_glasses.at(glass_number);
            } else {
              j = glasses_.nearest(Eigen::Vector2d(value_of(g0), value_of(g1)));
            }
            const Eigen::Vector2d p = glasses_.glass_point(j);
            if (mode == GlassMode::kFixed) {
              g0 = K<T>(p[0]);
              g1 = K<T>(p[1]);
            } else {
              // Straight-through: the value of the catalog glass, the derivative of g.
              g0 = g0 + K<T>(p[0] - value_of(g0));
              g1 = g1 + K<T>(p[1] - value_of(g1));
            }
          }
          glasses_.unwhiten(g0, g1, lens.nd[v.surface], lens.vd[v.surface]);
          if (!glass_offsets_.empty() && mode != GlassMode::kContinuous) {
            const int j =
                mode == GlassMode::kFixed
                    ? fixed_glasses.at(glass_number)
                    : glasses_.nearest(Eigen::Vector2d(value_of(x[i]), value_of(x[i + 1])));
            lens.catalog_offset[v.surface] = glass_offsets_[j];
          }
          ++glass_number;
          break;
        }
        case LensVariable::Kind::kGlass1:
          break;  // handled with kGlass0
        case LensVariable::Kind::kConic:
        case LensVariable::Kind::kAsphere:
          break;  // the surface profiles, below
      }
    }
    // A glass element split by a dummy surface: every space takes the glass of its first space
    // (one variable pair per element, so both sides of the dummy are the same glass).
    for (int k = 0; k < k_count; ++k) {
      const int e = element_first_[k];
      if (e == k || structure_.surfaces[k].material.is_air()) continue;
      lens.nd[k] = lens.nd[e];
      lens.vd[k] = lens.vd[e];
      if (!lens.catalog_offset.empty()) lens.catalog_offset[k] = lens.catalog_offset[e];
      if (!lens.model_dpgf.empty()) lens.model_dpgf[k] = lens.model_dpgf[e];
    }
    // Surface profiles: the structure's (normalized) terms, then the profile variables.
    if (has_profiles_) {
      lens.ensure_profiles();
      lens.profile = profile_kind_;
      for (int k = 0; k < k_count; ++k) lens.conic[k] = K<T>(conic0_[k]);
      for (std::size_t j = 0; j < asphere0_.size(); ++j) lens.asphere[j] = K<T>(asphere0_[j]);
      for (int i = 0; i < size(); ++i) {
        const LensVariable& v = variables_[i];
        if (v.kind == LensVariable::Kind::kConic) lens.conic[v.surface] = x[i];
        if (v.kind == LensVariable::Kind::kAsphere)
          lens.asphere[static_cast<std::size_t>(v.surface) * kAsphereTerms + v.term] =
              x[i] * K<T>(1.0 / profile_scale(v.term));
      }
    }
    // Fixed (frozen by structure) values: the stop is flat; frozen variables are still variables.
    const int last = k_count - 1;
    // Pickups and solves before the last surface (header), in the normalized lens's unit.
    const double unit = solve_unit_;
    if (has_solves_) apply_pickups_and_solves(lens, solves_, unit, 0, last);
    if (afocal_) {
      // An afocal lens: the last curvature holds the angular magnification (paraxial/afocal.h),
      // the last thickness is the variable as it is (header).
      lens.curvature_per_mm[last] = solve_last_curvature_for_angular_magnification(
          lens, K<T>(angular_magnification_), reference_nm);
      lens.thickness_mm[last] = x[defocus_index_];
    } else {
      lens.curvature_per_mm[last] = solve_last_curvature(lens, K<T>(power_sign_), reference_nm);
      if (paraxial_image_solve_) {
        const ParaxialData<T> par = paraxial_data(lens, reference_nm);
        lens.thickness_mm[last] = image_distance_for_defocus_mm(par, x[defocus_index_]);
      } else {
        lens.thickness_mm[last] = x[defocus_index_];  // ablation: s_{K-1} = s'_{K-1} f
      }
    }
    if (has_solves_) apply_pickups_and_solves(lens, solves_, unit, last, k_count);
    lens.scale_lengths(K<T>(norm_mm_));
    // The 3D placements as the structure gives them (mm), at the spec scale as prepare_system
    // scales the structure (geometry_scale_): scale_lengths above multiplied the structure's
    // decenters by |f| as if they were normalized (|f| = 1) lengths, which moved a 0.2 mm
    // decenter of a 50 mm lens to 10 mm.
    if (!lens.geometry.placement.empty()) {
      lens.geometry = make_trace_geometry<T>(structure_);
      if (geometry_scale_ != 1.0)
        for (std::size_t i = 0; i < lens.geometry.placement.size(); i += 5) {
          lens.geometry.placement[i] = lens.geometry.placement[i] * K<T>(geometry_scale_);
          lens.geometry.placement[i + 1] = lens.geometry.placement[i + 1] * K<T>(geometry_scale_);
        }
    }
    return lens;
  }

  // Whitened distance^2 of each glass pair to its nearest catalog glass: l_GV terms (templated).
  template <typename T>
  T glass_variable_loss(const T* x) const {
    T sum = K<T>(0.0);
    for (int i = 0; i < size(); ++i) {
      if (variables_[i].kind != LensVariable::Kind::kGlass0) continue;
      const int j = glasses_.nearest(Eigen::Vector2d(value_of(x[i]), value_of(x[i + 1])));
      const Eigen::Vector2d p = glasses_.glass_point(j);
      const T d0 = x[i] - K<T>(p[0]);
      const T d1 = x[i + 1] - K<T>(p[1]);
      sum = sum + d0 * d0 + d1 * d1;
    }
    return sum;
  }

  // The paraxial image solve (step 3; on by default). Off (the paper's ablation "no paraxial
  // image solve"): the last spacing is a plain variable, s'_{K-1} = t_{K-1} / f, still named
  // "defocus". Set it before from_lens/to_lens: it changes what the variable means.
  void set_paraxial_image_solve(bool on) { paraxial_image_solve_ = on; }
  bool paraxial_image_solve() const { return paraxial_image_solve_; }

  // x / a'_{2i} of asphere term j (0 = a2): rho^(2i), rho = 1 / (2 N).
  double profile_scale(int term) const;

  // Indices of the variables whose name or group is in `names` ("curvatures", "c3", "g2", ...).
  // Throws Error naming an unknown entry.
  std::vector<int> select(const std::vector<std::string>& names) const;

  // Why variable i cannot be free: "picked up: c4 = -1 x c3", "solved: marginal ray height
  // 0 mm", or empty (header rule 1).
  std::string dependent_reason(int i) const;
  // Variable i's surface flags it in the lens file (header rule 3).
  bool flagged(int i) const;

 private:
  Lens structure_;
  GlassSpace glasses_;
  std::vector<LensVariable> variables_;
  // element_first_spaces of the structure (glass_elements.h): one glass per element.
  std::vector<int> element_first_;
  // Catalog-model corrections per catalog glass j and traced wavelength (empty: abbe model).
  std::vector<std::vector<double>> glass_offsets_;
  double focal_length_mm_ = 1.0;
  // The structure's scale to the spec focal length (prepare_system's, 1 as written): its
  // placements' decenters are traced times this.
  double geometry_scale_ = 1.0;
  double norm_mm_ = 1.0;     // |f|, the length unit of the normalized lens
  double power_sign_ = 1.0;  // the normalized lens's EFL: +1, or -1 for a diverging lens
  bool afocal_ = false;      // Specs::afocal: the last curvature holds angular_magnification_
  double angular_magnification_ = 0.0;
  int defocus_index_ = -1;
  // Profiles of the normalized (f = 1) structure: kind per surface, k and a'_{2i} constants.
  bool has_profiles_ = false;
  std::vector<std::uint8_t> profile_kind_;
  std::vector<double> conic0_, asphere0_;
  bool paraxial_image_solve_ = true;
  // The structure's pickups and solves (paraxial/solves.h).
  bool has_solves_ = false;
  LensSolves solves_;
  double solve_unit_ = 1.0;  // the file's mm in the normalized lens: spec scale / f
};

// The free variables of an optimization and why (header rules 1-4).
struct VariableChoice {
  std::vector<int> held;            // indices held fixed, sorted
  std::vector<std::string> report;  // one line per reason: "free (lens file vary flags): c1, c2"
};
// `freeze` and `vary` are the explicit lists (names or groups as select() takes them; profile
// names in `vary` are variables of `param` already); `focus_only` holds all but the defocus.
// Throws Error for a name in both lists, a dependent variable in `vary`, or a focus-only run
// whose last thickness is solved.
VariableChoice choose_variables(const LensParameterization& param,
                                const std::vector<std::string>& freeze,
                                const std::vector<std::string>& vary, bool focus_only);

// to_trace_lens on double is compiled once, in src/optimize/design_double.cpp.
extern template TraceLens<double> LensParameterization::to_trace_lens<double>(
    const double*, GlassMode, const std::vector<int>&) const;

}  // namespace lensopt
