// TraceLens<T>: the numbers the tracer needs, on scalar type T (double or a ceres::Jet), built
// from a Lens once. Prescription variables can be seeded as Jet derivative directions.
//
// Surfaces k = 0..K-1: curvature c_k (1/mm), profile (trace/profile.h: sphere, conic k_k, even
// asphere a_{2i,k}; `profile` empty = every surface a sphere), thickness t_k (mm, to surface k+1;
// t_{K-1} is the distance to the image plane), medium after surface k with (nd_k, vd_k) (air: 1,
// 0). Refractive index of medium k at wavelength l:
//   abbe model:     n_k(l) = A_k + B_k / l^2 (glass/dispersion.h)
//   a .zmx model glass (is_glass[k] == ModelGlass::kZemax): OpticStudio's model glass,
//                   n_k = zemax_model_index(nd_k, vd_k, dPgF_k, l), nd_k exact at 587.5618 nm
//   catalog model:  n_k(l) = abbe(nd_k, vd_k, l) + [n_cat(l) - abbe(nd_k0, vd_k0, l)]
// The bracket is a constant per (surface, wavelength), so the catalog model equals the catalog's
// formula at the nominal glass and still carries derivatives with respect to nd and vd.
// Wavelengths: the system's, then its primary (reference) wavelength last; paraxial data at any
// of them use the same index as the real rays (index_at_nm looks the wavelength up).
// make_trace_lens is the one builder from a Lens; the optimizer's forward map
// (LensParameterization::to_trace_lens) fills the same fields through trace_wavelengths_nm and
// catalog_offsets, so every consumer traces with one dispersion model.
#pragma once

#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "lensopt/core/scalar.h"
#include "lensopt/glass/dispersion.h"
#include "lensopt/lens/lens.h"

namespace lensopt {

// Surface profile kinds of a TraceLens (the kernel picks one loop per surface, trace/profile.h).
inline constexpr std::uint8_t kProfileSphere = 0;
inline constexpr std::uint8_t kProfileConic = 1;
inline constexpr std::uint8_t kProfileAsphere = 2;
// Asphere terms per surface in a TraceLens: a2, a4, ..., a16.
inline constexpr int kAsphereTerms = 8;

// One prescription variable: which number of the lens.
struct PrescriptionVariable {
  enum class Kind { kCurvature, kThickness, kNd, kVd, kConic, kAsphere };
  Kind kind = Kind::kCurvature;
  int surface = 0;  // 0-based surface index (for kNd/kVd: the surface the glass follows)
  int term = 0;     // kAsphere: 0 = a2, 1 = a4, ..., 7 = a16

  // "c3", "t5", "nd2", "vd2", "k3", "a4_3" (1-based surface numbers, as in the user's view).
  std::string name() const;
};

// Every curvature but the stop's, every thickness, nd and vd of every glass: the 23 variables of
// the Tessar (7 + 8 + 4 + 4); then the conic constant of every non-spherical surface and each
// of its nonzero asphere terms.
std::vector<PrescriptionVariable> all_prescription_variables(const Lens& lens);

// Parses "k3" (conic of surface 3) or "a4_3" / "a2_3" (asphere term of surface 3): returns false
// for any other name.
bool parse_profile_variable(const std::string& name, PrescriptionVariable& out);

// The value of a variable in a lens.
double variable_value(const Lens& lens, const PrescriptionVariable& variable);

// Sets a variable's value in a lens.
void set_variable_value(Lens& lens, const PrescriptionVariable& variable, double value);

// Bits of TraceGeometry::flags.
inline constexpr std::uint8_t kPlacementTiltFirst = 1;        // OpticStudio's order flag 1
inline constexpr std::uint8_t kPlacementCoordinateBreak = 2;  // a dummy surface: frame only
inline constexpr std::uint8_t kPlacementRestore = 4;          // the frame after is the one before
inline constexpr std::uint8_t kPlacementMoved = 8;            // a nonzero placement

// Placement in 3D, reflection and obscuration of a TraceLens (issue 32; Surface in lens.h and
// trace/kernel.h state the model). Every array is empty for a centred refracting lens without
// obscurations, and the kernel's rotationally symmetric path runs unchanged.
template <typename T>
struct TraceGeometry {
  // K * 5: decenter x, y (mm), tilt x, y, z (deg) of each surface; empty = every surface
  // centred (then flags and aperture_center_mm are empty too).
  std::vector<T> placement;
  std::vector<std::uint8_t> flags;         // K: kPlacement* bits
  std::vector<double> aperture_center_mm;  // K * 2: clear aperture / obscuration centre, or empty
  std::vector<double> obscuration_mm;      // K: central obscuration radius (0 none), or empty
  // K: -1 where the medium after surface k is traversed backwards (after an odd number of
  // mirrors); its index is then negative (TraceLens::index). Empty = all +1.
  std::vector<signed char> medium_sign;

  bool placed() const { return !placement.empty(); }
  T value(int k, int j) const { return placement[static_cast<std::size_t>(k) * 5 + j]; }

  template <typename U, typename Convert>
  TraceGeometry<U> convert(Convert cvt) const {
    TraceGeometry<U> out;
    out.placement.reserve(placement.size());
    for (const T& v : placement) out.placement.push_back(cvt(v));
    out.flags = flags;
    out.aperture_center_mm = aperture_center_mm;
    out.obscuration_mm = obscuration_mm;
    out.medium_sign = medium_sign;
    return out;
  }
};

// The TraceGeometry of a lens's surfaces (placements as T constants).
template <typename T>
TraceGeometry<T> make_trace_geometry(const Lens& lens) {
  TraceGeometry<T> g;
  const std::size_t k_count = lens.surfaces.size();
  if (lens.breaks_symmetry()) {
    g.placement.assign(k_count * 5, K<T>(0.0));
    g.flags.assign(k_count, 0);
    g.aperture_center_mm.assign(k_count * 2, 0.0);
    for (std::size_t k = 0; k < k_count; ++k) {
      const Surface& s = lens.surfaces[k];
      const Placement& p = s.placement;
      const double values[5] = {p.decenter_x_mm, p.decenter_y_mm, p.tilt_x_deg, p.tilt_y_deg,
                                p.tilt_z_deg};
      for (int j = 0; j < 5; ++j) g.placement[k * 5 + j] = K<T>(values[j]);
      g.flags[k] = static_cast<std::uint8_t>((p.tilt_first ? kPlacementTiltFirst : 0) |
                                             (s.coordinate_break ? kPlacementCoordinateBreak : 0) |
                                             (s.restore_frame ? kPlacementRestore : 0) |
                                             (p.any() ? kPlacementMoved : 0));
      g.aperture_center_mm[k * 2] = s.aperture_decenter_x_mm;
      g.aperture_center_mm[k * 2 + 1] = s.aperture_decenter_y_mm;
    }
  }
  bool obscured = false, mirrors = false;
  for (const Surface& s : lens.surfaces) {
    obscured = obscured || s.obscuration_mm > 0.0;
    mirrors = mirrors || s.mirror;
  }
  if (obscured)
    for (const Surface& s : lens.surfaces) g.obscuration_mm.push_back(s.obscuration_mm);
  if (mirrors) {
    signed char sign = 1;
    for (const Surface& s : lens.surfaces) {
      if (s.mirror) sign = static_cast<signed char>(-sign);
      g.medium_sign.push_back(sign);
    }
  }
  return g;
}

template <typename T>
struct TraceLens {
  std::vector<T> curvature_per_mm;  // K
  std::vector<T> thickness_mm;      // K
  std::vector<T> nd;                // K, medium after each surface (1 for air)
  std::vector<T> vd;                // K (0 for air)
  std::vector<char> is_glass;       // K: 0 air, else the ModelGlass of the medium (dispersion.h)
  std::vector<double> model_dpgf;   // K: dPgF of OpticStudio model glasses; empty = all 0
  // Surface profiles (trace/profile.h); all three empty when every surface is a sphere.
  std::vector<std::uint8_t> profile;  // K: kProfileSphere, kProfileConic or kProfileAsphere
  std::vector<T> conic;               // K: conic constant k
  std::vector<T> asphere;             // K * kAsphereTerms: a2, a4, ..., a16 (mm^(1-2i))
  // Catalog-model correction per surface and wavelength (see header); empty for the abbe model.
  std::vector<std::vector<double>> catalog_offset;
  std::vector<double> wavelengths_nm;
  // Clear semi-diameters (mm) per surface, 0 = none; empty = no surface clips (kernel step 5).
  std::vector<double> semi_diameter_mm;
  int stop = 0;
  // 3D placement, mirrors and obscurations (issue 32); all empty for a centred refracting lens.
  TraceGeometry<T> geometry;

  int surface_count() const { return static_cast<int>(curvature_per_mm.size()); }
  // The sign of medium k's index: -1 after an odd number of mirrors (k = -1: object space, +1).
  bool reflected(int k) const {
    return k >= 0 && !geometry.medium_sign.empty() && geometry.medium_sign[k] < 0;
  }
  bool has_profiles() const { return !profile.empty(); }
  // Asphere term j (0 = a2, 1 = a4, ...) of surface k; 0 when the lens has no profiles.
  T asphere_term(int k, int j) const {
    return asphere.empty() ? K<T>(0.0) : asphere[static_cast<std::size_t>(k) * kAsphereTerms + j];
  }
  // The paraxial curvature c + 2 a2 (conic and a4+ add no paraxial power).
  T paraxial_curvature(int k) const {
    return asphere.empty() ? curvature_per_mm[k]
                           : curvature_per_mm[k] + K<T>(2.0) * asphere_term(k, 0);
  }
  // Gives every surface a profile record (spheres), so profile terms can be set.
  void ensure_profiles() {
    if (has_profiles()) return;
    const std::size_t k_count = curvature_per_mm.size();
    profile.assign(k_count, kProfileSphere);
    conic.assign(k_count, K<T>(0.0));
    asphere.assign(k_count * kAsphereTerms, K<T>(0.0));
  }
  // Multiplies every length of the prescription by s: c / s, t s, a_{2i} s^(1-2i).
  void scale_lengths(const T& s) {
    for (int k = 0; k < surface_count(); ++k) {
      curvature_per_mm[k] = curvature_per_mm[k] / s;
      thickness_mm[k] = thickness_mm[k] * s;
    }
    for (std::size_t i = 0; i < geometry.placement.size(); i += 5) {
      geometry.placement[i] = geometry.placement[i] * s;  // decenters; tilts are angles
      geometry.placement[i + 1] = geometry.placement[i + 1] * s;
    }
    if (asphere.empty()) return;
    for (int k = 0; k < surface_count(); ++k) {
      T power = s;  // s^(2i-1) for a_{2i}
      for (int j = 0; j < kAsphereTerms; ++j) {
        T& a = asphere[static_cast<std::size_t>(k) * kAsphereTerms + j];
        a = a / power;
        power = power * s * s;
      }
    }
  }

  // Index of medium k at wavelength number w (k = -1 is object space: 1).
  // A medium traversed backwards (after an odd number of mirrors) has the negative index.
  T index(int k, int w) const {
    if (k < 0 || !is_glass[k]) return reflected(k) ? K<T>(-1.0) : K<T>(1.0);
    T n = model_index(k, wavelengths_nm[w]);
    if (!catalog_offset.empty()) n = n + K<T>(catalog_offset[k][w]);
    return reflected(k) ? -n : n;
  }
  // The model-glass index of medium k (no catalog correction): the paper's or OpticStudio's.
  T model_index(int k, double wavelength_nm) const {
    if (is_glass[k] == static_cast<char>(ModelGlass::kZemax))
      return zemax_model_index(nd[k], vd[k], K<T>(model_dpgf.empty() ? 0.0 : model_dpgf[k]),
                               wavelength_nm);
    return abbe_index(nd[k], vd[k], wavelength_nm);
  }
  // Same at a wavelength given in nm: the traced index (with the catalog correction) when it is
  // one of wavelengths_nm; elsewhere the abbe model's A + B / l^2, which is the lens's own index
  // only for the abbe model: a catalog-model lens holds its catalog's corrections at its own
  // wavelengths alone, so any other wavelength is a caller's error (std::logic_error), not a
  // silent switch of dispersion model.
  T index_at_nm(int k, double wavelength_nm) const {
    if (k < 0 || !is_glass[k]) return reflected(k) ? K<T>(-1.0) : K<T>(1.0);
    for (int w = static_cast<int>(wavelengths_nm.size()) - 1; w >= 0; --w)
      if (wavelengths_nm[w] == wavelength_nm) return index(k, w);
    if (!catalog_offset.empty())
      throw std::logic_error("TraceLens::index_at_nm: " + std::to_string(wavelength_nm) +
                             " nm is not one of the lens's wavelengths (catalog dispersion)");
    return reflected(k) ? -model_index(k, wavelength_nm) : model_index(k, wavelength_nm);
  }
  // The primary (reference) wavelength: the last one.
  double reference_nm() const { return wavelengths_nm.back(); }
};

// TraceLens::is_glass of a material: 0 air; ModelGlass::kZemax for an OpticStudio model glass;
// ModelGlass::kPaper otherwise (the paper's model glass, and catalog glasses, whose catalog
// correction is relative to the paper's model).
inline char trace_glass_kind(const Material& m) {
  if (m.is_air()) return 0;
  if (m.kind == Material::Kind::kModel && m.model_glass == ModelGlass::kZemax)
    return static_cast<char>(ModelGlass::kZemax);
  return static_cast<char>(ModelGlass::kPaper);
}

// The wavelengths a lens is traced at: the specs' wavelengths, then the primary one.
std::vector<double> trace_wavelengths_nm(const Specs& specs);

// Catalog-model corrections n_cat(l) - abbe(nd, vd, l) of one glass at `wavelengths_nm` (see the
// header). Throws Error naming `what` if the glass's formula cannot be evaluated.
std::vector<double> catalog_offsets(const Glass& glass, double nd, double vd,
                                    const std::vector<double>& wavelengths_nm,
                                    const std::string& what);

// Builds the double TraceLens of a lens for its specs' wavelengths and dispersion model: the one
// lens-to-trace builder every consumer uses.
TraceLens<double> make_trace_lens(const Lens& lens);

// Converts a TraceLens to another scalar type: constants, except variables[first + j] for
// j < N which become derivative direction j of a ceres::Jet<double, N>-like scalar U
// (seed(value, j) must build it). Used for gradients in chunks of N variables.
template <typename U, typename T, typename Seed>
TraceLens<U> convert_trace_lens(const TraceLens<T>& in,
                                const std::vector<PrescriptionVariable>& variables, int first,
                                int count, Seed seed) {
  TraceLens<U> out;
  const int k_count = in.surface_count();
  auto cvt = [](const std::vector<T>& v) {
    std::vector<U> r;
    r.reserve(v.size());
    for (const T& x : v) r.push_back(U(x));
    return r;
  };
  out.curvature_per_mm = cvt(in.curvature_per_mm);
  out.thickness_mm = cvt(in.thickness_mm);
  out.nd = cvt(in.nd);
  out.vd = cvt(in.vd);
  out.is_glass = in.is_glass;
  out.model_dpgf = in.model_dpgf;
  out.profile = in.profile;
  out.conic = cvt(in.conic);
  out.asphere = cvt(in.asphere);
  out.catalog_offset = in.catalog_offset;
  out.wavelengths_nm = in.wavelengths_nm;
  out.semi_diameter_mm = in.semi_diameter_mm;
  out.stop = in.stop;
  out.geometry = in.geometry.template convert<U>([](const T& x) { return U(x); });
  (void)k_count;
  for (int j = 0; j < count; ++j) {
    const PrescriptionVariable& v = variables[first + j];
    std::vector<U>* target = nullptr;
    int index = v.surface;
    switch (v.kind) {
      case PrescriptionVariable::Kind::kCurvature:
        target = &out.curvature_per_mm;
        break;
      case PrescriptionVariable::Kind::kThickness:
        target = &out.thickness_mm;
        break;
      case PrescriptionVariable::Kind::kNd:
        target = &out.nd;
        break;
      case PrescriptionVariable::Kind::kVd:
        target = &out.vd;
        break;
      case PrescriptionVariable::Kind::kConic:
      case PrescriptionVariable::Kind::kAsphere: {
        // A seeded profile term needs the profile's own loop even at the value 0.
        out.ensure_profiles();
        std::uint8_t& kind = out.profile[v.surface];
        if (v.kind == PrescriptionVariable::Kind::kConic) {
          target = &out.conic;
          if (kind == kProfileSphere) kind = kProfileConic;
        } else {
          target = &out.asphere;
          index = v.surface * kAsphereTerms + v.term;
          kind = kProfileAsphere;
        }
        break;
      }
    }
    (*target)[index] = seed(value_of((*target)[index]), j);
  }
  return out;
}

}  // namespace lensopt
