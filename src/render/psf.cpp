#include "lensopt/render/psf.h"

#include <fmt/format.h>

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
  std::array<int, kColourChannels> used{};
  for (std::size_t w = 0; w < channels.size(); ++w) {
    if (channels[w] < 0 || channels[w] >= kColourChannels)
      throw Error(fmt::format("wavelength {} has channel {}; channels are 0 (R), 1 (G), 2 (B)",
                              w + 1, channels[w]));
    ++used[channels[w]];
  }
  static const char* kNames[] = {"R", "G", "B"};
  for (int k = 0; k < kColourChannels; ++k)
    if (used[k] == 0)
      throw Error(
          fmt::format("no wavelength is assigned to colour channel {}: an RGB render "
                      "needs at least one wavelength per channel",
                      kNames[k]));
}

}  // namespace lensopt
