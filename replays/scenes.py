"""The five ETH/UCY scenes: letters, recordings, homography, photo and walkability map.

Pixel convention (verified on every recording): ``pixel = H^-1 (x, y, 1)``, divided by its third
component, gives (column u, row v); ``world = H (u, v, 1)``.
"""

from __future__ import annotations

import io
import os
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Final

import numpy as np

from replays.data_root import data_root
from replays.errors import DataFormatError, UnknownNameError
from replays.files import parse_numbers, read_bytes, require_budget

MAX_HOMOGRAPHY_BYTES: Final = 4096  # a 3x3 matrix in text [B]
MAX_IMAGE_BYTES: Final = 64 << 20  # largest photo or map file read [B]; ETH/UCY's largest is 0.6 MB
IMAGE_BYTES_PER_PIXEL: Final = 16  # decoded image (up to 4 x 16 bit) + RGB copy + map, per pixel [B]
PNG_SIGNATURE: Final = b"\x89PNG\r\n\x1a\n"


@dataclass(frozen=True)
class SceneInfo:
    """Static facts of one scene (no arrays)."""

    name: str
    """scene name: eth, hotel, univ, zara1, zara2"""
    letter: str
    """letter of the domain-adaptation protocol (A-E)"""
    recordings: tuple[str, ...]
    """recordings of the test set (whole files)"""
    train_recordings: tuple[str, ...]
    """recordings whose raw/train and raw/val portions train a domain-adaptation model"""
    image: str
    """stem of the photo/map pair under image/"""

    def __repr__(self) -> str:
        return f"{self.letter}/{self.name}"


SCENES: dict[str, SceneInfo] = {
    s.name: s
    for s in (
        SceneInfo("eth", "A", ("biwi_eth",), ("biwi_eth",), "seq_eth"),
        SceneInfo("hotel", "B", ("biwi_hotel",), ("biwi_hotel",), "seq_hotel"),
        SceneInfo("univ", "C", ("students001", "students003"),
                  ("students001", "students003", "uni_examples"), "students003"),
        SceneInfo("zara1", "D", ("crowds_zara01",), ("crowds_zara01",), "crowds_zara01"),
        SceneInfo("zara2", "E", ("crowds_zara02",), ("crowds_zara02", "crowds_zara03"), "crowds_zara02"),
    )
}
SCENE_NAMES: tuple[str, ...] = tuple(SCENES)
LETTERS: dict[str, str] = {s.letter: s.name for s in SCENES.values()}


def scene_info(name: str) -> SceneInfo:
    """Look a scene up by name (``"zara1"``) or letter (``"D"``)."""
    key = LETTERS.get(name, name.lower()) if isinstance(name, str) else None
    if key not in SCENES:
        raise UnknownNameError(f"unknown scene {name!r}; expected one of {', '.join(SCENES)} or letters A-E")
    return SCENES[key]


def scene_of_recording(recording: str) -> SceneInfo:
    """Scene a recording belongs to; accepts split suffixes (``crowds_zara03_train``)."""
    base = str(recording).removesuffix("_train").removesuffix("_val")
    for info in SCENES.values():
        if base in info.train_recordings:
            return info
    raise UnknownNameError(f"recording {recording!r} belongs to no ETH/UCY scene")


def read_homography(path: Path) -> np.ndarray:
    """(3, 3) float64 matrix H with world = H @ pixel, from a whitespace-separated text file."""
    text = read_bytes(path, MAX_HOMOGRAPHY_BYTES, "homography")
    try:
        H = parse_numbers(io.StringIO(text.decode("utf-8")))
    except ValueError as err:  # also UnicodeDecodeError
        raise DataFormatError(f"{path}: cannot read a 3x3 homography ({err})") from err
    if H.shape != (3, 3) or not np.isfinite(H).all() or abs(np.linalg.det(H)) < 1e-12:
        raise DataFormatError(f"{path}: expected a finite, invertible 3x3 matrix, got shape {H.shape}")
    return H


def read_image(path: Path, grayscale: bool) -> np.ndarray:
    """Read a PNG with OpenCV: (H, W) uint8 if grayscale else (H, W, 3) uint8 RGB.

    Its size is read from the PNG header first: an image whose decoding would pass
    ``replays.files.MEMORY_BUDGET_BYTES`` (16 bytes per pixel) is refused before it is decoded.
    """
    import cv2

    data = read_bytes(path, MAX_IMAGE_BYTES, "photo or map")
    if len(data) < 24 or data[:8] != PNG_SIGNATURE or data[12:16] != b"IHDR":
        raise DataFormatError(f"{path}: not a PNG image")
    width, height = int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")
    require_budget(width * height * IMAGE_BYTES_PER_PIXEL, f"{path}: decoding a {width} x {height} px image")
    flag = cv2.IMREAD_UNCHANGED if grayscale else cv2.IMREAD_COLOR
    image = cv2.imdecode(np.frombuffer(data, np.uint8), flag)
    if image is None or image.shape[:2] != (height, width):
        raise DataFormatError(f"{path}: damaged or unreadable PNG image")
    if grayscale and (image.ndim != 2 or image.dtype != np.uint8):
        raise DataFormatError(f"{path}: expected a single-channel 8-bit map, got shape {image.shape} {image.dtype}")
    return image if grayscale else cv2.cvtColor(image, cv2.COLOR_BGR2RGB)


class Scene:
    """A scene's geometry: homography, walkability map, photo and world <-> pixel conversion.

    Built from files with ``load_scene`` (ETH/UCY) or from arrays (simulated layouts rasterised to a map).
    Read-only: ``load_scene`` shares one Scene per process among envs, evaluators and plug-ins, so its arrays are
    private copies that refuse writes, and its attributes cannot be reassigned (``AttributeError``).

    Attributes:
        name: scene name.
        H: (3, 3) float64, world = H @ (u, v, 1).   H_inv: its inverse.
        walkable: (H, W) bool, True = walkable.
        photo: (H, W, 3) uint8 RGB (a rendering of the map for simulated layouts).
    """

    __slots__ = ("H", "H_inv", "__weakref__", "name", "photo", "walkable")

    def __init__(self, name: str, H: np.ndarray, walkable: np.ndarray, photo: np.ndarray | None = None):
        H = np.array(H, dtype=np.float64)
        if H.shape != (3, 3) or not np.isfinite(H).all() or abs(np.linalg.det(H)) < 1e-12:
            raise ValueError(f"scene {name}: H must be a finite, invertible 3x3 matrix, got shape {H.shape}")
        walkable = np.array(walkable, dtype=bool)
        if walkable.ndim != 2 or 0 in walkable.shape:
            raise ValueError(f"scene {name}: walkable must be a non-empty (H, W) map, got shape {walkable.shape}")
        photo = np.array(photo) if photo is not None else np.repeat(walkable[..., None] * np.uint8(255), 3, -1)
        if photo.shape != (*walkable.shape, 3):
            raise ValueError(f"scene {name}: photo must be (H, W, 3) like the map {walkable.shape}, "
                             f"got {photo.shape}")
        for field, value in (("name", str(name)), ("H", H), ("H_inv", np.linalg.inv(H)), ("walkable", walkable),
                             ("photo", photo)):
            if isinstance(value, np.ndarray):
                value.flags.writeable = False
            object.__setattr__(self, field, value)

    def __setattr__(self, name: str, value: object) -> None:
        raise AttributeError(f"Scene {self.name} is read-only: build a new Scene instead of setting {name!r}")

    def __reduce__(self) -> tuple:
        return Scene, (self.name, self.H, self.walkable, self.photo)

    def __repr__(self) -> str:
        return f"Scene({self.name}, map {self.walkable.shape[1]}x{self.walkable.shape[0]} px)"

    @classmethod
    def from_files(cls, info: SceneInfo, root: Path) -> Scene:
        """Read an ETH/UCY scene's homography, map and photo from the data root."""
        H = read_homography(root / "homography" / f"{info.recordings[0]}_H.txt")
        map_path = root / "image" / f"{info.image}_map.png"
        mask = read_image(map_path, grayscale=True)
        if not np.isin(mask, (0, 1)).all():
            raise DataFormatError(f"{map_path}: expected values 0/1 only")
        photo = read_image(root / "image" / f"{info.image}_reference.png", grayscale=False)
        if photo.shape[:2] != mask.shape:
            raise DataFormatError(f"{map_path}: map {mask.shape} and photo {photo.shape[:2]} differ in size")
        return cls(info.name, H, mask.astype(bool), photo)

    def world_to_pixel(self, xy_m: np.ndarray) -> np.ndarray:
        """(..., 2) world metres -> (..., 2) float pixel (column u, row v)."""
        return apply_homography(self.H_inv, xy_m)

    def pixel_to_world(self, uv_px: np.ndarray) -> np.ndarray:
        """(..., 2) pixel (column u, row v) -> (..., 2) world metres."""
        return apply_homography(self.H, uv_px)

    def is_walkable(self, xy_m: np.ndarray) -> np.ndarray:
        """(..., 2) world metres -> (...) bool; points off the image count as not walkable."""
        uv = np.rint(self.world_to_pixel(xy_m))
        height, width = self.walkable.shape
        inside = (uv[..., 0] >= 0) & (uv[..., 0] < width) & (uv[..., 1] >= 0) & (uv[..., 1] < height)
        u = np.where(inside, uv[..., 0], 0).astype(np.intp)
        v = np.where(inside, uv[..., 1], 0).astype(np.intp)
        return inside & self.walkable[v, u]


def apply_homography(H: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply a 3x3 projective map to (..., 2) points; returns (..., 2) float64. An affine map (last row 0, 0, 1:
    every synthetic layout's) skips the perspective division.

    Each coordinate is its sum of products written out, the same bits on every CPU and for every batch (a matrix
    product's rounding depends on the BLAS kernel the CPU gets, with or without fused multiply-adds)."""
    points = np.asarray(points, dtype=np.float64)
    x, y = points[..., 0], points[..., 1]
    u = x * H[0, 0] + y * H[0, 1] + H[0, 2]
    v = x * H[1, 0] + y * H[1, 1] + H[1, 2]
    if H[2, 0] == 0.0 and H[2, 1] == 0.0 and H[2, 2] == 1.0:
        return np.stack([u, v], axis=-1)
    w = x * H[2, 0] + y * H[2, 1] + H[2, 2]
    return np.stack([u / w, v / w], axis=-1)


@cache
def _load_scene(name: str, root: Path) -> Scene:
    return Scene.from_files(scene_info(name), root)


def load_scene(name: str, root: str | os.PathLike | None = None) -> Scene:
    """Scene by name or letter, its files read from the data root (cached per root)."""
    return _load_scene(scene_info(name).name, data_root(root))
