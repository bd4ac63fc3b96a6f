"""lensopt in Python: differentiable lens design with exact ray tracing.

The C++ core (lensopt._lensopt) does the optics; this package re-exports it:

Lenses
    load_lens(path), parse_lens(text, format), save_lens(lens, path): .toml, the paper's .yml
    (read), Zemax .zmx. Lens, Surface, Material, Specs are edited in place
    (lens.surfaces[1].thickness_mm = 2.0; lens.specs.f_number = 2.8).
Analysis
    analyze(lens) -> AnalysisReport (report.to_dict() equals `lensopt analyze --json`;
    analyze(lens, wave=True, zernike_terms=J): report.wave, report.zernike_waves),
    trace_rays / trace_pupil (numpy in and out), spots, psfs, field_data.
Rendering
    Renderer(lens).render(image) (H x W x C float32), Renderer.maps(width, height) (per-pixel
    distortion and relative illumination), Renderer(lens, psf="geometric|diffraction|auto")
    and Renderer.psf (which PSFs it uses), read_image / write_image.
Optimization
    optimize(lens) (merit="spot" or "wavefront"), tolerance(lens), Parameterization (the paper's
    lens variables, design loss and its exact gradient), Imaging (differentiable image
    formation).
PyTorch
    lensopt.torch (imported separately; needs python3-torch): ImageFormation (an nn.Module whose
    parameters are the lens variables), spot_loss and the lens-loss terms.

Errors are lensopt.LensoptError (a ValueError) with the CLI's "file:line:column: message".
Long calls release the GIL; optimize() stops on Ctrl-C (KeyboardInterrupt).
"""

import os as _os

# OpenMP threads that wait passively (sleep) between parallel regions instead of spinning; the
# user's own setting wins (include/lensopt/core/passive_threads.h). The extension's loops run in
# LLVM's OpenMP runtime when it was built with it (_lensopt.openmp_runtime == "libomp",
# python/CMakeLists.txt): a runtime of its own, initialized after this line, so passive even when
# torch was imported first. Built with GCC's libgomp only, the setting takes effect only if nothing
# loaded libgomp before (torch does), and the package warns.
_user_wait_policy = "OMP_WAIT_POLICY" in _os.environ
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")


def _gomp_already_loaded():
    """Whether libgomp is mapped in this process already (torch, numpy's BLAS, ... loaded it)."""
    try:
        with open("/proc/self/maps", encoding="ascii", errors="replace") as maps:
            return any("libgomp" in line for line in maps)
    except OSError:
        return False


_gomp_before = not _user_wait_policy and _gomp_already_loaded()

from . import _lensopt  # noqa: E402

if _gomp_before and _lensopt.openmp_runtime == "libgomp":
    import warnings as _warnings

    _warnings.warn(
        "lensopt: OpenMP (libgomp) was loaded before lensopt (usually by `import torch`), so "
        "its threads spin between parallel regions and burn the other cores (3.8-12.7x the CPU "
        "of a joint step with 2 threads): set OMP_WAIT_POLICY=PASSIVE in the environment, or "
        "import lensopt before torch (or build the extension with LLVM's OpenMP runtime, "
        "libomp5-14: python/CMakeLists.txt)",
        RuntimeWarning,
        stacklevel=2,
    )

from ._lensopt import (  # noqa: F401,E402
    AnalysisReport,
    FieldPoint,
    FieldReport,
    Imaging,
    Lens,
    LensoptError,
    Material,
    OptimizeResult,
    Parameterization,
    Renderer,
    Specs,
    Surface,
    SurfaceList,
    ToleranceReport,
    analyze,
    catalog_glasses,
    chromatic_focal_shift,
    encircled_energy,
    field_data,
    field_sweep,
    glass_index,
    lateral_colour,
    load_lens,
    optimize,
    parse_lens,
    prescription,
    psfs,
    read_image,
    save_lens,
    spots,
    tolerance,
    trace_pupil,
    trace_rays,
    write_image,
)

__version__ = "0.1.0"


def render(lens, image, **options):
    """Renders an H x W x C (or H x W) linear-light image through `lens` (`lensopt render`).

    Options are Renderer's (rings, fields, res_factor, distortion, relative_illumination,
    threads, psf, pupil_samples). Returns H x W x C float32. For several images build one Renderer and reuse it.
    """
    return Renderer(lens, **options).render(image)
