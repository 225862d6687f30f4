import os
from typing import Any, Iterable, Iterator, Optional, Sequence, Tuple, Union, overload

import numpy as np
import numpy.typing as npt

__version__: str

class FormatError(ValueError): ...
class InputError(ValueError): ...
class NetworkError(FormatError, ConnectionError): ...

Frames = Union[npt.ArrayLike, Iterable[npt.ArrayLike]]

class Container:
    def __init__(
        self,
        location: Union[str, os.PathLike[str]],
        *,
        tries: int = 4,
        stall_timeout: float = 20.0,
        connections: int = 4,
        cache: Optional[Union[str, os.PathLike[str]]] = None,
        cache_size: str = "2G",
        ca_file: Optional[Union[str, os.PathLike[str]]] = None,
    ) -> None: ...
    @property
    def dims(self) -> Tuple[int, int, int]: ...
    @property
    def frames(self) -> int: ...
    @property
    def times(self) -> list[float]: ...
    @property
    def levels(self) -> int: ...
    @property
    def value_range(self) -> Tuple[float, float]: ...
    @property
    def bps(self) -> float: ...
    @property
    def variable(self) -> str: ...
    @property
    def spacing(self) -> Tuple[float, float, float]: ...
    @property
    def location(self) -> str: ...
    @property
    def shape(self) -> Tuple[int, int, int, int]: ...
    def level_dims(self, level: int) -> Tuple[int, int, int]: ...
    def frame(
        self, t: int, level: Optional[int] = None, out: Optional[npt.NDArray[np.float32]] = None
    ) -> npt.NDArray[np.float32]: ...
    def info(self) -> dict[str, Any]: ...
    def close(self) -> None: ...
    @property
    def closed(self) -> bool: ...
    def __len__(self) -> int: ...
    @overload
    def __getitem__(self, t: int) -> npt.NDArray[np.float32]: ...
    @overload
    def __getitem__(self, t: slice) -> list[npt.NDArray[np.float32]]: ...
    def __iter__(self) -> Iterator[npt.NDArray[np.float32]]: ...
    def __enter__(self) -> Container: ...
    def __exit__(self, *exc: object) -> None: ...

def open(
    location: Union[str, os.PathLike[str]],
    *,
    tries: int = 4,
    stall_timeout: float = 20.0,
    connections: int = 4,
    cache: Optional[Union[str, os.PathLike[str]]] = None,
    cache_size: str = "2G",
    ca_file: Optional[Union[str, os.PathLike[str]]] = None,
) -> Container: ...
def encode(
    frames: Frames,
    out: Union[str, os.PathLike[str]],
    *,
    psnr: Optional[float] = None,
    bps: Optional[float] = None,
    tolerance: Optional[float] = None,
    max_error: Optional[float] = None,
    dictionary: Union[str, os.PathLike[str]] = "",
    codec: str = "ksvd",
    zfp_accuracy: Optional[float] = None,
    atoms: int = 0,
    max_keyframe_gap: Optional[int] = None,
    overwrite: bool = False,
    resume: bool = False,
    times: Optional[Sequence[float]] = None,
    variable: str = "",
    brick_size: Union[str, int] = "auto",
    spacing: Optional[Tuple[float, float, float]] = None,
) -> dict[str, Any]: ...
def train(
    frames: Frames,
    out: Union[str, os.PathLike[str]],
    *,
    atoms: int = 256,
    psnr: Optional[float] = None,
    tolerance: Optional[float] = None,
    times: Optional[Sequence[float]] = None,
    overwrite: bool = False,
) -> dict[str, Any]: ...
def psnr(a: npt.ArrayLike, b: npt.ArrayLike) -> float: ...
def ssim(a: npt.ArrayLike, b: npt.ArrayLike) -> float: ...
