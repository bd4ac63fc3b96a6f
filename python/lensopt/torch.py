"""lensopt in PyTorch: differentiable image formation and the paper's lens losses.

ImageFormation is an nn.Module whose parameter `x` holds the paper's lens variables (normalized
curvatures c' = c f, spacings s' = t / f with the last one the defocus, and two whitened glass
variables per glass; lensopt.Parameterization names them). Its forward takes B x C x H x W images
(linear light, channels R, G, B, further ones copied) on any device and returns the aberrated
images: the spatially varying PSF blur, relative illumination and distortion of the lens, as
`lensopt render` forms them. The full image spans the sensor diagonal.

How the gradient flows: the optics (field PSFs P_h, paraxial heights y_ref,h, centroid heights
ybar_h, relative illumination R_h) and their exact derivatives wrt x come from lensopt's Jets
(forward-mode, in C++ on the CPU); they enter torch as tensors on the images' device through one
torch.autograd.Function, whose backward contracts torch's gradients wrt the PSFs and maps with the
Jets' derivative parts (Imaging.optics_backward). The image operations run in torch on the
images' device, as lensopt's renderer forms them (render/render.h), so autograd differentiates
them wrt the images and the optics:
  - patch kernels K_q = L_q(sum_h a_qh P_h) / T (9 x 9 patches; the layout, field weights a_qh
    and the PSF-to-pixel resampling L_q from Imaging.layout),
  - the overlap-add blur B = sum_q w_q (K_q * S_ext) by FFT per patch block (S_ext the images
    extended by symmetric reflection),
  - relative illumination B R(r), R piecewise linear through (y_ref,h, R_h),
  - the distortion warp: bicubic (Keys) samples at the inverse map through (ybar_h, y_ref,h).
Only integer choices (the patch layout, kernel radii, interpolation pieces, warp taps and which
samples are black) are fixed from the optics' values, as the C++ renderer fixes them; no image is
copied to the CPU, so a network on a GPU keeps its images there. The blur works one patch row at
a time and the warp (its own autograd Function) in chunks, so the temporaries stay small.

float32 images on the CPU (image_ops="auto", the default) take lensopt's own image formation
instead, the same code as the joint optimization and `lensopt bench --joint-imaging`: one
autograd.Function whose forward is Imaging.render_images (the C++ blur, RI and warp of each crop,
reading only the window of the images the crop needs) and whose backward is its adjoint
Imaging.backward_images (dL/dx through the Jets, dL/dimages). Its data path is the CLI's: within
1.1x of the CLI's joint step (BENCHMARKS.md "lensopt.torch against the CLI step, torch first"),
where the torch operations on the CPU took 2.5-3x. It agrees with the torch operations to float32
rounding (tests/python/test_torch.py); image_ops="torch" keeps the latter.

On the CPU, glibc's malloc by default returns the memory a training step frees to the system, and
the next step faults it in again (a quarter to a third of the CPU time of four 256 x 256 crops of
a 1280 x 720 image, BENCHMARKS.md); MALLOC_MMAP_THRESHOLD_=67108864
MALLOC_TRIM_THRESHOLD_=268435456 in the environment (both: either alone is worse) avoids that
(for the torch operations). OpenMP's threads (lensopt's and torch's) wait passively, also when
torch was imported first (lensopt/__init__.py says how), unless OMP_WAIT_POLICY says otherwise.

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
from torch.autograd.function import once_differentiable

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
    # A copy: for a CPU float64 x the numpy view would share x's memory, and an in-place update
    # of x (an optimizer step, gradcheck's perturbation) would then also change the values the
    # module compares with to decide whether the optics must be sampled again.
    return np.array(x.detach().to("cpu", torch.float64).numpy(), dtype=np.float64, copy=True)


def _fft_size(n: int) -> int:
    """The smallest m >= n with no prime factor above 7 (a fast FFT length)."""
    m = max(int(n), 1)
    while True:
        k = m
        for p in (2, 3, 5, 7):
            while k % p == 0:
                k //= p
        if k == 1:
            return m
        m += 1


def _reflect(i: np.ndarray, n: int) -> np.ndarray:
    """Symmetric reflection of indices into [0, n): x_{-1-i} = x_i (and periodically beyond)."""
    m = np.mod(i, 2 * n)
    return np.where(m < n, m, 2 * n - 1 - m)


def _piece(xs: np.ndarray, x: np.ndarray):
    """The piece k (xs[k] <= x < xs[k+1], the end pieces beyond) of piecewise-linear
    interpolation through nodes xs, and where x lies at or below xs[0] / at or above xs[-1]."""
    k = np.searchsorted(xs, x, side="right") - 1
    low, high = x <= xs[0], x >= xs[-1]
    k = np.where(low, 0, np.where(high, len(xs) - 2, k))
    return k, low, high


def _lerp(xs: torch.Tensor, ys: torch.Tensor, x: torch.Tensor, k: torch.Tensor) -> torch.Tensor:
    """ys[k] + t (ys[k+1] - ys[k]), t = (x - xs[k]) / (xs[k+1] - xs[k]): differentiable in the
    nodes (and x), the piece k fixed (core/interpolate.h's linear_piece)."""
    x0, x1, y0, y1 = xs[k], xs[k + 1], ys[k], ys[k + 1]
    return y0 + (x - x0) / (x1 - x0) * (y1 - y0)


def _keys(t: torch.Tensor):
    """Keys cubic (a = -1/2) weights of the taps at -1, 0, 1, 2 for fractions t (n) and their
    derivatives wrt t: n x 4 each."""
    t2 = t * t
    t3 = t2 * t
    weights = torch.stack((-0.5 * t3 + t2 - 0.5 * t, 1.5 * t3 - 2.5 * t2 + 1.0,
                           -1.5 * t3 + 2.0 * t2 + 0.5 * t, 0.5 * t3 - 0.5 * t2), dim=-1)
    slopes = torch.stack((-1.5 * t2 + 2.0 * t - 0.5, 4.5 * t2 - 5.0 * t,
                          -4.5 * t2 + 4.0 * t + 0.5, 1.5 * t2 - t), dim=-1)
    return weights, slopes


class _Rfft2Function(torch.autograd.Function):
    """torch.fft.rfft2(x, s=(ny, nx)) over the last two dimensions (x zero-padded to ny x nx)
    with a cheaper adjoint than torch's own (which fills a full complex spectrum and runs a
    complex FFT): for real x and X = rfft2(x), dL/dx = ny nx irfft2(G') (cropped to x) with G'
    the gradient G wrt X with the columns that stand for two of the full spectrum's
    (0 < l < nx - l) halved."""

    @staticmethod
    def forward(ctx, x, ny, nx):
        ctx.size, ctx.shape = (ny, nx), tuple(x.shape[-2:])
        return torch.fft.rfft2(x, s=(ny, nx))

    @staticmethod
    def backward(ctx, grad):
        ny, nx = ctx.size
        g = grad.clone()
        g[..., 1:(nx + 1) // 2] *= 0.5
        gx = torch.fft.irfft2(g, s=(ny, nx)) * float(ny * nx)
        return gx[..., :ctx.shape[0], :ctx.shape[1]], None, None


# The warp gathers its taps in chunks of about this many values (cache-sized temporaries).
_WARP_CHUNK_VALUES = 1 << 20


def _warp_chunks(pixels: int, channels: int):
    n = max(64, _WARP_CHUNK_VALUES // (16 * channels))
    return [(a, min(pixels, a + n)) for a in range(0, pixels, n)]


class _WarpFunction(torch.autograd.Function):
    """The Keys warp's sampling as one operation: out[p, c] = sum_{m,t} wy[p, m] wx[p, t]
    src[start[p, m] + t, c] with wx = keys(fx[p]), wy = keys(fy[p]) valid[p]; src is the padded
    region with its pixels as rows and the channels (batch x channels) as columns, start[p, m]
    the first of the 4 consecutive pixels of tap row m of output pixel p (so each tap row is one
    contiguous run of 4 x channels values). Gathered and weighted chunk by chunk (no 16-fold
    temporary of the whole image, no autograd graph of the taps); the backward scatters the
    weighted gradient to the taps (dL/dsrc) and contracts it with the taps and the weights'
    slopes (dL/dfx, dL/dfy). The taps' positions (start) and valid are fixed by the plan."""

    @staticmethod
    def forward(ctx, src, fx, fy, valid, start):
        pixels, k = fx.shape[0], src.shape[1]
        runs = src.as_strided((src.shape[0] - 3, 4 * k), (k, 1))
        out = src.new_empty(pixels, k)
        wx, wy = _keys(fx)[0], _keys(fy)[0] * valid[:, None]
        for a, b in _warp_chunks(pixels, k):
            w = (wy[a:b, :, None] * wx[a:b, None, :]).reshape(b - a, 1, 16)
            taps = runs[start[4 * a:4 * b]].view(b - a, 16, k)
            torch.bmm(w, taps, out=out[a:b].view(b - a, 1, k))
        ctx.save_for_backward(src, fx, fy, valid, start)
        return out

    @staticmethod
    def backward(ctx, grad):
        src, fx, fy, valid, start = ctx.saved_tensors
        pixels, k = fx.shape[0], src.shape[1]
        grad = grad.contiguous()
        need_src, need_fx, need_fy = ctx.needs_input_grad[:3]
        g_src = g_fx = g_fy = None
        if need_src:  # per channel plane: contiguous weight x gradient products and scatters
            g_src = src.new_zeros(k, src.shape[0])
            grad_t = grad.t().contiguous()
        if need_fx or need_fy:
            runs = src.as_strided((src.shape[0] - 3, 4 * k), (k, 1))
            g_w = src.new_empty(pixels, 16)
        (wx, slope_x), (wy, slope_y) = _keys(fx), _keys(fy)
        wy = wy * valid[:, None]
        tap = torch.arange(4, device=src.device)
        for a, b in _warp_chunks(pixels, k):
            n = b - a
            g = grad[a:b].view(n, k, 1)
            if need_src:  # g_src[start + t] += w g
                w = (wy[a:b, :, None] * wx[a:b, None, :]).reshape(n, 16)
                index = (start[4 * a:4 * b, None] + tap).reshape(-1)
                for c in range(k):
                    g_src[c].scatter_add_(0, index, (w * grad_t[c, a:b, None]).reshape(-1))
            if need_fx or need_fy:  # dL/dw = taps . g
                taps = runs[start[4 * a:4 * b]].view(n, 16, k)
                torch.bmm(taps, g, out=g_w[a:b].view(n, 16, 1))
        if need_fx or need_fy:  # then the weights' slopes
            g_w = g_w.view(pixels, 4, 4)
            g_fx = (torch.bmm(wy[:, None, :], g_w).view(pixels, 4) * slope_x).sum(1)
            g_wy = torch.bmm(g_w, wx[:, :, None]).view(pixels, 4)
            g_fy = (g_wy * slope_y).sum(1) * valid
        return None if g_src is None else g_src.t(), g_fx, g_fy, None, None


class _GatherFunction(torch.autograd.Function):
    """images[:, :channels, rows][..., cols] (rows, cols: index vectors) as one operation whose
    backward adds the gradient straight into one zero gradient of the images' shape (autograd's
    own chain of slice and two index_select backwards makes three full-size temporaries)."""

    @staticmethod
    def forward(ctx, images, channels, rows, cols):
        ctx.shape, ctx.channels = images.shape, channels
        ctx.save_for_backward(rows, cols)
        return images[:, :channels].index_select(2, rows).index_select(3, cols)

    @staticmethod
    def backward(ctx, grad):
        rows, cols = ctx.saved_tensors
        B, _, _, W = ctx.shape
        out = grad.new_zeros(ctx.shape)
        band = grad.new_zeros(B, ctx.channels, rows.shape[0], W).index_add_(3, cols, grad)
        out[:, :ctx.channels].index_add_(2, rows, band)
        return out, None, None, None


class _OpticsFunction(torch.autograd.Function):
    """x -> (PSFs F x 3 x G x G, y_ref F, ybar F, RI F) as float64 tensors on `device`, sampled
    by lensopt's Jets; the backward contracts their gradients with the Jets' derivative parts
    (Imaging.optics_backward, on the CPU: only the optics' gradients, never an image, go there)."""

    @staticmethod
    def forward(ctx, x, module, derivatives, device):
        module._prepare(x, derivatives=derivatives)
        ctx.module = module
        ctx.x = x.detach().clone()
        # Fresh tensors per call (autograd attaches this call's node to them).
        return tuple(t.clone() for t in module._optics_tensors(device))

    @staticmethod
    def backward(ctx, g_psf, g_ref, g_centroid, g_ri):
        module = ctx.module
        module._prepare(ctx.x, derivatives=True)

        def host(g):
            return g.detach().to("cpu", torch.float64).contiguous().numpy()

        gx = module.imaging.optics_backward(host(g_psf), host(g_ref), host(g_centroid),
                                            host(g_ri))
        return torch.from_numpy(gx).to(device=ctx.x.device, dtype=ctx.x.dtype), None, None, None


class _LensoptImagingFunction(torch.autograd.Function):
    """(x, float32 CPU images B x C x H x W) -> their crops, by lensopt's own image formation
    (Imaging.render_images: the renderer's blur, RI and warp in C++, the joint optimization's and
    `lensopt bench --joint-imaging`'s code), and the backward by its adjoint
    (Imaging.backward_images: dL/dx through the Jets' derivative parts, dL/dimages). Only the
    pixels a crop reads are copied out of the images; no optics cross into torch."""

    @staticmethod
    def forward(ctx, x, images, module, crop, derivatives):
        module._prepare(x, derivatives=derivatives)
        ctx.module, ctx.crop = module, crop
        ctx.x = x.detach().clone()
        ctx.save_for_backward(images)
        return torch.from_numpy(module.imaging.render_images(images.detach().numpy(), crop))

    @staticmethod
    @once_differentiable
    def backward(ctx, grad):
        (images,) = ctx.saved_tensors
        need_x, need_images = ctx.needs_input_grad[:2]
        module = ctx.module
        module._prepare(ctx.x, derivatives=need_x)
        gx, g_images = module.imaging.backward_images(
            images.detach().numpy(), ctx.crop, grad.detach().to(torch.float32).numpy(),
            lens_gradient=need_x, image_gradient=need_images)
        if gx is not None:
            gx = torch.from_numpy(gx).to(device=ctx.x.device, dtype=ctx.x.dtype)
        if g_images is not None:
            g_images = torch.from_numpy(g_images)
        return gx, g_images, None, None, None


class _Plan:
    """The constants of one image operation (full size W x H, crop, channel count) under one
    prepare(): the blur's patch tasks, gather and scatter indices, windows and PSF resampling;
    the RI's radii and pieces; the warp's pieces, tap indices and validity. Integer choices come
    from the optics' values as in lensopt's renderer; every differentiable quantity is computed
    in torch from the optics tensors."""


# Patches per row / column of the overlap-add blur (PsfGrid::kPatches).
_PATCHES = 9


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
        catalog: glass catalog of the glass variables (default: the one `lensopt optimize`
            takes, lensopt.Parameterization's: the lens's own, else the nearest to its glasses).
        glass_mode: "quantized" (the paper's straight-through glasses), "continuous" or "fixed".
        rings, fields: PSF ray sampling (default the joint optimization's: 8 rings, 21 fields).
        grid_size, bin_um, sigma_bins, support_bins: the PSF grid and KDE (support_bins=3 is the
            joint optimization's). With rings=32 and support_bins=2 (`lensopt render`'s
            sampling) and the other defaults, forward equals `lensopt render` to 1e-5 on float32
            images.
        relative_illumination, distortion: apply (and differentiate) them.
        freeze: variable names or groups ("curvatures", "spacings", "glasses", "c3") whose
            gradient is zeroed.
        threads: threads of the C++ optics and image formation (0: all cores); the torch image
            operations use torch's.
        image_ops: "auto": float32 images on the CPU are formed by lensopt's C++ image formation
            and its adjoint (`Imaging.render_images` / `backward_images`: the joint
            optimization's code, `lensopt bench --joint-imaging`'s; only the pixels a crop reads
            are copied), other images (float64, other devices) by the torch operations below;
            "torch": the torch operations always. The two agree to float32 rounding
            (tests/python/test_torch.py).

    forward(images, crop=None): B x C x H x W -> B x C x H x W (or the crop's h x w), on the
    images' device, in their dtype (computed in float64 for float64 images, else float32).
    """

    def __init__(self, lens, *, catalog: str = "", glass_mode: str = "quantized", rings: int = 8,
                 fields: int = 21, grid_size: int = 65, bin_um: float = 4.0,
                 sigma_bins: float = 0.5, support_bins: int = 3,
                 relative_illumination: bool = True, distortion: bool = True,
                 paraxial_image_solve: bool = True, freeze=(), threads: int = 0,
                 image_ops: str = "auto"):
        super().__init__()
        if fields < 2:
            raise ValueError(f"fields = {fields}: the image formation needs at least 2 fields")
        if image_ops not in ("auto", "torch"):
            raise ValueError(f"image_ops = {image_ops!r}: 'auto' or 'torch'")
        self.image_ops = image_ops
        # What it was made from, for copy.deepcopy and pickle (__getstate__).
        self._lens = lens.copy()
        self._init_kwargs = dict(
            catalog=catalog, glass_mode=glass_mode, rings=rings, fields=fields,
            grid_size=grid_size, bin_um=bin_um, sigma_bins=sigma_bins, support_bins=support_bins,
            relative_illumination=relative_illumination, distortion=distortion,
            paraxial_image_solve=paraxial_image_solve, freeze=tuple(freeze), threads=threads,
            image_ops=image_ops)
        self.param = _lensopt.Parameterization(lens, catalog=catalog,
                                               paraxial_image_solve=paraxial_image_solve)
        self.glass_mode = glass_mode
        self.relative_illumination = relative_illumination
        self.distortion = distortion
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
        self._generation = 0   # counts the samplings of the optics
        self._values = None    # the optics' values (numpy) of the last sampling
        self._cache = {}       # per generation: optics tensors, layouts and plans
        self._geometry = {}    # pixel geometry of image and crop sizes (not x-dependent)

    @property
    def names(self):
        """The variables' names ("c1", "s2", "defocus", "g1.0", ...)."""
        return self.param.names

    def __getstate__(self):
        """copy.deepcopy and pickle: the lens and options the module was made with, the
        variables' values (device, requires_grad) and the training flag. The C++ optics and the
        caches are rebuilt from them (__setstate__), so a copy renders the same images."""
        return {"lens": self._lens, "options": dict(self._init_kwargs),
                "x": self.x.detach().cpu().clone(), "device": str(self.x.device),
                "requires_grad": self.x.requires_grad, "training": self.training}

    def __setstate__(self, state):
        self.__init__(state["lens"], **state["options"])
        with torch.no_grad():
            self.x.copy_(state["x"])
        self.x.requires_grad_(state["requires_grad"])
        self.train(state["training"])
        if state["device"] != "cpu":
            self.to(state["device"])

    def _prepare(self, x: torch.Tensor, derivatives: bool):
        v = _numpy_x(x)
        p = self._prepared
        if p is not None and np.array_equal(p[0], v) and (p[1] or not derivatives):
            return
        self.imaging.prepare(v, derivatives)
        self._prepared = (v, derivatives)
        self._generation += 1
        self._values = None  # fetched by _optics_values() when the torch image operations run
        self._cache = {}

    def _optics_values(self):
        if self._values is None:
            self._values = self.imaging.optics(jacobians=False)
        return self._values

    def _optics_tensors(self, device):
        key = ("optics", str(device))
        if key not in self._cache:
            o = self._optics_values()
            self._cache[key] = tuple(
                torch.from_numpy(np.ascontiguousarray(o[name])).to(device)
                for name in ("psf", "reference_y_mm", "centroid_y_mm", "relative_illumination"))
        return self._cache[key]

    def _layout(self, width: int, height: int):
        key = ("layout", width, height)
        if key not in self._cache:
            self._cache[key] = self.imaging.layout(width, height)
        return self._cache[key]

    def _image_geometry(self, width, height, ax, ay, pitch):
        """The radius (mm) of every pixel centre of a width x height image (kept across the
        samplings of the optics: it depends on the sensor geometry only)."""
        key = ("image", width, height, ax, ay, pitch)
        if key not in self._geometry:
            dx = np.arange(width) + 0.5 - ax
            dy = np.arange(height) + 0.5 - ay
            self._geometry[key] = pitch * np.sqrt(dy[:, None] ** 2 + dx[None, :] ** 2)
        return self._geometry[key]

    def _crop_geometry(self, width, height, crop, ax, ay, pitch, device):
        """Per crop pixel its offsets from the axis (pixels), radius (mm), whether it lies on the
        axis, and those as flat tensors on the device (kept across samplings of the optics)."""
        key = ("crop", width, height, crop, ax, ay, pitch, str(device))
        if key not in self._geometry:
            cx0, cy0, cw, ch = crop
            jj, ii = np.mgrid[0:ch, 0:cw]
            dx = (cx0 + ii) + 0.5 - ax
            dy = (cy0 + jj) + 0.5 - ay
            r = pitch * np.sqrt(dx * dx + dy * dy)
            on_axis = ~(r > 1e-12)
            r_safe = np.where(on_axis, 1.0, r)
            tensors = tuple(torch.from_numpy(a.reshape(-1)).to(device)
                            for a in (dx, dy, r_safe, on_axis))
            self._geometry[key] = dict(dx=dx, dy=dy, r=r, on_axis=on_axis, r_safe=r_safe,
                                       tensors=tensors)
        return self._geometry[key]

    def _plan(self, width, height, crop, channels, device):
        key = ("plan", width, height, crop, channels, str(device))
        if key in self._cache:
            return self._cache[key]
        L = self._layout(width, height)
        o = self._optics_values()
        yref, ybar = o["reference_y_mm"], o["centroid_y_mm"]
        cx0, cy0, cw, ch = crop
        p = _Plan()
        p.colours = 3 if channels >= 3 else 1
        p.crop = crop
        ax, ay, pitch = L["axis_x"], L["axis_y"], L["pitch_mm"]

        def dev(a, dtype=None):
            t = torch.from_numpy(np.ascontiguousarray(a))
            return t.to(device=device, dtype=dtype) if dtype is not None else t.to(device)

        # The warp: per crop pixel its sample position (render/distortion_warp.h), black
        # outside the image; the blurred region is what the valid samples' taps reach.
        p.warp = self.distortion
        if p.warp:
            for h in range(1, len(ybar)):
                if not ybar[h] > ybar[h - 1]:
                    f = o["fields_deg"]
                    raise ValueError(
                        f"cannot apply distortion: the image heights of fields {f[h - 1]:.2f} "
                        f"and {f[h]:.2f} deg do not increase ({ybar[h - 1]:.6f}, "
                        f"{ybar[h]:.6f} mm)")
            g = self._crop_geometry(width, height, crop, ax, ay, pitch, device)
            dx, dy, r_out, on_axis, r_safe = g["dx"], g["dy"], g["r"], g["on_axis"], g["r_safe"]
            k, _, _ = _piece(ybar, r_out)
            rho = yref[k] + (r_out - ybar[k]) / (ybar[k + 1] - ybar[k]) * (yref[k + 1] - yref[k])
            axis_scale = (yref[1] - yref[0]) / (ybar[1] - ybar[0])
            scale = np.where(on_axis, axis_scale, rho / r_safe)
            sx, sy = ax + dx * scale, ay + dy * scale
            valid = (sx >= 0.0) & (sx <= width) & (sy >= 0.0) & (sy <= height)
            fx0 = np.floor(sx - 0.5).astype(np.int64)
            fy0 = np.floor(sy - 0.5).astype(np.int64)
            if valid.any():
                x_lo = int(np.clip(fx0[valid] - 1, 0, width - 1).min())
                x_hi = int(np.clip(fx0[valid] + 2, 0, width - 1).max()) + 1
                y_lo = int(np.clip(fy0[valid] - 1, 0, height - 1).min())
                y_hi = int(np.clip(fy0[valid] + 2, 0, height - 1).max()) + 1
            else:  # every sample black
                x_lo, x_hi, y_lo, y_hi = cx0, cx0 + 1, cy0, cy0 + 1
        else:
            x_lo, x_hi, y_lo, y_hi = cx0, cx0 + cw, cy0, cy0 + ch
        p.rx0, p.ry0, p.rw, p.rh = x_lo, y_lo, x_hi - x_lo, y_hi - y_lo
        if p.warp:
            # The taps of pixel p are rows fy0-1 .. fy0+2 and columns fx0-1 .. fx0+2 of the image,
            # clamped to its border. The warp samples the region padded by 2 pixels on every side
            # with its edge pixels repeated (pad_rows, pad_cols): where a tap lies beyond the
            # image, the region reaches the image's border (it spans every valid sample's
            # clamped taps), so the repeated edge is the clamp; elsewhere the taps lie inside the
            # region. Tap row m of p is then the 4 consecutive padded pixels from
            # warp_start[p, m] (0 for black samples, whose weights are 0).
            padded_width = p.rw + 4
            rows = fy0[..., None] - 1 + np.arange(4) - p.ry0 + 2  # ch x cw x 4
            start = rows * padded_width + (fx0 - 1 - p.rx0 + 2)[..., None]
            p.warp_start = dev(np.where(valid[..., None], start, 0).reshape(-1))
            p.pad_rows = dev(np.clip(np.arange(-2, p.rh + 2), 0, p.rh - 1))
            p.pad_cols = dev(np.clip(np.arange(-2, p.rw + 2), 0, p.rw - 1))
            p.warp_piece = dev(k.reshape(-1))
            p.warp_dx, p.warp_dy, p.warp_r, p.warp_axis = g["tensors"]
            p.warp_floor_x = dev(fx0.reshape(-1).astype(np.float64))
            p.warp_floor_y = dev(fy0.reshape(-1).astype(np.float64))
            p.warp_valid = dev(valid.reshape(-1).astype(np.float64))
            p.axis = (ax, ay)
        # Relative illumination over the region: the radius of each pixel and its piece.
        p.ri = self.relative_illumination
        if p.ri:
            g = self._image_geometry(width, height, ax, ay, pitch)
            r = g[p.ry0:p.ry0 + p.rh, p.rx0:p.rx0 + p.rw]
            k, low, high = _piece(yref, r)
            p.ri_radius, p.ri_piece = dev(r), dev(k)
            p.ri_low, p.ri_high = dev(low), dev(high)
        # The blur: the patches whose windows meet the region, blocks at a common radius R.
        n = _PATCHES
        rx1, ry1 = p.rx0 + p.rw, p.ry0 + p.rh
        xs = [(q, max(L["lo_x"][q], p.rx0), min(L["hi_x"][q], rx1)) for q in range(n)]
        ys = [(q, max(L["lo_y"][q], p.ry0), min(L["hi_y"][q], ry1)) for q in range(n)]
        xs = [t for t in xs if t[2] > t[1]]
        ys = [t for t in ys if t[2] > t[1]]
        patches = np.array([py * n + px for py, _, _ in ys for px, _, _ in xs])
        radii = L["radius"][patches]
        R = int(radii.max())
        ex = max(x1 - x0 for _, x0, x1 in xs)
        ey = max(y1 - y0 for _, y0, y1 in ys)
        p.R, p.ex, p.ey = R, ex, ey
        p.nx, p.ny = _fft_size(ex + 2 * R), _fft_size(ey + 2 * R)
        p.npx, p.npy = len(xs), len(ys)
        p.cols = dev(np.stack([_reflect(x0 - R + np.arange(p.nx), width) for _, x0, _ in xs]))
        # The rows of every block row (symmetrically reflected), once: block row a is rows
        # row_offset[a] .. + ny of them.
        first = [y0 - R for _, y0, _ in ys]
        p.ext_rows = dev(_reflect(np.arange(min(first), max(first) + p.ny), height))
        p.row_offset = [f - min(first) for f in first]

        def windows(spans, w, e):
            out = np.zeros((len(spans), e))
            for a, (q, x0, x1) in enumerate(spans):
                out[a, :x1 - x0] = w[q, x0:x1]
            return out

        wx = windows(xs, L["window_x"], ex)
        wy = windows(ys, L["window_y"], ey)
        p.window_np = (wx, wy)  # the windows are separable: npx x ex and npy x ey
        tx = np.array([x0 for _, x0, _ in xs])[:, None] + np.arange(ex) - p.rx0  # npx x ex
        ty = np.array([y0 for _, y0, _ in ys])[:, None] + np.arange(ey) - p.ry0
        tx, ty = np.clip(tx, 0, p.rw - 1), np.clip(ty, 0, p.rh - 1)
        p.target_x, p.target_y = dev(tx.reshape(-1)), dev(ty)
        # PSF bins -> pixel kernels of radius R (render/psf_resample.h): the four taps.
        size_q = 2 * radii + 1
        S = 2 * R + 1
        corner = L["corner"][patches]
        ok = corner >= 0
        cy, cx = np.divmod(np.where(ok, corner, 0), size_q[:, None])
        shift = (R - radii)[:, None]
        base = np.where(ok, (cy + shift) * S + (cx + shift), 0).astype(np.int64)
        fx, fy = L["fx"][patches], L["fy"][patches]
        p.kernel_index = dev(np.stack([base, base + 1, base + S, base + S + 1]))  # 4 x nq x G^2
        p.kernel_weight_np = np.stack([(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy])
        p.bin_ok = dev(ok)
        p.field_weights = dev(L["field_weights"][patches])
        p.window_t = {}
        p.kernel_weight = {}
        self._cache[key] = p
        return p

    def _blur(self, images, psf, p, cdtype):
        """B = sum_q w_q (K_q * S_ext) over the plan's region (colour channels), B x Cc x rh x rw,
        by FFT per patch block at the common radius R; K_q the patch kernels from the PSFs."""
        device = images.device
        B = images.shape[0]
        F, _, G, _ = psf.shape
        nq = p.npx * p.npy
        R, S = p.R, 2 * p.R + 1
        # Patch kernels K_q[c] = L_q(sum_h a_qh P_h[c]) / T in the images' precision (float64
        # for float64 images): each bin's weight splat bilinearly onto 4 kernel pixels.
        mixed = torch.einsum("qf,fcb->qcb", p.field_weights, psf.reshape(F, 3, G * G))
        m = (mixed * ((mixed.detach() > 0) & p.bin_ok[:, None, :])).to(cdtype)
        total = m.sum(-1, keepdim=True)
        key = (str(device), cdtype)
        if key not in p.kernel_weight:
            p.kernel_weight[key] = torch.from_numpy(p.kernel_weight_np).to(device=device,
                                                                           dtype=cdtype)
        kernel = torch.zeros(nq, 3, S * S, dtype=cdtype, device=device)
        for index, weight in zip(p.kernel_index, p.kernel_weight[key]):
            kernel = kernel.scatter_add(2, index[:, None, :].expand(nq, 3, -1),
                                        m * weight[:, None, :])
        unit = torch.zeros(S * S, dtype=cdtype, device=device)
        unit[R * S + R] = 1.0
        has_energy = total > 0
        kernel = torch.where(
            has_energy, kernel / torch.where(has_energy, total, torch.ones_like(total)), unit)
        if p.colours == 1:
            kernel = kernel.mean(1, keepdim=True)
        cc = kernel.shape[1]
        # Per patch row (unbind: their gradients are stacked, not added up at full size).
        kernel = kernel.reshape(p.npy, p.npx, cc, S, S).unbind(0)
        if key not in p.window_t:
            p.window_t[key] = tuple(torch.from_numpy(w).to(device=device, dtype=cdtype)
                                    for w in p.window_np)
        window_x, window_y = p.window_t[key]
        window_x = window_x[:, None, :]  # npx x 1 x ex
        # The blocks' rows and columns of the images (B x Cc x rows x npx nx), gathered once.
        scene = _GatherFunction.apply(images, p.colours, p.ext_rows, p.cols.reshape(-1))
        scene = scene.to(cdtype)
        region = torch.zeros(B, cc, p.rh, p.rw, dtype=cdtype, device=device)
        # One patch row at a time (small temporaries): its blocks B x Cc x npx x ny x nx, their
        # convolutions' centres windowed and added along x into the row's band, then the band
        # windowed and added along y into the region.
        for a in range(p.npy):
            blocks = scene.narrow(2, p.row_offset[a], p.ny)
            blocks = blocks.reshape(B, cc, p.ny, p.npx, p.nx).transpose(2, 3)
            # The row's kernels at the blocks' origin (zero-padded to ny x nx): the centred
            # output row i is then row i + R of the circular convolution, and the blocks'
            # centres (rows R .. R + ey) rows 2R .. 2R + ey (< ny: no wrap-around).
            spectra = _Rfft2Function.apply(kernel[a], p.ny, p.nx).transpose(0, 1)
            conv = torch.fft.irfft2(torch.fft.rfft2(blocks) * spectra, s=(p.ny, p.nx))
            conv = conv[..., 2 * R:2 * R + p.ey, 2 * R:2 * R + p.ex] * window_x  # B Cc npx ey ex
            conv = conv.transpose(2, 3).reshape(B, cc, p.ey, p.npx * p.ex)
            band = torch.zeros(B, cc, p.ey, p.rw, dtype=cdtype, device=device).index_add(
                3, p.target_x, conv)
            region = region.index_add(2, p.target_y[a], band * window_y[a, :, None])
        return region

    def _form(self, x: torch.Tensor, images: torch.Tensor, crop=None) -> torch.Tensor:
        """The image formation of lens variables x (the module's or another tensor, e.g. for
        gradcheck): forward() with an explicit x."""
        if images.dim() != 4:
            raise ValueError("images must be B x C x H x W")
        B, C, H, W = images.shape
        crop = (0, 0, W, H) if crop is None else tuple(int(v) for v in crop)
        cx0, cy0, cw, ch = crop
        if cw <= 0 or ch <= 0 or cx0 < 0 or cy0 < 0 or cx0 + cw > W or cy0 + ch > H:
            raise ValueError(f"crop {cw}x{ch} at ({cx0}, {cy0}) is not inside the {W}x{H} "
                             "images")
        device = images.device
        cdtype = torch.float64 if images.dtype == torch.float64 else torch.float32
        derivatives = torch.is_grad_enabled() and x.requires_grad
        if (self.image_ops == "auto" and device.type == "cpu" and images.dtype == torch.float32
                and x.device.type == "cpu"):
            return _LensoptImagingFunction.apply(x, images, self, crop, derivatives)
        psf, yref, ybar, ri_nodes = _OpticsFunction.apply(x, self, derivatives, device)
        p = self._plan(W, H, crop, C, device)
        out = self._blur(images, psf, p, cdtype)
        if p.ri:
            k = p.ri_piece
            ri = _lerp(yref, ri_nodes, p.ri_radius, k)
            ri = torch.where(p.ri_low, ri_nodes[0], torch.where(p.ri_high, ri_nodes[-1], ri))
            out = out * ri.to(cdtype)
        if C > p.colours:  # further channels (alpha): neither blurred nor dimmed
            extra = images[:, p.colours:, p.ry0:p.ry0 + p.rh, p.rx0:p.rx0 + p.rw]
            out = torch.cat((out, extra.to(cdtype)), dim=1)
        if p.warp:
            k = p.warp_piece
            rho = _lerp(ybar, yref, p.warp_r, k)
            axis_scale = (yref[1] - yref[0]) / (ybar[1] - ybar[0])
            scale = torch.where(p.warp_axis, axis_scale, rho / p.warp_r)
            u = p.axis[0] + p.warp_dx * scale - 0.5
            v = p.axis[1] + p.warp_dy * scale - 0.5
            # Positions in float64, the Keys weights of their fractions in the images' precision.
            fx = (u - p.warp_floor_x).to(cdtype)
            fy = (v - p.warp_floor_y).to(cdtype)
            src = out.permute(2, 3, 0, 1).index_select(0, p.pad_rows).index_select(1, p.pad_cols)
            src = src.reshape(-1, B * C).contiguous()
            out = _WarpFunction.apply(src, fx, fy, p.warp_valid.to(cdtype), p.warp_start)
            out = out.t().reshape(B, C, ch, cw)
        return out.to(images.dtype)

    def forward(self, images: torch.Tensor, crop=None) -> torch.Tensor:
        """The aberrated images (B x C x H x W), or with crop = (x0, y0, w, h) only that crop of
        them (B x C x h x w): the full images then set the sensor geometry (their diagonal spans
        the sensor's), so a crop sees the PSFs of where it lies, and only the crop (plus the
        PSFs' reach) is computed. Runs on the images' device; the optics are sampled (with
        derivatives when a backward pass may follow) by lensopt on the CPU."""
        return self._form(self.x, images, crop)

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
        return self.imaging.optics(jacobians=derivatives)

    def lens_loss_terms(self, **options) -> torch.Tensor:
        """(l_S, l_RP, l_RA, l_GV) of the current x, differentiable."""
        options.setdefault("glass_mode", self.glass_mode)
        return lens_loss_terms(self.x, self.param, **options)

    def lens_loss(self, **options) -> torch.Tensor:
        """The paper's l_lens of the current x, differentiable."""
        options.setdefault("glass_mode", self.glass_mode)
        return lens_loss(self.x, self.param, **options)
