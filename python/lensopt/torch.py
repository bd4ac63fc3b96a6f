"""lensopt in PyTorch: differentiable image formation and the paper's lens losses.

ImageFormation is an nn.Module whose parameter `x` holds the paper's lens variables (normalized
curvatures c' = c f, spacings s' = t / f with the last one the defocus, and two whitened glass
variables per glass; lensopt.Parameterization names them). Its forward takes B x C x H x W images
(linear light, channels R, G, B, further ones copied) on any device and returns the aberrated
images: the spatially varying PSF blur, relative illumination and distortion of the lens, as
`lensopt render` forms them. The full image spans the sensor diagonal.

How the gradient flows: the optics (PSFs, relative illumination, distortion nodes) and their
exact derivatives wrt x come from lensopt's Jets (forward-mode, in C++); the image operations and
their adjoints (wrt the PSFs and maps, and wrt the input image) run in lensopt's C++ renderer on
the CPU (FFT convolution per patch). A torch.autograd.Function chains torch's gradient of the
output into dL/dx and dL/dimage; images are moved to the CPU for the optics and the result back
to the input's device, so the rest of a network stays on its GPU.

Glasses (glass_mode="quantized", the paper's): the forward pass uses the nearest catalog glass
and the gradient passes straight through to the continuous g; l_GV pulls g towards its glass.
Because the quantized forward pass is piecewise constant in g, finite differences (gradcheck)
only agree with glass_mode="continuous".

The lens losses (spot_loss, l_RP, l_RA, l_GV, lens_loss) are torch functions of x with exact
gradients (Jets), so the paper's l_joint = l_task + lambda_lens l_lens is written in plain
PyTorch:

    optics = ImageFormation(lensopt.load_lens("lenses/doublet.toml"))
    restored = net(optics(sharp))
    loss = mse(restored, sharp) + optics.lens_loss()
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from . import _lensopt

__all__ = [
    "ImageFormation",
    "lens_loss_terms",
    "spot_loss",
    "l_RP",
    "l_RA",
    "l_GV",
    "lens_loss",
]


def _numpy_x(x: torch.Tensor) -> np.ndarray:
    return x.detach().to("cpu", torch.float64).contiguous().numpy()


class _ImageFormationFunction(torch.autograd.Function):
    """images' = A(x) images: forward by lensopt's renderer, backward by its adjoints."""

    @staticmethod
    def forward(ctx, x, images, module, crop=None):
        if images.dim() != 4:
            raise ValueError("images must be B x C x H x W")
        module._prepare(x, derivatives=module._derivatives)
        scenes = images.detach().to("cpu", torch.float64).permute(0, 2, 3, 1).contiguous().numpy()
        rendered = [module.imaging.render(scene, crop) for scene in scenes]
        out = torch.from_numpy(np.stack(rendered)).permute(0, 3, 1, 2)
        ctx.module = module
        ctx.crop = crop
        ctx.x = x.detach().clone()
        ctx.save_for_backward(images)
        return out.to(device=images.device, dtype=images.dtype).contiguous()

    @staticmethod
    def backward(ctx, grad_output):
        (images,) = ctx.saved_tensors
        module = ctx.module
        need_x, need_images = ctx.needs_input_grad[0], ctx.needs_input_grad[1]
        # The adjoints need the optics' derivatives (the lens part is what costs; the scene
        # part alone is the correlation with the patch kernels).
        module._prepare(ctx.x, derivatives=True)
        scenes = images.detach().to("cpu", torch.float64).permute(0, 2, 3, 1).contiguous().numpy()
        grads = grad_output.detach().to("cpu", torch.float64).permute(0, 2, 3, 1).contiguous().numpy()
        grad_x = np.zeros(module.param.size)
        grad_images = []
        for scene, grad in zip(scenes, grads):
            gx, gs = module.imaging.backward(scene, ctx.crop, grad, need_images)
            grad_x += gx
            if need_images:
                grad_images.append(gs)
        gx_t = None
        if need_x:
            gx_t = torch.from_numpy(grad_x).to(device=ctx.x.device, dtype=ctx.x.dtype)
        gi_t = None
        if need_images:
            gi_t = torch.from_numpy(np.stack(grad_images)).permute(0, 3, 1, 2)
            gi_t = gi_t.to(device=images.device, dtype=images.dtype).contiguous()
        return gx_t, gi_t, None, None


class _LensLossFunction(torch.autograd.Function):
    """(l_S, l_RP, l_RA, l_GV) of x; the backward is the gradient of sum_i w_i l_i with the
    incoming gradients as weights (one Jet evaluation per sign)."""

    @staticmethod
    def forward(ctx, x, param, options):
        v = _numpy_x(x)
        r = param.design_loss(v, gradient=False, **options)
        ctx.param, ctx.options, ctx.v = param, options, v
        ctx.x_meta = (x.device, x.dtype)
        terms = [r["spot_mm"], r["ray_path_mm"], r["ray_angle"], r["glass"]]
        return torch.tensor(terms, dtype=x.dtype, device=x.device)

    @staticmethod
    def backward(ctx, grad_terms):
        w = grad_terms.detach().to("cpu", torch.float64).numpy()
        names = ("weight_spot", "weight_ray_path", "weight_ray_angle", "weight_glass")
        grad = np.zeros(ctx.param.size)
        for sign in (1.0, -1.0):
            weights = np.maximum(sign * w, 0.0)
            if not weights.any():
                continue
            kw = dict(ctx.options)
            kw.update({n: float(v) for n, v in zip(names, weights)})
            grad += sign * ctx.param.design_loss(ctx.v, gradient=True, **kw)["gradient"]
        device, dtype = ctx.x_meta
        return torch.from_numpy(grad).to(device=device, dtype=dtype), None, None


def lens_loss_terms(x: torch.Tensor, param, *, rings: int = 8, fields: int = 11,
                    glass_mode: str = "quantized", paper_penalties: bool = False) -> torch.Tensor:
    """The paper's lens-loss terms (l_S in mm, l_RP in mm, l_RA, l_GV) of lens variables x, a
    differentiable tensor of 4 values. param: the lensopt.Parameterization of x."""
    options = dict(rings=rings, fields=fields, glass_mode=glass_mode,
                   paper_penalties=paper_penalties)
    return _LensLossFunction.apply(x, param, options)


def spot_loss(x: torch.Tensor, param, **options) -> torch.Tensor:
    """l_S: the mean over fields of the RMS spot radius (mm) of lens variables x."""
    return lens_loss_terms(x, param, **options)[0]


def l_RP(x: torch.Tensor, param, **options) -> torch.Tensor:
    """l_RP: the ray-path penalty (mm; glass and air thickness bounds along every ray)."""
    return lens_loss_terms(x, param, **options)[1]


def l_RA(x: torch.Tensor, param, **options) -> torch.Tensor:
    """l_RA: the ray-angle penalty (incidence and refraction angles above 60 deg)."""
    return lens_loss_terms(x, param, **options)[2]


def l_GV(x: torch.Tensor, param, **options) -> torch.Tensor:
    """l_GV: the squared whitened distance of each glass variable pair to its nearest glass."""
    return lens_loss_terms(x, param, **options)[3]


def lens_loss(x: torch.Tensor, param, *, lambda_rp: float = 100.0, lambda_ra: float = 100.0,
              lambda_gv: float = 0.01, **options) -> torch.Tensor:
    """The paper's l_lens = l_S + lambda_RP l_RP + lambda_RA l_RA + lambda_GV l_GV."""
    t = lens_loss_terms(x, param, **options)
    return t[0] + lambda_rp * t[1] + lambda_ra * t[2] + lambda_gv * t[3]


class ImageFormation(nn.Module):
    """Differentiable image formation through a lens; the parameter `x` is the lens variables.

    Args:
        lens: a lensopt.Lens (its structure is fixed; x starts at its variables).
        catalog: glass catalog of the glass variables (default: the lens's, else "ohara").
        glass_mode: "quantized" (the paper's straight-through glasses), "continuous" or "fixed".
        rings, fields: PSF ray sampling (default the joint optimization's: 8 rings, 21 fields).
        grid_size, bin_um, sigma_bins, support_bins: the PSF grid and KDE (support_bins=3 is the
            joint optimization's; 2 with rings=32 is `lensopt render`'s).
        relative_illumination, distortion: apply (and differentiate) them.
        freeze: variable names or groups ("curvatures", "spacings", "glasses", "c3") whose
            gradient is zeroed.
        threads: threads of the C++ optics and rendering (0: all cores).

    forward(images, crop=None): B x C x H x W -> B x C x H x W (or the crop's h x w), same
    device and dtype.
    """

    def __init__(self, lens, *, catalog: str = "", glass_mode: str = "quantized", rings: int = 8,
                 fields: int = 21, grid_size: int = 65, bin_um: float = 4.0,
                 sigma_bins: float = 0.5, support_bins: int = 3,
                 relative_illumination: bool = True, distortion: bool = True,
                 paraxial_image_solve: bool = True, freeze=(), threads: int = 0):
        super().__init__()
        self.param = _lensopt.Parameterization(lens, catalog=catalog,
                                               paraxial_image_solve=paraxial_image_solve)
        self.glass_mode = glass_mode
        self.imaging = _lensopt.Imaging(
            self.param, glass_mode=glass_mode, rings=rings, fields=fields, grid_size=grid_size,
            bin_um=bin_um, sigma_bins=sigma_bins, support_bins=support_bins,
            relative_illumination=relative_illumination, distortion=distortion, threads=threads)
        self.x = nn.Parameter(torch.from_numpy(self.param.from_lens(lens)))
        mask = torch.ones(self.param.size, dtype=torch.float64)
        if freeze:
            mask[list(self.param.select(list(freeze)))] = 0.0
            self.x.register_hook(lambda g: g * self.frozen_mask.to(g))
        self.register_buffer("frozen_mask", mask, persistent=False)
        self._prepared = None  # (x values, with derivatives)
        self._derivatives = True

    @property
    def names(self):
        """The variables' names ("c1", "s2", "defocus", "g1.0", ...)."""
        return self.param.names

    def _prepare(self, x: torch.Tensor, derivatives: bool):
        v = _numpy_x(x)
        p = self._prepared
        if p is not None and np.array_equal(p[0], v) and (p[1] or not derivatives):
            return
        self.imaging.prepare(v, derivatives)
        self._prepared = (v, derivatives)

    def forward(self, images: torch.Tensor, crop=None) -> torch.Tensor:
        """The aberrated images (B x C x H x W), or with crop = (x0, y0, w, h) only that crop of
        them (B x C x h x w): the full images then set the sensor geometry (their diagonal spans
        the sensor's), so a crop sees the PSFs of where it lies, and only the crop (plus the
        PSFs' reach) is computed."""
        # Sample the optics with derivatives only when a backward pass may follow.
        self._derivatives = torch.is_grad_enabled() and self.x.requires_grad
        return _ImageFormationFunction.apply(self.x, images, self,
                                             None if crop is None else tuple(crop))

    def lens(self):
        """The current lens (a lensopt.Lens; catalog glasses when quantized)."""
        return self.param.to_lens(_numpy_x(self.x), self.glass_mode)

    def glasses(self):
        """The nearest catalog glass per element."""
        return self.param.glasses(_numpy_x(self.x))

    def optics(self, derivatives: bool = False):
        """The sampled optics of the current x (lensopt.Imaging.optics: PSFs, y_ref, ybar, RI
        and, with derivatives, their Jacobians wrt x) as numpy arrays."""
        self._prepare(self.x, derivatives)
        return self.imaging.optics()

    def lens_loss_terms(self, **options) -> torch.Tensor:
        """(l_S, l_RP, l_RA, l_GV) of the current x, differentiable."""
        options.setdefault("glass_mode", self.glass_mode)
        return lens_loss_terms(self.x, self.param, **options)

    def lens_loss(self, **options) -> torch.Tensor:
        """The paper's l_lens of the current x, differentiable."""
        options.setdefault("glass_mode", self.glass_mode)
        return lens_loss(self.x, self.param, **options)
