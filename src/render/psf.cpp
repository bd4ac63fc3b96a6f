#include "lensopt/render/psf.h"

#include <fmt/format.h>

#include <cmath>

#include "lensopt/core/error.h"

namespace lensopt {

void PsfOptions::validate() const {
  if (grid_size < 3 || grid_size > 1025 || grid_size % 2 == 0)
    throw Error(fmt::format("PSF grid size {} must be odd and in [3, 1025]", grid_size));
  if (!(bin_um > 0.0) || !(bin_um < 1000.0))
    throw Error(fmt::format("PSF bin width {} um must be in (0, 1000)", bin_um));
  if (!(sigma_bins > 0.0) || !(sigma_bins <= 4.0))
    throw Error(fmt::format("PSF kernel sigma {} bins must be in (0, 4]", sigma_bins));
  if (support_bins < 1 || support_bins > 8)
    throw Error(fmt::format("PSF kernel support {} bins must be in [1, 8]", support_bins));
  if (support_bins + 0.5 < 2.5 * sigma_bins)
    throw Error(fmt::format("PSF kernel support {} bins is too small for sigma {} bins",
                            support_bins, sigma_bins));
}

void validate_wavelength_channels(const std::vector<int>& channels, int wavelength_count) {
  if (static_cast<int>(channels.size()) != wavelength_count)
    throw Error(
        fmt::format("{} wavelength channels for {} wavelengths: give one channel (R, G or "
                    "B) per wavelength",
                    channels.size(), wavelength_count));
  for (std::size_t w = 0; w < channels.size(); ++w) {
    if (channels[w] < 0 || channels[w] >= kColourChannels)
      throw Error(fmt::format("wavelength {} has channel {}; channels are 0 (R), 1 (G), 2 (B)",
                              w + 1, channels[w]));
  }
}

std::array<std::vector<int>, kColourChannels> channel_wavelengths(
    const std::vector<int>& channels, const std::vector<double>& wavelengths_nm) {
  constexpr std::array<double, kColourChannels> kCentreNm = {620.0, 550.0, 460.0};
  std::array<std::vector<int>, kColourChannels> out;
  for (std::size_t w = 0; w < channels.size(); ++w)
    if (channels[w] >= 0 && channels[w] < kColourChannels)
      out[channels[w]].push_back(static_cast<int>(w));
  for (int k = 0; k < kColourChannels; ++k) {
    if (!out[k].empty() || wavelengths_nm.empty()) continue;
    std::size_t best = 0;
    for (std::size_t w = 1; w < wavelengths_nm.size(); ++w)
      if (std::abs(wavelengths_nm[w] - kCentreNm[k]) <
          std::abs(wavelengths_nm[best] - kCentreNm[k]))
        best = w;
    out[k].push_back(static_cast<int>(best));
  }
  return out;
}

}  // namespace lensopt
