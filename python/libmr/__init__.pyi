# Type stubs of the libmr package (the _libmr extension, re-exported). Units: metres, 1/m,
# degrees, pixels, scene-linear radiance. Images: numpy float32 arrays (H, W, C).
import enum
import os
from typing import Any, Callable, Iterator, List, Optional, Sequence, Tuple, Union, overload

import numpy as np
import numpy.typing as npt

__version__: str
__all__: List[str]

_Image = npt.NDArray[np.float32]  # (H, W, C) float32; (H, W) accepted as one channel
_Path = Union[str, os.PathLike]
_RgbLike = Sequence[float]

SCENE_FORMAT_VERSION: int

def version() -> str: ...

# --- errors ---
class ErrorCode(enum.IntEnum):
    invalid_argument = 0
    io = 1
    corrupt_input = 2
    size_mismatch = 3
    color = 4
    internal = 5
    cancelled = 6

class Error(Exception):
    code: ErrorCode
    message: str

class InvalidArgumentError(Error, ValueError): ...
class FileError(Error, OSError): ...
class CorruptInputError(Error): ...
class SizeMismatchError(Error, ValueError): ...
class ColorError(Error): ...
class InternalError(Error): ...
class CancelledError(Error): ...

# --- images, metadata, colour, files ---
class Metadata:
    def __init__(self, values: dict[str, Union[str, float]] = ...) -> None: ...
    def names(self) -> List[str]: ...
    def keys(self) -> List[str]: ...
    def get_string(self, name: str) -> Optional[str]: ...
    def get_number(self, name: str) -> Optional[float]: ...
    def get(self, name: str, default: Any = None) -> Union[str, float, Any]: ...
    def __getitem__(self, name: str) -> Union[str, float]: ...
    def __setitem__(self, name: str, value: Union[str, float]) -> None: ...
    def __delitem__(self, name: str) -> None: ...
    def __contains__(self, name: str) -> bool: ...
    def __len__(self) -> int: ...
    def __iter__(self) -> Iterator[str]: ...
    def to_dict(self) -> dict[str, Union[str, float]]: ...
    def copy(self) -> Metadata: ...

def image_metadata(image: _Image) -> Optional[Metadata]: ...
def is_libmr_image(image: Any) -> bool: ...
def new_image(height: int, width: int, channels: int = 3) -> _Image: ...

class ColorConfig:
    @staticmethod
    def builtin() -> ColorConfig: ...
    @staticmethod
    def from_file(path: _Path) -> ColorConfig: ...
    @staticmethod
    def from_environment(path: Optional[_Path] = None) -> ColorConfig: ...
    @property
    def source(self) -> str: ...
    def colorspace_names(self) -> List[str]: ...
    def has_colorspace(self, name: str) -> bool: ...
    def is_data(self, name: str) -> bool: ...
    def display_colorspace(self) -> str: ...
    def convert(self, image: _Image, from_space: str, to_space: str) -> None:
        """In place, first three channels."""

def highlight_rolloff(x: float, knee: float = 0.8) -> float: ...

class PixelType(enum.IntEnum):
    automatic = 0
    uint8 = 1
    uint16 = 2
    half = 3
    float32 = 4

_PixelTypeArg = Union[PixelType, str]  # "automatic", "8", "16", "half", "float"

class ImageFileInfo:
    width: int
    height: int
    channels: int
    pixel_type: PixelType
    format: str
    orientation: int
    software: str

def probe_image(path: _Path) -> ImageFileInfo: ...
@overload
def read_image(path: _Path, *, colorspace: str = "", to_scene_linear: bool = True,
               reject_non_finite: bool = True, apply_orientation: bool = True,
               color: Union[ColorConfig, _Path, None] = None,
               with_metadata: bool = False) -> _Image: ...
@overload
def read_image(path: _Path, *, colorspace: str = "", to_scene_linear: bool = True,
               reject_non_finite: bool = True, apply_orientation: bool = True,
               color: Union[ColorConfig, _Path, None] = None,
               with_metadata: bool = True) -> Tuple[_Image, Metadata]: ...
def write_image(path: _Path, image: _Image, *, pixel_type: _PixelTypeArg = "automatic",
                colorspace: str = "", jpeg_quality: int = 95, overwrite: bool = True,
                metadata: Optional[Metadata] = None,
                color: Union[ColorConfig, _Path, None] = None) -> None: ...
def write_exr_layers(path: _Path, layers: List[tuple], *, metadata: Optional[Metadata] = None,
                     pixel_type: _PixelTypeArg = "half") -> None: ...
def check_output_path(path: _Path) -> None: ...
def write_text_file(path: _Path, text: str, overwrite: bool = True) -> None: ...
def is_readable_image_extension(path: _Path) -> bool: ...
def is_writable_image_extension(path: _Path) -> bool: ...
def max_decoded_pixels() -> int: ...
def set_max_decoded_pixels(pixels: int) -> None: ...

class CancelToken:
    def __init__(self) -> None: ...
    def request(self) -> None: ...
    def requested(self) -> bool: ...
    def reset(self) -> None: ...
    def set_progress(self, callback: Optional[Callable[[str, int, int], None]],
                     min_interval_s: float = 0.1) -> None: ...

# --- scene ---
class Vec3:
    x: float
    y: float
    z: float
    @overload
    def __init__(self, x: float = 0.0, y: float = 0.0, z: float = 0.0) -> None: ...
    @overload
    def __init__(self, xyz: Sequence[float]) -> None: ...
    def __iter__(self) -> Iterator[float]: ...
    def __len__(self) -> int: ...
    def __getitem__(self, i: int) -> float: ...

def direction_from_azimuth_elevation(azimuth_deg: float, elevation_deg: float) -> Vec3: ...

class Camera:
    width: int
    height: int
    focal_px: float
    cx: float
    cy: float
    def __init__(self, width: int, height: int, focal_px: float, cx: Optional[float] = None,
                 cy: Optional[float] = None) -> None: ...
    @staticmethod
    def from_horizontal_fov(width: int, height: int, fov_deg: float) -> Camera: ...
    @staticmethod
    def from_focal_px(width: int, height: int, focal_px: float) -> Camera: ...
    @staticmethod
    def from_metadata(width: int, height: int, metadata: Optional[Metadata] = None,
                      fallback_fov_deg: float = 60.0) -> Camera: ...
    def horizontal_fov_deg(self) -> float: ...
    def z_to_distance(self, x: int, y: int) -> float: ...
    def ray_direction(self, x: int, y: int) -> Tuple[float, float, float]: ...

class SceneCamera:
    width: int
    height: int
    focal_px: float
    principal_point_px: Optional[Tuple[float, float]]
    def __init__(self, **fields: Any) -> None: ...

def camera_for_image(camera: SceneCamera, width: int, height: int) -> Camera: ...
def scene_camera(camera: Camera) -> SceneCamera: ...

class CameraPose:
    position_m: Vec3
    yaw_deg: float
    pitch_deg: float
    roll_deg: float
    def __init__(self, **fields: Any) -> None: ...
    def axes(self) -> Tuple[Vec3, Vec3, Vec3]: ...
    def ray_direction(self, camera: Camera, x: float, y: float) -> Vec3: ...

class Medium:
    class HeightFog:
        base_height_m: float
        scale_height_m: float
        def __init__(self, **fields: Any) -> None: ...
    class Noise:
        amplitude: float
        scale_m: float
        octaves: int
        seed: int
        def __init__(self, **fields: Any) -> None: ...
    sigma_t_per_m: List[float]  # 1/m, (R, G, B)
    albedo: List[float]
    g: float
    height_fog: Optional[Medium.HeightFog]
    layer_bottom_m: float
    layer_top_m: float
    noise: Medium.Noise
    def __init__(self, **fields: Any) -> None: ...

class Sun:
    direction_to_sun: Vec3
    irradiance: List[float]
    angular_radius_deg: float
    irradiance_auto: bool
    def __init__(self, **fields: Any) -> None: ...

class Lamp:
    position_m: Vec3
    intensity_per_sr: List[float]
    spot_direction: Vec3
    inner_angle_deg: float
    outer_angle_deg: float
    intensity_auto: bool
    def __init__(self, **fields: Any) -> None: ...

class LampList:
    def __init__(self, lamps: Sequence[Lamp] = ...) -> None: ...
    def append(self, lamp: Lamp) -> None: ...
    def extend(self, lamps: Sequence[Lamp]) -> None: ...
    def insert(self, i: int, lamp: Lamp) -> None: ...
    def pop(self, i: int = -1) -> Lamp: ...
    def clear(self) -> None: ...
    def __getitem__(self, i: int) -> Lamp: ...
    def __setitem__(self, i: int, lamp: Lamp) -> None: ...
    def __delitem__(self, i: int) -> None: ...
    def __len__(self) -> int: ...
    def __iter__(self) -> Iterator[Lamp]: ...

class Lighting:
    sun: Optional[Sun]
    sky_radiance: Optional[List[float]]
    lamps: LampList
    def __init__(self, **fields: Any) -> None: ...

class Quality(enum.IntEnum):
    draft = 0
    normal = 1
    final = 2

class Backend(enum.IntEnum):
    automatic = 0
    cpu = 1
    vulkan = 2

class ShadowTraversal(enum.IntEnum):
    embree = 0
    multi_index = 1

class RenderSettings:
    quality: Quality
    backend: Backend
    march_steps: int
    grid_step: int
    gradient_acceleration: bool
    volumetric_shadows: bool
    light_path_attenuation: bool
    max_distance_m: float
    seed: int
    threads: int
    shadow_traversal: ShadowTraversal
    def __init__(self, **fields: Any) -> None: ...

class Blockers:
    class Completion:
        enabled: bool
        max_height_m: float
        max_extent_m: float
        prism_max_width_m: float
        def __init__(self, **fields: Any) -> None: ...
    class SkylineSample:
        azimuth_deg: float
        height_m: float
        def __init__(self, **fields: Any) -> None: ...
    class Skyline:
        distance_m: float
        samples: List[Blockers.SkylineSample]
        def __init__(self, **fields: Any) -> None: ...
    class Polygon:
        corners_m: List[Vec3]
        def __init__(self, **fields: Any) -> None: ...
    class Canopy:
        height_m: float
        gap_fraction: float
        radius_m: float
        cell_m: float
        seed: int
        def __init__(self, **fields: Any) -> None: ...
    completion: Blockers.Completion
    skyline: Optional[Blockers.Skyline]
    polygons: List[Blockers.Polygon]
    canopy: Optional[Blockers.Canopy]
    def __init__(self, **fields: Any) -> None: ...

class Scene:
    pose: CameraPose
    medium: Medium
    lighting: Lighting
    render: RenderSettings
    camera: Optional[SceneCamera]
    blockers: Blockers
    def __init__(self, **fields: Any) -> None: ...
    def validate(self) -> None: ...
    def warnings(self) -> List[str]: ...
    def to_json(self) -> str: ...
    @staticmethod
    def from_json(text: str, source_name: str = "<scene>") -> Scene: ...
    def copy(self) -> Scene: ...

def scene_from_json(text: str, source_name: str = "<scene>") -> Scene: ...
def scene_to_json(scene: Scene) -> str: ...
def load_scene(path: _Path) -> Scene: ...
def save_scene(path: _Path, scene: Scene) -> None: ...
def validate_scene(scene: Scene) -> None: ...
def scene_warnings(scene: Scene) -> List[str]: ...

# --- fog ---
def extinction_from_visibility(visibility_m: float) -> float: ...
def visibility_from_extinction(sigma_t_per_m: float) -> float: ...
def estimate_airlight(image: _Image) -> List[float]: ...

class DepthKind(enum.IntEnum):
    distance = 0
    planar_z = 1
    disparity = 2

_DepthKindArg = Union[DepthKind, str]  # "distance", "z", "disparity"

class DepthMap:
    distance_m: _Image  # (H, W, 1) metres along each ray, +inf = sky
    no_surface_pixels: int
    invalid_pixels: int
    sky_threshold_pixels: int
    clamped_pixels: int

def read_depth(path: _Path, camera: Optional[Camera] = None, *, kind: _DepthKindArg = "distance",
               scale: float = 1.0, baseline_m: float = 0.0, doffs_px: float = 0.0,
               sky_depth_m: float = 65504.0) -> DepthMap: ...
def depth_to_distance(stored: _Image, camera: Optional[Camera] = None, *,
                      kind: _DepthKindArg = "distance", scale: float = 1.0,
                      baseline_m: float = 0.0, doffs_px: float = 0.0,
                      sky_depth_m: float = 65504.0) -> DepthMap: ...

class FogLayers:
    composite: _Image  # C = I T + R
    transmittance: _Image  # T in [0, 1]
    inscatter: _Image  # R, scene-linear radiance
    sun_visibility: Optional[_Image]  # (H, W, 1)
    optical_depth: Optional[_Image]  # (H, W, 3)
    sky_radiance: List[float]
    camera: Camera
    backend: str
    backend_notice: str
    backend_notice_is_warning: bool
    timings: dict[str, float]
    warnings: List[str]
    call_s: float

def default_camera(width: int, height: int, scene: Optional[Scene] = None,
                   metadata: Optional[Metadata] = None) -> Camera: ...
def fog(image: _Image, depth: _Image, scene: Optional[Scene] = None, *,
        camera: Optional[Camera] = None, sky_alpha: Optional[_Image] = None,
        metadata: Optional[Metadata] = None, cancel: Optional[CancelToken] = None,
        soften_seams: bool = False) -> FogLayers: ...
def working_size(width: int, height: int, long_side_px: int = 1280) -> Optional[Tuple[int, int]]: ...
def working_copy(image: _Image, width: int, height: int) -> np.ndarray: ...
def scale_camera(camera: Camera, width: int, height: int) -> Camera: ...
def upsample_fog(image: _Image, working_image: _Image, working: FogLayers) -> FogLayers: ...
class FileFogResult:
    streamed: bool
    reason: str
    camera: Camera
    width: int
    height: int
    no_surface_pixels: int
    invalid_pixels: int
    sky_threshold_pixels: int
    clamped_pixels: int

def fog_file(photo: _Path, depth: _Path, output: _Path, scene: Optional[Scene] = None, *,
             camera: Optional[Camera] = None, depth_kind: _DepthKindArg = "distance",
             depth_scale: float = 1.0, baseline_m: float = 0.0, doffs_px: float = 0.0,
             sky_depth_m: float = 65504.0, pixel_type: _PixelTypeArg = "automatic",
             colorspace: str = "", input_colorspace: str = "", software: str = "",
             jpeg_quality: int = 95, overwrite: bool = True,
             color: Union[ColorConfig, _Path, None] = None,
             cancel: Optional[CancelToken] = None) -> FileFogResult: ...
def fog_homogeneous(image: _Image, depth: _Image, sigma_t_per_m: Union[float, _RgbLike],
                    airlight: Union[float, _RgbLike, None] = None) -> FogLayers: ...

# --- estimation ---
class SunEstimate:
    direction_to_sun: Vec3
    azimuth_deg: float
    elevation_deg: float
    rms_residual_deg: float
    median_residual_px: float

class SceneEstimate:
    scene: Scene
    camera: Camera
    camera_source: str
    distance_m: _Image
    sky_alpha: Optional[_Image]
    depth_confidence: Optional[_Image]
    horizon: Tuple[Tuple[float, float], Tuple[float, float]]
    horizon_source: str
    height_source: str
    confidence: float
    sky_from_mask: bool
    sun: Optional[SunEstimate]
    notes: List[str]
    pixels: dict[str, int]

def camera_for_photo(image: _Image, fallback_fov_deg: float = 60.0, *,
                     metadata: Optional[Metadata] = None) -> Tuple[Camera, str, float]: ...
def estimate(image: _Image, annotations: Union[dict, str, _Path, None] = None, *,
             camera: Optional[Camera] = None, metadata: Optional[Metadata] = None,
             automatic: bool = True, default_camera_height_m: float = 1.6,
             billboard_depression_deg: float = 2.0, ground_contact: bool = True,
             min_rise_ratio: float = 0.4, refine_depth: bool = True, sky_fold: bool = True,
             vegetation: bool = True, people: bool = True, frame_border: bool = True,
             backlit_land: bool = True, water_mirror: bool = True, lamps_not_sky: bool = True,
             cancel: Optional[CancelToken] = None) -> SceneEstimate: ...

# --- material transfer ---
class Material:
    diffuse_albedo: List[float]
    specular_albedo: float
    roughness: float
    def __init__(self) -> None: ...

class MaterialCandidate:
    material: Material
    segment: int
    pixel_count: int
    relative_rms: float

class MaterialTransferResult:
    image: _Image
    segment_labels: Optional[_Image]
    candidates: List[MaterialCandidate]
    assignment: List[int]
    exposures: List[float]
    objective: float
    best_objective_history: List[float]
    notes: List[str]
    warnings: List[str]
    def to_json(self) -> str: ...

def load_region_labels(path: _Path, width: int, height: int) -> _Image: ...
def transfer_material(sample: _Image, sample_depth: _Image, target: Optional[_Image],
                      target_depth: _Image, region_labels: Union[_Image, _Path], *,
                      sample_scene: Optional[Scene] = None, target_scene: Optional[Scene] = None,
                      sample_camera: Optional[Camera] = None,
                      target_camera: Optional[Camera] = None, max_candidates: int = 8,
                      superpixel_size_px: float = 0.0, max_relative_rms: float = 0.25,
                      smoothness_weight: float = 0.1, tabu_max_iterations: int = 200,
                      tabu_patience: int = 40, seed: int = 1, keep_detail: bool = True,
                      fit_photo_range: bool = True, threads: int = 0,
                      cancel: Optional[CancelToken] = None) -> MaterialTransferResult: ...
