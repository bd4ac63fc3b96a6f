from typing import Any

import numpy as np
import numpy.typing as npt

from ._lensopt import (
    AfocalField as AfocalField,
    AfocalFirstOrder as AfocalFirstOrder,
    AfocalReport as AfocalReport,
    AnalysisReport as AnalysisReport,
    FieldReport as FieldReport,
    Imaging as Imaging,
    Lens as Lens,
    LensoptError as LensoptError,
    Material as Material,
    OptimizeResult as OptimizeResult,
    Parameterization as Parameterization,
    Renderer as Renderer,
    Specs as Specs,
    FieldPoint as FieldPoint,
    Surface as Surface,
    SurfaceList as SurfaceList,
    ToleranceReport as ToleranceReport,
    analyze as analyze,
    catalog_glasses as catalog_glasses,
    chromatic_focal_shift as chromatic_focal_shift,
    encircled_energy as encircled_energy,
    field_data as field_data,
    field_sweep as field_sweep,
    glass_index as glass_index,
    lateral_colour as lateral_colour,
    load_lens as load_lens,
    optimize as optimize,
    parse_lens as parse_lens,
    prescription as prescription,
    psfs as psfs,
    read_image as read_image,
    save_lens as save_lens,
    spots as spots,
    tolerance as tolerance,
    trace_pupil as trace_pupil,
    trace_rays as trace_rays,
    write_image as write_image,
)

__version__: str

def render(lens: Lens, image: npt.ArrayLike, **options: Any) -> np.ndarray: ...
