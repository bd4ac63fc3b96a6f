// Image-quality metrics between a reference image x and a test image y (the paper reports them
// between the scene image and its blurred version, before relative illumination and distortion).
//
// PSNR = 10 log10(L^2 / MSE), MSE over every pixel of the compared channels, L = 1 (the peak of
// a [0, 1] image). Identical images have PSNR = +inf.
// SSIM (Wang et al. 2004): per channel, with Gaussian-weighted local statistics (11 x 11 window,
// sigma 1.5, weights summing to 1) at every position where the window lies inside the image,
//   SSIM = ((2 mu_x mu_y + C1)(2 s_xy + C2)) / ((mu_x^2 + mu_y^2 + C1)(s_x^2 + s_y^2 + C2)),
// C1 = (0.01 L)^2, C2 = (0.03 L)^2; the mean over positions, then over channels.
#pragma once

#include "lensopt/render/image.h"

namespace lensopt {

// Over channels [0, channels) of both images (same size). Throws Error for mismatched sizes.
double psnr_db(const FloatImage& x, const FloatImage& y, int channels, int threads = 0);

// Over channels [0, channels). Images smaller than the 11 x 11 window in a direction use the
// largest odd window that fits (same sigma). Throws Error for mismatched sizes.
double ssim(const FloatImage& x, const FloatImage& y, int channels, int threads = 0);

}  // namespace lensopt
