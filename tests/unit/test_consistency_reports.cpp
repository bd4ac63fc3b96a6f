// The designer's reports agree with analyze: the field sweep (MTF and RMS spot vs field, the
// mtf-field plot's data) on analyze's own system gives analyze's RMS spot, distortion and
// diffraction MTF exactly, and on the plot's finer field grid the same numbers at the fields the
// two grids share; encircled energy is centred on analyze's centroids.
#include <doctest/doctest.h>

#include <cmath>
#include <string>
#include <vector>

#include "lensopt/analysis/analyze.h"
#include "lensopt/analysis/encircled_energy.h"
#include "lensopt/analysis/field_sweep.h"
#include "lensopt/formats/lens_file.h"
#include "test_support.h"

namespace test_consistency_reports {

using namespace lensopt;

TEST_CASE("consistency: the field sweep and encircled energy read analyze's numbers") {
  const auto src = lensopt::test::source_dir();
  for (const std::string name : {"lenses/tessar.toml", "lenses/zmx/cooke_triplet_50.zmx"}) {
    CAPTURE(name);
    const Lens lens = read_lens(src / name);
    AnalyzeOptions options;
    options.trace.rings = 8;
    options.trace.fields = 11;
    options.wave = true;
    options.wave_options.pupil_samples = 32;
    options.mtf_frequencies_cyc_mm = {10, 30};
    const AnalysisReport report = analyze_lens(lens, options);
    REQUIRE(report.wave);
    const TraceSystem<double> sys = prepare_lens_system(lens, options.trace);
    WaveOptions wave = options.wave_options;
    wave.wavelength_weights = lens_wavelength_weights(lens, sys.wavelength_count);
    const FieldSweep own = field_sweep(sys, wave, options.mtf_frequencies_cyc_mm);
    REQUIRE(own.field_deg.size() == report.fields.size());
    for (std::size_t h = 0; h < report.fields.size(); ++h) {
      CAPTURE(h);
      const FieldReport& f = report.fields[h];
      REQUIRE(f.rms_spot_um);
      CHECK(own.rms_spot_um[h] == *f.rms_spot_um);
      CHECK(own.distortion_percent[h] == f.distortion_percent);
      for (std::size_t k = 0; k < 2; ++k) {
        CHECK(own.mtf_t[k][h] == report.wave->fields[h].mtf_t[k]);
        CHECK(own.mtf_s[k][h] == report.wave->fields[h].mtf_s[k]);
      }
    }
    // The plot's grid (21 angles from the axis to the largest field): the same numbers where the
    // grids meet.
    const TraceSystem<double> fine = field_sweep_system(lens, sys, options.trace, 21);
    const FieldSweep sweep = field_sweep(fine, wave, options.mtf_frequencies_cyc_mm);
    int shared = 0;
    for (std::size_t h = 0; h < report.fields.size(); ++h)
      for (std::size_t j = 0; j < sweep.field_deg.size(); ++j) {
        if (std::abs(sweep.field_deg[j] - report.fields[h].field_deg) > 1e-12) continue;
        ++shared;
        CAPTURE(sweep.field_deg[j]);
        CHECK(sweep.rms_spot_um[j] == doctest::Approx(own.rms_spot_um[h]).epsilon(1e-9));
        CHECK(sweep.distortion_percent[j] ==
              doctest::Approx(own.distortion_percent[h]).epsilon(1e-9).scale(1e-9));
        for (std::size_t k = 0; k < 2; ++k) {
          CHECK(sweep.mtf_t[k][j] == doctest::Approx(own.mtf_t[k][h]).epsilon(1e-9));
          CHECK(sweep.mtf_s[k][j] == doctest::Approx(own.mtf_s[k][h]).epsilon(1e-9));
        }
      }
    MESSAGE(shared << " fields shared");
    CHECK(shared >= 2);
    // Encircled energy about analyze's centroids.
    EncircledEnergyOptions eo;
    eo.wave = wave;
    eo.field_indices = {0, static_cast<int>(sys.fields_deg.size()) - 1};
    const EncircledEnergy ee = encircled_energy(sys, eo);
    REQUIRE(ee.fields.size() == 2);
    for (const FieldEncircledEnergy& f : ee.fields) {
      CHECK(f.centroid_y_mm == report.fields[f.field].centroid_y_mm);
      CHECK(f.rays == report.fields[f.field].traced_rays);
      CHECK(f.geometric.back() == 1.0);  // the radii reach the farthest ray
      REQUIRE(f.diffraction.size() >= 2);
      CHECK(f.diffraction.size() <= ee.radius_um.size());
      for (std::size_t i = 1; i < ee.radius_um.size(); ++i)
        CHECK(f.geometric[i] >= f.geometric[i - 1]);
      // The PSF is |U|^2 >= 0: its encircled energy never falls (float samples: 1e-6).
      for (std::size_t i = 1; i < f.diffraction.size(); ++i) {
        CHECK(f.diffraction[i] >= f.diffraction[i - 1] - 1e-6);
        CHECK(f.diffraction[i] <= 1.0 + 1e-6);
      }
    }
  }
}

}  // namespace test_consistency_reports
