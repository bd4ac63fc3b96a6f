// The rotationally symmetric fast path stays bit-identical (issue 32): the kernel's driver
// (trace_bundle) before the 3D-placement work, copied verbatim below from main @ b3e6a74 as
// main_trace_bundle, against today's trace_bundle on every shipped lens, every field and
// wavelength, with and without the loss records and the optical path; double and Jet. Both call
// the same per-surface loops (trace_surface_double, the profile loops), so equal bits mean the
// driver (the per-surface dispatch moved into detail::intersect_surface, the 3D-placement branch,
// the obscuration step) changed nothing for a lens without placements.
#include <ceres/jet.h>
#include <doctest/doctest.h>

#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "lensopt/formats/lens_file.h"
#include "lensopt/trace/kernel.h"
#include "lensopt/trace/system.h"
#include "test_support.h"

namespace lensopt::test_trace_fastpath {
namespace {

// ---- main @ b3e6a74, include/lensopt/trace/kernel.h trace_bundle, renamed. ----
template <typename T>
void main_trace_bundle(const TraceLens<T>& lens, int w, int end, bool to_image, RayBundle<T>& rays,
                       RayRecord<T>* record) {
  using std::sqrt;
  const std::size_t count = rays.size();
  const T one = K<T>(1.0);
  const T zero = K<T>(0.0);
  T* x = rays.x.data();
  T* y = rays.y.data();
  T* z = rays.z.data();
  T* l = rays.l.data();
  T* m = rays.m.data();
  T* n = rays.n.data();
  std::uint8_t* status = rays.status.data();
  std::int8_t* failed_at = rays.failed_surface.data();
  rays.failure_scratch.resize(count);
  std::int32_t* failure = rays.failure_scratch.data();
  // Optical path: only on the recording path, so the plain trace is untouched.
  const bool path = record && record->optical_path_mm.size() == count;
  T* opl = path ? record->optical_path_mm.data() : nullptr;
  T* start_z = path ? record->path_start_z.data() : nullptr;
  T* start_n = path ? record->path_start_n.data() : nullptr;

  // A ray must travel forwards. The checks below first ask whether any ray needs the
  // bookkeeping (a reduction that vectorizes), so a bundle without failures, the usual case,
  // skips the per-ray status loops.
  if (detail::any_not_forward(n, count)) {
    for (std::size_t i = 0; i < count; ++i) {
      if (!(n[i] > zero) && status[i] == kRayOk) {
        status[i] = kRayBackwards;
        failed_at[i] = 0;
        n[i] = one;
      }
    }
  }

  for (int k = 0; k < end; ++k) {
    const T c = lens.curvature_per_mm[k];
    const T shift = k > 0 ? lens.thickness_mm[k - 1] : zero;
    const T mu = lens.index(k - 1, w) / lens.index(k, w);
    if (path) {
      for (std::size_t i = 0; i < count; ++i) {
        start_z[i] = z[i] - shift;
        start_n[i] = n[i] > zero ? n[i] : one;  // a backwards ray is flagged; keep it finite
      }
    }
    const std::uint8_t profile = lens.has_profiles() ? lens.profile[k] : kProfileSphere;
    if (profile != kProfileSphere) {
      // Conic or even asphere (trace/profile.h).
      T* travel = record && k > 0 ? record->axial_travel_mm[k - 1].data() : nullptr;
      T* zeta_rec = record ? record->cos2_incidence[k].data() : nullptr;
      T* zeta_prime_rec = record ? record->cos2_refraction[k].data() : nullptr;
      const T& conic = lens.conic[k];
      const T* a = lens.asphere.data() + static_cast<std::size_t>(k) * kAsphereTerms;
      if constexpr (std::is_same_v<T, double>) {
        detail::trace_surface_profile_double(profile, c, conic, a, shift, mu, count, x, y, z, l, m,
                                             n, failure, travel, zeta_rec, zeta_prime_rec,
                                             record != nullptr);
      } else if (profile == kProfileConic) {
        if (record)
          detail::trace_surface_conic<T, true>(c, conic, shift, mu, count, x, y, z, l, m, n,
                                               failure, travel, zeta_rec, zeta_prime_rec);
        else
          detail::trace_surface_conic<T, false>(c, conic, shift, mu, count, x, y, z, l, m, n,
                                                failure, nullptr, nullptr, nullptr);
      } else if (record) {
        detail::trace_surface_asphere<T, true>(c, conic, a, shift, mu, count, x, y, z, l, m, n,
                                               failure, travel, zeta_rec, zeta_prime_rec);
      } else {
        detail::trace_surface_asphere<T, false>(c, conic, a, shift, mu, count, x, y, z, l, m, n,
                                                failure, nullptr, nullptr, nullptr);
      }
    } else if constexpr (std::is_same_v<T, double>) {
      detail::trace_surface_double(
          c, shift, mu, count, x, y, z, l, m, n, failure,
          record && k > 0 ? record->axial_travel_mm[k - 1].data() : nullptr,
          record ? record->cos2_incidence[k].data() : nullptr,
          record ? record->cos2_refraction[k].data() : nullptr, record != nullptr);
    } else if (record) {
      detail::trace_surface<T, true>(c, shift, mu, count, x, y, z, l, m, n, failure,
                                     k > 0 ? record->axial_travel_mm[k - 1].data() : nullptr,
                                     record->cos2_incidence[k].data(),
                                     record->cos2_refraction[k].data());
    } else {
      detail::trace_surface<T, false>(c, shift, mu, count, x, y, z, l, m, n, failure, nullptr,
                                      nullptr, nullptr);
    }
    // Step 5: the clear aperture of surface k, if it has one.
    if (!lens.semi_diameter_mm.empty() && lens.semi_diameter_mm[k] > 0.0) {
      const T limit = K<T>(lens.semi_diameter_mm[k] * lens.semi_diameter_mm[k]);
      for (std::size_t i = 0; i < count; ++i) {
        const bool outside = x[i] * x[i] + y[i] * y[i] > limit;
        failure[i] = (outside && failure[i] == kRayOk) ? std::int32_t{kRayVignetted} : failure[i];
      }
    }
    if (path) {
      const T n_before = lens.index(k - 1, w);
      for (std::size_t i = 0; i < count; ++i)
        opl[i] = opl[i] + n_before * (z[i] - start_z[i]) / start_n[i];
    }
    // The first failure of a ray wins.
    std::int32_t any_failure = 0;
    for (std::size_t i = 0; i < count; ++i) any_failure |= failure[i];
    if (any_failure != 0) {
      for (std::size_t i = 0; i < count; ++i) {
        if (failure[i] != kRayOk && status[i] == kRayOk) {
          status[i] = static_cast<std::uint8_t>(failure[i]);
          failed_at[i] = static_cast<std::int8_t>(k);
        }
      }
    }
  }

  if (to_image) {
    const int last = lens.surface_count() - 1;
    const T t = lens.thickness_mm[last];
    T* travel = record ? record->axial_travel_mm[last].data() : nullptr;
    const T n_image = path ? lens.index(last, w) : one;
    if (!travel && !path && !detail::any_not_forward(n, count)) {
      // Every ray travels forwards: the same transfer without the per-ray branch.
      for (std::size_t i = 0; i < count; ++i) {
        const T s = -(z[i] - t) / n[i];
        x[i] = x[i] + s * l[i];
        y[i] = y[i] + s * m[i];
        z[i] = zero;
      }
      return;
    }
    for (std::size_t i = 0; i < count; ++i) {
      const T z_rel = z[i] - t;
      if (travel) travel[i] = -z_rel;
      if (!(n[i] > zero)) {
        if (status[i] == kRayOk) {
          status[i] = kRayBackwards;
          failed_at[i] = static_cast<std::int8_t>(last);
        }
        continue;
      }
      const T s = -z_rel / n[i];
      if (path) opl[i] = opl[i] + n_image * s;
      x[i] = x[i] + s * l[i];
      y[i] = y[i] + s * m[i];
      z[i] = zero;
    }
  }
}

// ---- end of the copy. ----

template <typename T>
bool same_bits(const std::vector<T>& a, const std::vector<T>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0;
}

template <typename T>
void compare_on(const TraceSystem<T>& sys, const std::string& name, int& compared) {
  const int k_count = sys.lens.surface_count();
  for (std::size_t h = 0; h < sys.fields_deg.size(); ++h)
    for (int w = 0; w <= sys.wavelength_count; ++w)
      for (int mode = 0; mode < 3; ++mode) {
        CAPTURE(name);
        CAPTURE(h);
        CAPTURE(w);
        CAPTURE(mode);
        RayBundle<T> a, b;
        start_rays(sys, static_cast<int>(h), w, a);
        start_rays(sys, static_cast<int>(h), w, b);
        RayRecord<T> ra, rb;
        RayRecord<T>* pa = nullptr;
        RayRecord<T>* pb = nullptr;
        if (mode > 0) {
          ra.resize(k_count, a.size(), mode == 2);
          rb.resize(k_count, b.size(), mode == 2);
          pa = &ra;
          pb = &rb;
        }
        trace_bundle(sys.lens, w, k_count, true, a, pa);
        main_trace_bundle(sys.lens, w, k_count, true, b, pb);
        if constexpr (std::is_same_v<T, double>) {
          CHECK(same_bits(a.x, b.x));
          CHECK(same_bits(a.y, b.y));
          CHECK(same_bits(a.l, b.l));
          CHECK(same_bits(a.m, b.m));
          CHECK(same_bits(a.n, b.n));
          if (mode == 2) {
            CHECK(same_bits(ra.optical_path_mm, rb.optical_path_mm));
          }
          if (mode > 0)
            for (int k = 0; k < k_count; ++k) {
              CHECK(same_bits(ra.axial_travel_mm[k], rb.axial_travel_mm[k]));
              CHECK(same_bits(ra.cos2_incidence[k], rb.cos2_incidence[k]));
            }
        } else {
          for (std::size_t i = 0; i < a.size(); ++i) {
            CHECK(a.x[i].a == b.x[i].a);
            CHECK(a.y[i].a == b.y[i].a);
            for (int j = 0; j < T::DIMENSION; ++j) {
              CHECK(a.x[i].v[j] == b.x[i].v[j]);
              CHECK(a.y[i].v[j] == b.y[i].v[j]);
            }
          }
        }
        CHECK(a.status == b.status);
        CHECK(a.failed_surface == b.failed_surface);
        ++compared;
      }
}

}  // namespace

TEST_CASE("trace fast path: bit-identical to main's driver on every shipped lens") {
  std::vector<std::filesystem::path> files;
  for (const char* folder : {"lenses", "lenses/zmx", "lenses/starts"})
    for (const auto& e : std::filesystem::directory_iterator(test::source_dir() / folder)) {
      const std::string ext = e.path().extension().string();
      if (ext == ".toml" || ext == ".zmx") files.push_back(e.path());
    }
  std::sort(files.begin(), files.end());
  REQUIRE(files.size() >= 10);
  TraceOptions options;
  options.rings = 6;
  options.threads = 1;
  int compared = 0, lenses = 0;
  for (const auto& path : files) {
    const Lens lens = read_lens(path);
    REQUIRE_FALSE(lens.breaks_symmetry());
    const TraceSystem<double> sys = prepare_lens_system(lens, options);
    REQUIRE_FALSE(sys.lens.geometry.placed());
    compare_on(sys, path.filename().string(), compared);
    ++lenses;
  }
  MESSAGE(lenses << " lenses, " << compared << " bundles compared");
  CHECK(compared > 100);
}

TEST_CASE("trace fast path: Jets bit-identical to main's driver") {
  using J = ceres::Jet<double, 3>;
  const Lens lens = read_lens(test::source_dir() / "lenses" / "tessar.toml");
  TraceOptions options;
  options.rings = 4;
  options.threads = 1;
  const TraceSystem<double> sys = prepare_lens_system(lens, options);
  TraceSystem<J> sj;
  sj.lens = convert_trace_lens<J>(sys.lens, all_prescription_variables(lens), 0, 3,
                                  [](double v, int j) { return J(v, j); });
  sj.scale = J(value_of(sys.scale));
  sj.epd_mm = J(sys.epd_mm);
  sj.entrance_pupil_z_mm = J(sys.entrance_pupil_z_mm);
  sj.fields_deg = sys.fields_deg;
  sj.object_distance_mm = sys.object_distance_mm;
  sj.field_object_y_mm = sys.field_object_y_mm;
  sj.vignetting = sys.vignetting;
  sj.wavelength_count = sys.wavelength_count;
  sj.pupil = sys.pupil;
  for (const PupilMap<double>& m : sys.pupil_maps)
    sj.pupil_maps.push_back({J(m.scale_x), J(m.offset_y), J(m.scale_y)});
  int compared = 0;
  compare_on(sj, "tessar (Jet)", compared);
  CHECK(compared > 10);
}

}  // namespace lensopt::test_trace_fastpath
