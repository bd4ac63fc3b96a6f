// TraceLens<T>: the numbers the tracer needs, on scalar type T (double or a ceres::Jet), built
// from a Lens once. Prescription variables can be seeded as Jet derivative directions.
//
// Surfaces k = 0..K-1: curvature c_k (1/mm), thickness t_k (mm, to surface k+1; t_{K-1} is the
// distance to the image plane), medium after surface k with (nd_k, vd_k) (air: 1, 0).
// Refractive index of medium k at wavelength l:
//   abbe model:     n_k(l) = A_k + B_k / l^2 (glass/dispersion.h)
//   catalog model:  n_k(l) = abbe(nd_k, vd_k, l) + [n_cat(l) - abbe(nd_k0, vd_k0, l)]
// The bracket is a constant per (surface, wavelength), so the catalog model equals the catalog's
// formula at the nominal glass and still carries derivatives with respect to nd and vd.
// Wavelengths: the system's, then its primary (reference) wavelength last; paraxial data at any
// of them use the same index as the real rays (index_at_nm looks the wavelength up).
// make_trace_lens is the one builder from a Lens; the optimizer's forward map
// (LensParameterization::to_trace_lens) fills the same fields through trace_wavelengths_nm and
// catalog_offsets, so every consumer traces with one dispersion model.
#pragma once

#include <string>
#include <vector>

#include "lensopt/core/scalar.h"
#include "lensopt/glass/dispersion.h"
#include "lensopt/lens/lens.h"

namespace lensopt {

// One prescription variable: which number of the lens.
struct PrescriptionVariable {
  enum class Kind { kCurvature, kThickness, kNd, kVd };
  Kind kind = Kind::kCurvature;
  int surface = 0;  // 0-based surface index (for kNd/kVd: the surface the glass follows)

  // "c3", "t5", "nd2", "vd2" (1-based surface numbers, as in the user's view).
  std::string name() const;
};

// Every curvature but the stop's, every thickness, nd and vd of every glass: the 23 variables of
// the Tessar (7 + 8 + 4 + 4).
std::vector<PrescriptionVariable> all_prescription_variables(const Lens& lens);

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
  std::vector<char> is_glass;       // K
  // Catalog-model correction per surface and wavelength (see header); empty for the abbe model.
  std::vector<std::vector<double>> catalog_offset;
  std::vector<double> wavelengths_nm;
  // Clear semi-diameters (mm) per surface, 0 = none; empty = no surface clips (kernel step 5).
  std::vector<double> semi_diameter_mm;
  int stop = 0;

  int surface_count() const { return static_cast<int>(curvature_per_mm.size()); }

  // Index of medium k at wavelength number w (k = -1 is object space: 1).
  T index(int k, int w) const {
    if (k < 0 || !is_glass[k]) return K<T>(1.0);
    T n = abbe_index(nd[k], vd[k], wavelengths_nm[w]);
    if (!catalog_offset.empty()) n = n + K<T>(catalog_offset[k][w]);
    return n;
  }
  // Same at a wavelength given in nm: the traced index (with the catalog correction) when it is
  // one of wavelengths_nm, else the abbe model.
  T index_at_nm(int k, double wavelength_nm) const {
    if (k < 0 || !is_glass[k]) return K<T>(1.0);
    for (int w = static_cast<int>(wavelengths_nm.size()) - 1; w >= 0; --w)
      if (wavelengths_nm[w] == wavelength_nm) return index(k, w);
    return abbe_index(nd[k], vd[k], wavelength_nm);
  }
  // The primary (reference) wavelength: the last one.
  double reference_nm() const { return wavelengths_nm.back(); }
};

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
  out.catalog_offset = in.catalog_offset;
  out.wavelengths_nm = in.wavelengths_nm;
  out.semi_diameter_mm = in.semi_diameter_mm;
  out.stop = in.stop;
  (void)k_count;
  for (int j = 0; j < count; ++j) {
    const PrescriptionVariable& v = variables[first + j];
    std::vector<U>* target = nullptr;
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
    }
    (*target)[v.surface] = seed(value_of((*target)[v.surface]), j);
  }
  return out;
}

}  // namespace lensopt
