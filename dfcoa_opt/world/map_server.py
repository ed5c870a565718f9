"""Maps in the ROS ``map_server`` format: a YAML file plus an image (PGM or PNG).

The reading follows nav2's ``nav2_map_server/src/map_io.cpp`` (``loadMapYaml``
and ``loadMapFromFile`` as of Jazzy, Kilted and Rolling):

- YAML keys ``image``, ``resolution`` (m/cell), ``origin`` ``[x, y, yaw]`` (the
  pose of the lower-left corner of the lower-left pixel), ``negate``,
  ``occupied_thresh`` and ``free_thresh`` are required; ``mode`` is optional
  (``trinary``, the default, ``scale`` or ``raw``, in any case). A relative
  ``image`` is relative to the YAML file's folder.
- The image is made grey (a colour pixel by the Rec. 601 luma weights), then each
  pixel gets the value map_server publishes (:func:`map_server_values`): 100
  occupied, 0 free, -1 unknown, 1..99 between the thresholds in ``scale`` mode,
  the grey level itself (0..100, else -1) in ``raw`` mode. In ``trinary`` and
  ``scale`` mode an image with an alpha channel makes every pixel that is not
  fully opaque unknown.
- The image's top row is the top of the map.

**The toolkit's rule:** a cell is free only when map_server would publish 0 for
it. Unknown (-1) and every value 1..100 count as occupied: robots stay out of
space that nobody has seen, and out of every cell with some chance of an
obstacle.

Not supported (a one-line :class:`~dfcoa_opt.core.errors.ScenarioError`): a rotated
map (``yaw != 0``), 16-bit images, and YAML beyond flat ``key: value`` lines
(:func:`parse_flat_yaml`). Every error names the YAML file and the key.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.core.atomic import file_exists
from dfcoa_opt.core.errors import ScenarioError, did_you_mean
from dfcoa_opt.world.flat_yaml import parse_flat_yaml
from dfcoa_opt.world.grid import OccupancyGrid

#: The values map_server publishes for an occupied, a free and an unknown cell.
OCCUPIED, FREE, UNKNOWN = 100, 0, -1
#: map_server's modes (``mode`` is matched without regard to case, as nav2 does).
MODES = ("trinary", "scale", "raw")
#: The keys nav2's ``loadMapYaml`` requires; ``mode`` is optional (default ``trinary``).
REQUIRED = ("image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh")
KEYS = (*REQUIRED, "mode")



@dataclass(frozen=True)
class MapYaml:
    """The fields of a map_server YAML file, checked.

    Attributes:
        path: The YAML file.
        image: The image file (a relative ``image`` resolved against the YAML's folder).
        resolution: Side of one cell, m/cell (the toolkit's ``world.resolution`` is
            its inverse, cells/m).
        origin: World ``(x, y)`` of the lower-left corner of the lower-left pixel, m.
        negate: Whether white means occupied.
        occupied_thresh: Occupancy probability at or above which a pixel is occupied.
        free_thresh: Occupancy probability at or below which a pixel is free.
        mode: ``"trinary"``, ``"scale"`` or ``"raw"``.
    """

    path: Path
    image: Path
    resolution: float
    origin: tuple[float, float]
    negate: bool
    occupied_thresh: float
    free_thresh: float
    mode: str = "trinary"


# ----------------------------------------------------------------------- the YAML
def read_map_yaml(path: str | Path) -> MapYaml:
    """Read and check a map_server YAML file.

    Args:
        path: The ``.yaml`` file.

    Raises:
        ScenarioError: An unreadable file, a syntax outside :func:`parse_flat_yaml`,
            an unknown or missing key, or a bad value (one line naming the file and
            the key).
    """
    path = Path(path)
    src = str(path)
    try:
        text = path.read_bytes().decode("utf-8-sig")  # a byte-order mark is no key
    except OSError as exc:
        raise ScenarioError(src, "", f"cannot read the map YAML: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:
        raise ScenarioError(src, "", f"is not UTF-8 text ({exc.reason} at byte {exc.start})"
                            ) from None
    data = parse_flat_yaml(text, src)
    for key in data:
        if key not in KEYS:
            raise ScenarioError(src, key, "unknown map_server key" + did_you_mean(key, KEYS)
                                + f"; known keys: {', '.join(KEYS)}")
    for key in REQUIRED:
        if key not in data:
            raise ScenarioError(src, key, "is required (map_server needs it)")
    free, occupied = (_number(data, k, src, 0.0, 1.0) for k in ("free_thresh", "occupied_thresh"))
    if not free < occupied:
        raise ScenarioError(src, "free_thresh", f"{free:g} must be below occupied_thresh "
                                                f"({occupied:g})")
    return MapYaml(path=path, image=_image_path(data["image"], path), origin=_origin(data, src),
                   resolution=_resolution(data, src), negate=_negate(data["negate"], src),
                   occupied_thresh=occupied, free_thresh=free, mode=_mode(data, src))


def _number(data: dict[str, Any], key: str, src: str, low: float = -math.inf,
            high: float = math.inf) -> float:
    """``data[key]`` as a finite float in ``[low, high]`` (a quoted number too, as yaml-cpp)."""
    value = data[key]
    try:
        if isinstance(value, bool):
            raise ValueError
        x = float(value)
    except (TypeError, ValueError):
        raise ScenarioError(src, key, f"must be a number, got {value!r}") from None
    if not (math.isfinite(x) and low <= x <= high):
        span = "a finite number" if math.isinf(low) else f"in [{low:g}, {high:g}]"
        raise ScenarioError(src, key, f"must be {span}, got {value!r}")
    return x


def _resolution(data: dict[str, Any], src: str) -> float:
    """``resolution``, m/cell, finite and > 0."""
    res = _number(data, "resolution", src)
    if not (res > 0 and math.isfinite(1.0 / res)):
        raise ScenarioError(src, "resolution", f"must be > 0 m/cell, got {res:g}")
    return res


def _origin(data: dict[str, Any], src: str) -> tuple[float, float]:
    """``origin`` ``[x, y, yaw]``: 3 finite numbers, yaw 0 (no rotated maps)."""
    value = data["origin"]
    if not isinstance(value, list) or len(value) != 3:
        raise ScenarioError(src, "origin", f"must be a list [x, y, yaw] of 3 numbers, got "
                                           f"{value!r}")
    x, y, yaw = (_number({"origin": v}, "origin", src) for v in value)
    if yaw != 0.0:
        raise ScenarioError(src, "origin", f"yaw {yaw:g} rad: rotated maps are not supported "
                                           "(the toolkit's maps are axis-aligned); use yaw 0")
    return x, y


def _negate(value: Any, src: str) -> bool:
    """``negate``: 0, 1, true or false (quoted too, as yaml-cpp reads it)."""
    if isinstance(value, (int, bool)) and value in (0, 1):
        return bool(value)
    if isinstance(value, str) and value.lower() in ("0", "1", "true", "false"):
        return value.lower() in ("1", "true")
    raise ScenarioError(src, "negate", f"must be 0, 1, true or false, got {value!r}")


def _mode(data: dict[str, Any], src: str) -> str:
    """``mode``: trinary (default), scale or raw, in any case."""
    value = data.get("mode", "trinary")
    if not isinstance(value, str) or value.lower() not in MODES:
        raise ScenarioError(src, "mode", f"unknown mode {value!r}; map_server's modes: "
                                         f"{', '.join(MODES)}")
    return value.lower()


def _image_path(value: Any, yaml_path: Path) -> Path:
    """``image``, relative to the YAML file's folder unless absolute."""
    if not isinstance(value, str) or not value.strip():
        raise ScenarioError(str(yaml_path), "image", f"must be a file name, got {value!r}")
    image = Path(value)
    return image if image.is_absolute() else yaml_path.parent / image


# ---------------------------------------------------------------------- the image
def read_map_image(meta: MapYaml, max_cells: int | None = None) -> NDArray[np.uint8]:
    """The pixels of the map's image, top row first: ``(H, W)`` grey or ``(H, W, C)``.

    ``C`` is 2 (grey, alpha), 3 (RGB) or 4 (RGBA); a palette image becomes RGB(A),
    and an image with a transparent colour (PNG ``tRNS``) RGBA.

    Args:
        meta: The map's YAML (for the image path and error messages).
        max_cells: Largest ``H * W`` accepted; checked from the header, before
            the pixels are decoded.

    Raises:
        ScenarioError: A missing or unreadable image, one that is not 8-bit, or
            one with more pixels than ``max_cells`` (key ``image``).
    """
    from PIL import Image  # Pillow, a dependency of matplotlib; only maps need it

    src, img = str(meta.path), meta.image
    check_image(img, src, "image", max_cells)
    try:
        with warnings.catch_warnings():  # the size is bounded by check_image, not Pillow
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            with Image.open(img) as im:
                im.load()
                return _pixels(im, src, img)
    except (OSError, ValueError, SyntaxError) as exc:
        raise ScenarioError(src, "image", f"cannot read image '{img}': {exc}") from None


def check_image(img: Path, src: str, key: str, max_cells: int | None = None) -> None:
    """An image file exists, is readable, and has at most ``max_cells`` pixels.

    Only the header is read (Pillow), so a huge image is refused before its
    pixels are decoded.

    Args:
        img: The image file.
        src: The file that names it (for messages).
        key: The key that names it (for messages).
        max_cells: Most pixels accepted (None: no bound).

    Raises:
        ScenarioError: The file is missing or unreadable, or has too many pixels.
    """
    from PIL import Image

    if not file_exists(img):
        raise ScenarioError(src, key, f"image file '{img}' not found")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            with Image.open(img) as im:
                w, h = im.size
    except Image.DecompressionBombError as exc:
        raise ScenarioError(src, key, f"'{img}' is larger than this toolkit accepts: "
                                      f"{exc}") from None
    except (OSError, ValueError, SyntaxError) as exc:
        raise ScenarioError(src, key, f"cannot read image '{img}': {exc}") from None
    if max_cells is not None and w * h > max_cells:
        raise ScenarioError(src, key, f"'{img}' is {w} x {h} pixels, more than the "
                                      f"{max_cells:.0e} cells this toolkit accepts")


def _pixels(im: Any, src: str, img: Path) -> NDArray[np.uint8]:
    """A loaded Pillow image as an 8-bit array: L, LA, RGB or RGBA."""
    mode = im.mode
    if mode in ("I", "I;16", "I;16B", "I;16L", "F"):
        depth = "16-bit" if mode.startswith("I") else "floating-point"
        raise ScenarioError(src, "image", f"'{img}' has {depth} pixels (mode {mode}); save "
                                          "the map with 8-bit pixels")
    if "transparency" in im.info or mode in ("PA", "La", "RGBa"):
        im = im.convert("RGBA")
    elif mode in ("1", "P"):
        im = im.convert("L" if mode == "1" else "RGB")
    elif mode not in ("L", "LA", "RGB", "RGBA"):
        raise ScenarioError(src, "image", f"'{img}' has pixel mode {mode}; use a grey, "
                                          "grey+alpha, RGB or RGBA image")
    return np.asarray(im, dtype=np.uint8)


def grey_and_alpha(pixels: NDArray[np.uint8]
                   ) -> tuple[NDArray[np.uint8], NDArray[np.uint8] | None]:
    """The grey level and the alpha channel (None without one) of 8-bit pixels.

    A colour pixel's grey level is its Rec. 601 luma ``(306 R + 601 G + 117 B) / 1024``
    (truncated), the grey conversion of GraphicsMagick, which nav2 uses; a grey
    pixel (R = G = B) keeps its level exactly.

    Args:
        pixels: ``(H, W)`` grey, or ``(H, W, C)`` with C = 1 (grey), 2 (grey,
            alpha), 3 (RGB) or 4 (RGBA).
    """
    p = np.asarray(pixels, dtype=np.uint8)
    if p.ndim == 2:
        return p, None
    if p.ndim != 3 or p.shape[2] not in (1, 2, 3, 4):
        raise ValueError(f"expected (H, W) or (H, W, 1-4) pixels, got shape {p.shape}")
    alpha = p[..., -1] if p.shape[2] in (2, 4) else None
    if p.shape[2] <= 2:
        return p[..., 0], alpha
    rgb = p[..., :3].astype(np.uint32)
    luma = (306 * rgb[..., 0] + 601 * rgb[..., 1] + 117 * rgb[..., 2]) >> 10
    return luma.astype(np.uint8), alpha


def map_server_values(pixels: NDArray[np.uint8], mode: str = "trinary", negate: bool = False,
                      occupied_thresh: float = 0.65, free_thresh: float = 0.25
                      ) -> NDArray[np.int8]:
    """The value map_server publishes for each pixel, in the image's orientation.

    With ``p`` = grey / 255 and ``occ = p`` if ``negate`` else ``1 - p`` (computed
    in float32, as nav2 does):

    - ``trinary``: 100 when ``occ >= occupied_thresh``, 0 when ``occ <= free_thresh``,
      else -1;
    - ``scale``: the same, but between the thresholds (strictly)
      ``round(100 (occ - free_thresh) / (occupied_thresh - free_thresh))``
      (half away from zero), which may round to 0 or 100;
    - ``raw``: the grey level itself when it is 0..100, else -1 (``negate`` and
      alpha do not apply).

    In ``trinary`` and ``scale`` mode, with an alpha channel, every pixel whose
    alpha is below 255 is -1. (nav2 before Jazzy compared the thresholds strictly
    and averaged colour channels; grey, opaque pixels away from a threshold read
    the same there.)

    Args:
        pixels: 8-bit ``(H, W)`` grey or ``(H, W, C)`` grey+alpha/RGB/RGBA
            (:func:`grey_and_alpha`), top row first.
        mode: ``"trinary"``, ``"scale"`` or ``"raw"``.
        negate: White is occupied.
        occupied_thresh: Threshold of occupied, in [0, 1].
        free_thresh: Threshold of free, in [0, 1], below ``occupied_thresh``.

    Returns:
        ``(H, W)`` int8 in {-1, 0..100}.
    """
    grey, alpha = grey_and_alpha(pixels)
    if mode == "raw":
        return np.where(grey <= 100, grey, UNKNOWN).astype(np.int8)
    if mode not in ("trinary", "scale"):
        raise ValueError(f"unknown mode {mode!r}; expected one of {MODES}")
    f32 = np.float32
    occ = grey.astype(f32) / f32(255.0)
    if not negate:
        occ = f32(1.0) - occ
    out = np.full(grey.shape, UNKNOWN, dtype=np.int8)
    out[occ >= f32(occupied_thresh)] = OCCUPIED
    out[occ <= f32(free_thresh)] = FREE
    if mode == "scale":
        between = (occ > f32(free_thresh)) & (occ < f32(occupied_thresh))
        scaled = (occ[between] - f32(free_thresh)) / f32(occupied_thresh - free_thresh) * f32(100)
        whole = np.floor(scaled)
        out[between] = (whole + (scaled - whole >= f32(0.5))).astype(np.int8)
    if alpha is not None:
        out[alpha < 255] = UNKNOWN
    return out


# ----------------------------------------------------------------------- the grid
def occupancy_from_values(values: NDArray[np.int8]) -> NDArray[np.bool_]:
    """The toolkit's occupancy of map_server values: free only where the value is 0."""
    return np.asarray(values) != FREE


def load_map_yaml(path: str | Path, max_cells: int | None = None) -> OccupancyGrid:
    """The occupancy grid of a map_server map (YAML plus image).

    A cell is free only when map_server would publish 0 for it; unknown (-1)
    and 1..100 are occupied. The grid's resolution is ``1 / resolution``
    (cells/m) and its origin the YAML's ``(x, y)``; row 0 is the image's
    bottom row.

    Args:
        path: The map's ``.yaml`` file.
        max_cells: Largest number of cells accepted, checked before decoding.

    Raises:
        ScenarioError: Any problem with the YAML or the image (one line, naming
            the YAML file and the key).
    """
    meta = read_map_yaml(path)
    values = map_server_values(read_map_image(meta, max_cells), meta.mode, meta.negate,
                               meta.occupied_thresh, meta.free_thresh)
    return OccupancyGrid(occupancy_from_values(values)[::-1], 1.0 / meta.resolution, meta.origin)
