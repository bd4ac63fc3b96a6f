"""Type stubs of lensopt's C++ extension module (python/src)."""

import os
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union, overload

import numpy as np
import numpy.typing as npt

class LensoptError(ValueError):
    file: str
    line: int
    column: int
    message: str

class Material:
    def __init__(self) -> None: ...
    @property
    def kind(self) -> str: ...
    @property
    def glass_name(self) -> str: ...
    @property
    def nd(self) -> float: ...
    @property
    def vd(self) -> float: ...
    @property
    def label(self) -> str: ...
    def is_air(self) -> bool: ...
    @staticmethod
    def air() -> Material: ...
    @staticmethod
    def model(nd: float, vd: float) -> Material: ...
    @staticmethod
    def catalog(name: str, catalog: str = "ohara") -> Material: ...

class Surface:
    curvature_per_mm: float
    radius_mm: float
    thickness_mm: float
    material: Material
    is_stop: bool
    semi_diameter_mm: float
    vary: List[str]
    pickup_curvature: Optional[Dict[str, float]]
    pickup_thickness: Optional[Dict[str, float]]
    solve: Optional[Dict[str, Any]]
    def __init__(self, radius_mm: float = ..., thickness_mm: float = 0.0,
                 material: Material = ..., stop: bool = False,
                 semi_diameter_mm: float = 0.0) -> None: ...

class SurfaceList:
    def __len__(self) -> int: ...
    def __getitem__(self, i: int) -> Surface: ...
    def __setitem__(self, i: int, s: Surface) -> None: ...
    def __delitem__(self, i: int) -> None: ...
    def append(self, s: Surface) -> None: ...
    def insert(self, i: int, s: Surface) -> None: ...
    def pop(self, i: int = -1) -> Surface: ...

class FieldPoint:
    value: float
    weight: float
    def __init__(self, value: float, weight: float = 1.0) -> None: ...

class Specs:
    mode: str
    f_number: float
    half_field_deg: float
    sensor_diagonal_mm: float
    wavelengths_nm: List[float]
    wavelength_channels: List[int]
    wavelength_weights: List[float]
    primary_wavelength_nm: float
    aperture: str
    aperture_value: float
    field_type: str
    fields: List[FieldPoint]
    object_distance_mm: float
    dispersion: str
    def __init__(self) -> None: ...
    def focal_length_mm(self) -> float: ...

class Lens:
    name: str
    catalog_name: str
    specs: Specs
    surfaces: SurfaceList
    source_path: str
    extra_toml: str
    def __init__(self) -> None: ...
    def stop_index(self) -> int: ...
    def element_count(self) -> int: ...
    def track_length_mm(self) -> float: ...
    def total_track_mm(self) -> float: ...
    def validate(self) -> None: ...
    def apply_solves(self) -> None: ...
    def scaled(self, scale: float) -> Lens: ...
    def to_toml(self) -> str: ...
    def to_zmx(self) -> str: ...
    def copy(self) -> Lens: ...

def load_lens(path: Union[str, os.PathLike]) -> Lens: ...
def parse_lens(text: str, format: str = "toml", source_name: str = "<string>") -> Lens: ...
def save_lens(lens: Lens, path: Union[str, os.PathLike]) -> None: ...
def catalog_glasses(catalog: str = "ohara") -> List[Tuple[str, float, float]]: ...
def glass_index(glass: str, wavelength_nm: float, catalog: str = "ohara") -> float: ...

class FieldReport:
    field_deg: float
    rms_spot_um: Optional[float]
    centroid_y_mm: float
    reference_y_mm: float
    distortion_percent: float
    relative_illumination: Optional[float]
    traced_rays: int
    failed_rays: int
    aiming_error: float

class AnalysisReport:
    lens_name: str
    source_path: str
    scale: float
    efl_mm: float
    bfl_mm: float
    f_number: float
    epd_mm: float
    entrance_pupil_z_mm: float
    stop_radius_mm: float
    total_track_mm: float
    rings: int
    rays_per_field_wavelength: int
    wavelength_count: int
    ray_aiming: bool
    dispersion: str
    fields: List[FieldReport]
    mean_rms_spot_um: Optional[float]
    ray_failures: int
    failures_by_surface: List[int]
    max_aiming_error: float
    image_distance_mm: float
    virtual_image: bool
    angular_magnification: float
    object_distance_mm: float
    primary_wavelength_nm: float
    wave: Optional[Dict[str, Any]]  # analyze(wave=True): `analyze --wave --json`'s wave section
    zernike_waves: Optional[np.ndarray]  # zernike_terms > 0: [field, wavelength, term], waves
    def to_json(self) -> str: ...
    def to_text(self) -> str: ...
    def to_dict(self) -> Dict[str, Any]: ...

class AfocalFirstOrder:
    angular_magnification: float
    entrance_pupil_diameter_mm: float
    entrance_pupil_z_mm: float
    exit_pupil_diameter_mm: float
    exit_pupil_z_mm: float
    residual_power_diopters: float
    marginal_output_slope: float
    image_space_index: float

class AfocalField:
    field_deg: float
    field_value: float
    weight: float
    traced_rays: int
    failed_rays: int
    vignetted_rays: int
    chief_ok: bool
    output_chief_angle_deg: float
    paraxial_output_angle_deg: float
    angular_distortion_percent: float
    rms_angular_spot_mrad: Optional[float]
    rms_wavefront_waves: Optional[float]
    pv_wavefront_waves: Optional[float]
    strehl: Optional[float]
    zernike_waves: List[float]

class AfocalReport:
    lens_name: str
    source_path: str
    first_order: AfocalFirstOrder
    angular_magnification: float
    fields: List[AfocalField]
    mean_rms_angular_spot_mrad: Optional[float]
    object_distance_mm: float
    primary_wavelength_nm: float
    wavelength_count: int
    rays_per_field_wavelength: int
    rings: int
    ray_failures: int
    vignetted_rays: int
    def to_json(self) -> str: ...
    def to_text(self) -> str: ...
    def to_dict(self) -> Dict[str, Any]: ...

# None: `lensopt analyze`'s default (32 rings, 21 fields, all threads, MTF at 10, 30, 50
# cycles/mm, 128 pupil samples).
def analyze(lens: Lens, *, rings: Optional[int] = None, fields: Optional[int] = None,
            ray_aiming: bool = True, scale_to_spec: bool = True, dispersion: str = "",
            threads: Optional[int] = None, wave: bool = False,
            mtf_frequencies: Optional[Sequence[float]] = None,
            pupil_samples: Optional[int] = None, wavelength_weights: Sequence[float] = (),
            zernike_terms: int = 0, zernike_order: str = "fringe",
            mode: str = "") -> Union[AnalysisReport, AfocalReport]: ...
def trace_rays(lens: Lens, positions: npt.ArrayLike, directions: npt.ArrayLike, *,
               wavelength: int = -1, scale_to_spec: bool = True,
               dispersion: str = "") -> Dict[str, np.ndarray]: ...
def trace_pupil(lens: Lens, field_deg: float, pupil: npt.ArrayLike, *, wavelength: int = -1,
                ray_aiming: bool = True, scale_to_spec: bool = True,
                dispersion: str = "") -> Dict[str, np.ndarray]: ...
def spots(lens: Lens, *, rings: int = 32, fields: int = 21, ray_aiming: bool = True,
          scale_to_spec: bool = True, dispersion: str = "", threads: int = 0) -> Dict[str, Any]: ...
def psfs(lens: Lens, *, rings: int = 32, fields: int = 21, grid_size: int = 65,
         bin_um: float = 4.0, sigma_bins: float = 0.5, support_bins: int = 2,
         ray_aiming: bool = True, threads: int = 0) -> Dict[str, Any]: ...
def field_data(lens: Lens, *, rings: int = 32, fields: int = 21, ray_aiming: bool = True,
               threads: int = 0) -> Dict[str, List[float]]: ...

def prescription(lens: Lens, *, mode: str = "", dispersion: str = "") -> Dict[str, Any]: ...

def chromatic_focal_shift(lens: Lens, *, band: Optional[Sequence[float]] = None,
                          samples: int = 41, mode: str = "",
                          dispersion: str = "") -> Dict[str, Any]: ...

def lateral_colour(lens: Lens, *, mode: str = "", dispersion: str = "") -> Dict[str, Any]: ...

def encircled_energy(lens: Lens, *, fields: Sequence[int] = ..., radii: int = 101,
                     max_radius_um: float = 0.0, diffraction: bool = True,
                     pupil_samples: int = 128, mode: str = "", dispersion: str = "",
                     threads: Optional[int] = None) -> Dict[str, Any]: ...

def field_sweep(lens: Lens, *, fields: int = 11, frequencies: Sequence[float] = ...,
                mtf: bool = True, pupil_samples: int = 128, mode: str = "",
                dispersion: str = "", threads: Optional[int] = None) -> Dict[str, Any]: ...

class Renderer:
    def __init__(self, lens: Lens, *, rings: Optional[int] = None,
                 fields: Optional[int] = None, res_factor: int = 1,
                 distortion: bool = True, relative_illumination: bool = True,
                 threads: int = 0, psf: str = "geometric", pupil_samples: int = 64) -> None: ...
    def render(self, image: npt.ArrayLike) -> np.ndarray: ...
    def maps(self, width: int, height: int) -> Dict[str, Any]: ...
    fields_deg: List[float]
    reference_y_mm: List[float]
    centroid_y_mm: List[float]
    distortion: List[float]
    relative_illumination: List[float]
    # kind, diffraction (fields x 3 bool), diffraction_channels, pupil_samples, padding, fft_n,
    # warnings
    psf: Dict[str, Any]

def read_image(path: Union[str, os.PathLike]) -> np.ndarray: ...
def write_image(path: Union[str, os.PathLike], image: npt.ArrayLike) -> None: ...

class Parameterization:
    def __init__(self, lens: Lens, *, catalog: str = "", paraxial_image_solve: bool = True) -> None: ...
    size: int
    names: List[str]
    groups: List[str]
    focal_length_mm: float
    def __len__(self) -> int: ...
    def from_lens(self, lens: Lens) -> np.ndarray: ...
    def to_lens(self, x: npt.ArrayLike, glass_mode: str = "quantized") -> Lens: ...
    def glasses(self, x: npt.ArrayLike) -> List[str]: ...
    def select(self, names: Sequence[str]) -> List[int]: ...
    # None: the optimizer's default (weights 1, 100, 100, 0.01; 8 rings, 11 fields, 8 samples).
    def design_loss(self, x: npt.ArrayLike, *, weight_spot: Optional[float] = None,
                    weight_ray_path: Optional[float] = None,
                    weight_ray_angle: Optional[float] = None,
                    weight_glass: Optional[float] = None, rings: Optional[int] = None,
                    fields: Optional[int] = None, glass_mode: str = "quantized",
                    paper_penalties: bool = False, gradient: bool = True, merit: str = "spot",
                    wavefront_pupil_samples: Optional[int] = None) -> Dict[str, Any]: ...

class OptimizeResult:
    lens: Lens
    start_spot_um: float
    final_spot_um: float
    start_field_spot_um: List[float]
    final_field_spot_um: List[float]
    start_wavefront_waves: float  # merit="wavefront" only, else 0
    final_wavefront_waves: float
    afocal: bool
    start_angular_spot_mrad: float
    final_angular_spot_mrad: float
    start_field_angular_spot_mrad: List[float]
    final_field_angular_spot_mrad: List[float]
    glasses: List[str]
    iterations: int
    loss_evaluations: int
    seconds: float
    termination: str
    interrupted: bool
    kept_start: bool
    log: List[str]
    constraints_pass: bool

# The options are resolved as `lensopt optimize` resolves them (resolve_optimize_options): the
# defaults, the bounds for the lens (bounds="auto" | "lens" | "paper"), the lens's [optimize]
# table, then every argument that is not None.
def optimize(lens: Lens, *, max_iterations: Optional[int] = None,
             max_rounds: Optional[int] = None, freeze: Sequence[str] = ...,
             glass_search: Optional[str] = None, rings: Optional[int] = None,
             fields: Optional[int] = None, paper_penalties: Optional[bool] = None,
             verbose: bool = False, merit: Optional[str] = None,
             wavefront_pupil_samples: Optional[int] = None, bounds: str = "auto",
             vary: Optional[Sequence[str]] = None, soft_start: Optional[bool] = None,
             neighbours: Optional[int] = None, threads: Optional[int] = None,
             weight_ray_path: Optional[float] = None, weight_ray_angle: Optional[float] = None,
             weight_glass: Optional[float] = None, min_air_mm: Optional[float] = None,
             min_glass_mm: Optional[float] = None, max_glass_mm: Optional[float] = None,
             min_image_clearance_mm: Optional[float] = None,
             max_ray_angle_deg: Optional[float] = None, targets: Sequence[str] = ...,
             focus_only: Optional[bool] = None, min_virtual_image_mm: Optional[float] = None,
             max_virtual_image_mm: Optional[float] = None) -> OptimizeResult: ...

class ToleranceReport:
    lens_name: str
    nominal_spot_um: float
    trial_spots_um: List[float]
    spot_p90_um: float
    spot_mean_um: float
    yield_fraction: Optional[float]
    invalid_trials: int
    def to_json(self) -> str: ...
    def to_text(self) -> str: ...
    def trials_csv(self) -> str: ...
    def to_dict(self) -> Dict[str, Any]: ...

# None: `lensopt tolerance`'s value (the defaults, 10000 trials, seed 1, 16 rings, 11 fields,
# uniform, paraxial, with the lens's [tolerance] table applied).
def tolerance(lens: Lens, *, trials: Optional[int] = None, seed: Optional[int] = None,
              rings: Optional[int] = None, fields: Optional[int] = None,
              distribution: Optional[str] = None, compensator: Optional[str] = None,
              sensitivity: bool = True, max_spot_um: Optional[float] = None,
              threads: Optional[int] = None, jobs: Optional[int] = None) -> ToleranceReport: ...

class Imaging:
    def __init__(self, param: Parameterization, *, glass_mode: str = "quantized",
                 fixed_glasses: Sequence[int] = ..., rings: int = 8, fields: int = 21,
                 grid_size: int = 65, bin_um: float = 4.0, sigma_bins: float = 0.5,
                 support_bins: int = 3, res_factor: int = 1, relative_illumination: bool = True,
                 distortion: bool = True, ray_aiming: bool = True, threads: int = 0) -> None: ...
    variables: int
    timings: Dict[str, float]
    def prepare(self, x: npt.ArrayLike, derivatives: bool = True) -> None: ...
    def render(self, scene: npt.ArrayLike,
               crop: Optional[Tuple[int, int, int, int]] = None) -> np.ndarray: ...
    def backward(self, scene: npt.ArrayLike, crop: Optional[Tuple[int, int, int, int]],
                 grad: npt.ArrayLike,
                 scene_gradient: bool = True) -> Tuple[np.ndarray, Optional[np.ndarray]]: ...
    def render_images(self, images: np.ndarray,
                      crop: Optional[Tuple[int, int, int, int]] = None) -> np.ndarray: ...
    def scene_window(self, width: int, height: int, channels: int,
                     crop: Optional[Tuple[int, int, int, int]] = None
                     ) -> Tuple[int, int, int, int]: ...
    def backward_images(self, images: np.ndarray, crop: Optional[Tuple[int, int, int, int]],
                        grad: np.ndarray, *, lens_gradient: bool = True,
                        image_gradient: bool = True
                        ) -> Tuple[Optional[np.ndarray], Optional[np.ndarray]]: ...
    def optics(self, jacobians: bool = True) -> Dict[str, Any]: ...
    def optics_backward(self, grad_psf: npt.ArrayLike, grad_reference_y: npt.ArrayLike,
                        grad_centroid_y: npt.ArrayLike,
                        grad_illumination: npt.ArrayLike) -> np.ndarray: ...
    def layout(self, width: int, height: int) -> Dict[str, Any]: ...
