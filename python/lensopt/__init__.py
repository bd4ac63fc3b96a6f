"""lensopt in Python: differentiable lens design with exact ray tracing.

The C++ core (lensopt._lensopt) does the optics; this package re-exports it:

Lenses
    load_lens(path), parse_lens(text, format), save_lens(lens, path): .toml, the paper's .yml
    (read), Zemax .zmx. Lens, Surface, Material, Specs are edited in place
    (lens.surfaces[1].thickness_mm = 2.0; lens.specs.f_number = 2.8).
Analysis
    analyze(lens) -> AnalysisReport (report.to_dict() equals `lensopt analyze --json`;
    analyze(lens, wave=True, zernike_terms=J): report.wave, report.zernike_waves; an afocal
    lens gives an AfocalReport, measured in angle as the CLI measures it),
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
# user's own setting wins (include/lensopt/core/passive_threads.h). libgomp reads the variable only
# when it is loaded: if something (torch) loaded it before lensopt, the package keeps CPUs + 1 of
# its threads idle instead, which makes libgomp spin only 100 iterations before its threads sleep
# (its documented throttling when it manages more threads than there are CPUs; GOMP_SPINCOUNT in
# the libgomp manual; _lensopt._park_gomp_threads): lensopt's threads and torch's then wait as
# good as passively (BENCHMARKS.md "lensopt.torch against the CLI step, torch first").
_user_wait_policy = "OMP_WAIT_POLICY" in _os.environ or "GOMP_SPINCOUNT" in _os.environ
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")


def _loaded_gomp():
    """The paths of the libgomp copies mapped in this process (torch, numpy's BLAS, ... loaded
    them; a torch wheel's own copy is named libgomp-<hash>.so.1)."""
    try:
        with open("/proc/self/maps", encoding="utf-8", errors="replace") as maps:
            return sorted({line.split(None, 5)[5].strip() for line in maps
                           if len(line.split(None, 5)) == 6 and "libgomp" in line.split(None, 5)[5]
                           and line.split(None, 5)[5].strip().startswith("/")})
    except OSError:
        return []


_gomp_before = [] if _user_wait_policy else _loaded_gomp()

from . import _lensopt  # noqa: E402


def _throttle_gomp(paths):
    """Parks CPUs + 1 threads of each libgomp in `paths` (see above); the ones it could not."""
    try:
        cpus = len(_os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cpus = _os.cpu_count() or 1
    failed = []
    for path in paths:
        try:
            _lensopt._park_gomp_threads(path, cpus + 1)
        except (ValueError, RuntimeError):
            failed.append(path)
    return failed


if _gomp_before and _throttle_gomp(_gomp_before):
    import warnings as _warnings

    _warnings.warn(
        "lensopt: OpenMP (libgomp) was loaded before lensopt (usually by `import torch`), so "
        "its threads spin between parallel regions and burn the other cores (3.8-12.7x the CPU "
        "of a joint step with 2 threads): set OMP_WAIT_POLICY=PASSIVE in the environment, or "
        "import lensopt before torch",
        RuntimeWarning,
        stacklevel=2,
    )

from ._lensopt import (  # noqa: F401,E402
    AfocalField,
    AfocalFirstOrder,
    AfocalReport,
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
