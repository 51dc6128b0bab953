"""Type stubs of fibrefit's Rust extension (use the wrappers in `fibrefit`)."""

from typing import Any, Dict, List, Optional, Tuple

import numpy as np
import numpy.typing as npt

class FibrefitError(ValueError): ...

class Material:
    def eval(
        self,
        l: npt.NDArray[np.float64],
        v: npt.NDArray[np.float64],
        uv: Optional[npt.NDArray[np.float64]] = None,
        instance: Optional[npt.NDArray[np.float64]] = None,
    ) -> npt.NDArray[np.float64]: ...
    def sample(
        self,
        v: npt.NDArray[np.float64],
        u: npt.NDArray[np.float64],
        uv: Optional[npt.NDArray[np.float64]] = None,
        instance: Optional[npt.NDArray[np.float64]] = None,
    ) -> Tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]]: ...
    def pdf(
        self,
        v: npt.NDArray[np.float64],
        l: npt.NDArray[np.float64],
        uv: Optional[npt.NDArray[np.float64]] = None,
        instance: Optional[npt.NDArray[np.float64]] = None,
    ) -> npt.NDArray[np.float64]: ...
    def render_capture(self, capture: str, index: int) -> npt.NDArray[np.float32]: ...
    @property
    def model(self) -> str: ...
    @property
    def instances(self) -> int: ...
    @property
    def channels(self) -> int: ...
    @property
    def has_maps(self) -> bool: ...
    @property
    def maps_size(self) -> Optional[Tuple[int, int]]: ...
    def texel_fields(self) -> Optional[Dict[str, Any]]: ...
    @property
    def maps_dir(self) -> Optional[str]: ...
    @property
    def fibre_azimuth_deg(self) -> float: ...
    @property
    def source(self) -> str: ...
    @property
    def warnings(self) -> List[str]: ...
    @property
    def undetermined(self) -> List[Tuple[str, str]]: ...

class FitResult:
    def json(self) -> str: ...
    def report(self) -> str: ...
    @property
    def warnings(self) -> List[str]: ...
    @property
    def model(self) -> str: ...
    @property
    def has_maps(self) -> bool: ...
    @property
    def verdict(self) -> str: ...
    @property
    def floor(self) -> Optional[float]: ...
    @property
    def floor_ratio(self) -> Optional[float]: ...
    @property
    def reciprocal_floor(self) -> Optional[float]: ...
    @property
    def correction(self) -> Optional[Tuple[int, float, float]]: ...
    def to_json(self, path: str, report: Optional[str] = None) -> None: ...
    def material(self) -> Material: ...

def load(result: str, maps: Optional[str] = None, capture: Optional[str] = None) -> Material: ...
def load_data(
    path: str,
    *,
    stride: Optional[int] = None,
    fraction: Optional[float] = None,
    subsample_seed: Optional[int] = None,
    directions: Optional[int] = None,
    direction_seed: Optional[int] = None,
    max_theta: Optional[float] = None,
    skip_bad_rows: bool = False,
    small_angles_ok: bool = False,
    columns: Optional[Dict[str, str]] = None,
) -> Dict[str, Any]: ...
def fit(
    data: Optional[str] = None,
    config: Optional[str] = None,
    model: Optional[str] = None,
    *,
    table: Optional[str] = None,
    l: Optional[np.ndarray] = None,
    v: Optional[np.ndarray] = None,
    values: Optional[np.ndarray] = None,
    sigma: Optional[np.ndarray] = None,
    metric: Optional[str] = None,
    fuzz: Optional[bool] = None,
    maps: Optional[str] = None,
    progress: bool = False,
    threads: Optional[int] = None,
    gltf_variant: Optional[str] = None,
    correction: Optional[bool] = None,
    stride: Optional[int] = None,
    fraction: Optional[float] = None,
    subsample_seed: Optional[int] = None,
    directions: Optional[int] = None,
    direction_seed: Optional[int] = None,
    max_theta: Optional[float] = None,
    skip_bad_rows: bool = False,
    small_angles_ok: bool = False,
    columns: Optional[Dict[str, str]] = None,
    angles: Optional[str] = None,
) -> FitResult: ...
def score(
    result: str,
    data: str,
    *,
    stride: Optional[int] = None,
    fraction: Optional[float] = None,
    subsample_seed: Optional[int] = None,
    directions: Optional[int] = None,
    direction_seed: Optional[int] = None,
    max_theta: Optional[float] = None,
    skip_bad_rows: bool = False,
    small_angles_ok: bool = False,
    columns: Optional[Dict[str, str]] = None,
) -> Tuple[str, str]: ...
def eval(
    params: str, queries: str, model: Optional[str] = None, *, progress: bool = False
) -> Tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]: ...
def export(
    result: str,
    shader: Optional[str] = None,
    gltf: bool = False,
    object: str = "swatch",
    check: bool = False,
    model: Optional[str] = None,
    *,
    progress: bool = False,
) -> Dict[str, Any]: ...
def blender_script(
    result: str, name: Optional[str] = None, out: Optional[str] = None, *, progress: bool = False
) -> Dict[str, Any]: ...
def openpbr_material(
    result: str,
    name: Optional[str] = None,
    materialx: Optional[str] = None,
    usd: Optional[str] = None,
    *,
    progress: bool = False,
) -> Dict[str, Any]: ...
def view(
    result: str,
    out: Optional[str] = None,
    data: Optional[str] = None,
    *,
    progress: bool = False,
) -> str: ...
def version() -> str: ...
def capture_geometry(capture: str) -> str: ...
def image_scene(capture: str, index: int) -> str: ...
def capture_image(capture: str, index: int) -> Tuple[npt.NDArray[np.float32], npt.NDArray[np.bool_]]: ...
