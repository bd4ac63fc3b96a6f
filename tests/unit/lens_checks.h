// Lens comparisons shared by the format tests (TOML, .zmx round trips).
#pragma once

#include <doctest/doctest.h>

#include <bit>
#include <cstdint>

#include "lensopt/lens/lens.h"

namespace lensopt::test {

inline std::uint64_t bits(double x) {
  return std::bit_cast<std::uint64_t>(x);
}

// Every field of two lenses equal, doubles bit for bit.
inline void check_identical_lenses(const Lens& a, const Lens& b) {
  CHECK(a.name == b.name);
  CHECK(a.catalog_name == b.catalog_name);
  CHECK(a.extra_toml == b.extra_toml);
  CHECK(bits(a.specs.f_number) == bits(b.specs.f_number));
  CHECK(bits(a.specs.half_field_deg) == bits(b.specs.half_field_deg));
  CHECK(bits(a.specs.sensor_diagonal_mm) == bits(b.specs.sensor_diagonal_mm));
  REQUIRE(a.specs.wavelengths_nm.size() == b.specs.wavelengths_nm.size());
  for (std::size_t i = 0; i < a.specs.wavelengths_nm.size(); ++i)
    CHECK(bits(a.specs.wavelengths_nm[i]) == bits(b.specs.wavelengths_nm[i]));
  CHECK(a.specs.wavelength_channels == b.specs.wavelength_channels);
  CHECK(a.specs.dispersion == b.specs.dispersion);
  REQUIRE(a.surfaces.size() == b.surfaces.size());
  for (std::size_t i = 0; i < a.surfaces.size(); ++i) {
    CAPTURE(i);
    const Surface& s = a.surfaces[i];
    const Surface& t = b.surfaces[i];
    CHECK(bits(s.curvature_per_mm) == bits(t.curvature_per_mm));
    CHECK(bits(s.thickness_mm) == bits(t.thickness_mm));
    CHECK(bits(s.semi_diameter_mm) == bits(t.semi_diameter_mm));
    CHECK(s.is_stop == t.is_stop);
    CHECK(s.material.kind == t.material.kind);
    CHECK(s.material.glass_name == t.material.glass_name);
    CHECK(bits(s.material.nd) == bits(t.material.nd));
    CHECK(bits(s.material.vd) == bits(t.material.vd));
    CHECK(bits(s.conic) == bits(t.conic));
    CHECK(bits(s.asphere_r2_per_mm) == bits(t.asphere_r2_per_mm));
    for (std::size_t j = 0; j < s.asphere.size(); ++j)
      CHECK(bits(s.asphere[j]) == bits(t.asphere[j]));
  }
}

}  // namespace lensopt::test
