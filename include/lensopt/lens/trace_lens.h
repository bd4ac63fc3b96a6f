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

  int surface_count() const { return static_cast<int>(curvature_per_mm.size()); }
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
  T index(int k, int w) const {
    if (k < 0 || !is_glass[k]) return K<T>(1.0);
    T n = model_index(k, wavelengths_nm[w]);
    if (!catalog_offset.empty()) n = n + K<T>(catalog_offset[k][w]);
    return n;
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
    if (k < 0 || !is_glass[k]) return K<T>(1.0);
    for (int w = static_cast<int>(wavelengths_nm.size()) - 1; w >= 0; --w)
      if (wavelengths_nm[w] == wavelength_nm) return index(k, w);
    if (!catalog_offset.empty())
      throw std::logic_error("TraceLens::index_at_nm: " + std::to_string(wavelength_nm) +
                             " nm is not one of the lens's wavelengths (catalog dispersion)");
    return model_index(k, wavelength_nm);
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
