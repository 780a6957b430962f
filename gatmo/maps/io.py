"""map_server maps: ``map.yaml`` + image (PGM P5/P2, PNG), with ROS 1 map_server semantics.

Per pixel (``map_server/src/image_loader.cpp``): the colour is the channel average; the
occupancy probability is ``p = (255 - colour) / 255`` (``colour / 255`` when ``negate``). Mode
``trinary``: ``p > occupied_thresh`` -> 100, ``p < free_thresh`` -> 0, else -1 (strict
comparisons, so a pixel exactly at a threshold is unknown). ``scale``: in between becomes
``99 * (p - free) / (occ - free)``. ``raw``: the pixel value itself. A fully transparent pixel
is unknown. Image row 0 is the top of the map.
"""

from __future__ import annotations

import io as _stdio
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from gatmo._io import atomic_write_bytes, atomic_write_text
from gatmo.config import read_yaml, yaml_key_lines
from gatmo.errors import FormatError, MapError
from gatmo.maps.grid import FREE, OCCUPIED, UNKNOWN, OccupancyGrid

MODES = ("trinary", "scale", "raw")


@dataclass
class MapMetadata:
    """The fields of a map_server YAML; ``image`` is resolved against the YAML's folder."""

    image: Path
    resolution_m: float
    origin_xytheta: tuple[float, float, float]
    negate: bool = False
    occupied_thresh: float = 0.65
    free_thresh: float = 0.196
    mode: str = "trinary"


def read_map_yaml(yaml_path: str | Path) -> MapMetadata:
    """Parse and check a map YAML; errors name the file, line and key."""
    path = Path(yaml_path)
    data, text = read_yaml(path)
    lines = yaml_key_lines(text)

    def err(msg, key):
        return FormatError(msg, file=path, line=lines.get((key,)), field=key)

    if not isinstance(data, dict):
        raise FormatError("expected a mapping with image, resolution, origin", file=path)
    for key in ("image", "resolution", "origin"):
        if key not in data:
            raise FormatError("missing required key", file=path, field=key)
    known = {"image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh", "mode"}
    for key in data:
        if key not in known:
            raise err("unknown key", key)
    try:
        res = float(data["resolution"])
    except (TypeError, ValueError):
        raise err(f"expected a number, got {data['resolution']!r}", "resolution") from None
    if not np.isfinite(res) or res <= 0:
        raise err(f"must be > 0, got {res}", "resolution")
    origin = data["origin"]
    if not isinstance(origin, list) or len(origin) != 3:
        raise err(f"expected [x, y, yaw], got {origin!r}", "origin")
    try:
        origin_t = tuple(float(v) for v in origin)
    except (TypeError, ValueError):
        raise err(f"expected numbers, got {origin!r}", "origin") from None
    mode = str(data.get("mode", "trinary"))
    if mode not in MODES:
        raise err(f"unknown mode {mode!r}: trinary | scale | raw", "mode")
    vals = {}
    for key, default in (("occupied_thresh", 0.65), ("free_thresh", 0.196)):
        try:
            vals[key] = float(data.get(key, default))
        except (TypeError, ValueError):
            raise err(f"expected a number, got {data[key]!r}", key) from None
        if not 0.0 <= vals[key] <= 1.0:
            raise err(f"must be in [0, 1], got {vals[key]}", key)
    negate = data.get("negate", 0)
    if negate not in (0, 1, True, False):
        raise err(f"expected 0 or 1, got {negate!r}", "negate")
    image = data["image"]
    if not isinstance(image, str) or not image:
        raise err("expected a file name", "image")
    img = Path(image)
    if not img.is_absolute():
        img = path.parent / img
    return MapMetadata(img, res, origin_t, bool(negate), vals["occupied_thresh"],
                       vals["free_thresh"], mode)


def _read_pgm_p2(data: bytes, path: Path) -> np.ndarray:
    tokens = []
    for line in data.decode("ascii", errors="replace").splitlines():
        tokens.extend(line.split("#", 1)[0].split())
    if len(tokens) < 4 or tokens[0] != "P2":
        raise FormatError("not a P2 PGM image", file=path)
    try:
        w, h, maxval = int(tokens[1]), int(tokens[2]), int(tokens[3])
        px = np.array([int(t) for t in tokens[4:]], dtype=np.int64)
    except ValueError:
        raise FormatError("non-numeric value in P2 PGM", file=path) from None
    if px.size != w * h:
        raise FormatError(f"P2 PGM has {px.size} values, expected {w}x{h}", file=path)
    if maxval != 255:
        px = px * 255 // max(maxval, 1)
    return px.reshape(h, w).astype(np.float64)


def _image_size(path: Path, data: bytes) -> tuple[int, int]:
    if data[:2] in (b"P2", b"P5"):
        tokens = []
        for line in data[:4096].split(b"\n"):
            tokens.extend(line.split(b"#", 1)[0].split())
            if len(tokens) >= 3:
                break
        try:
            return int(tokens[1]), int(tokens[2])
        except (IndexError, ValueError):
            raise FormatError("bad PGM header", file=path) from None
    from PIL import Image

    try:
        with Image.open(_stdio.BytesIO(data)) as im:
            return im.size
    except Exception as exc:  # Pillow raises many types on garbage
        raise FormatError(f"cannot read image: {exc}", file=path) from None


def _read_pixels(path: Path, data: bytes) -> tuple[np.ndarray, np.ndarray | None]:
    """(H, W) float colour average and optional alpha (H, W)."""
    if data[:2] == b"P2":
        return _read_pgm_p2(data, path), None
    from PIL import Image

    try:
        with Image.open(_stdio.BytesIO(data)) as im:
            im.load()
            arr = np.asarray(im)
            mode = im.mode
    except Exception as exc:
        raise FormatError(f"cannot decode image: {exc}", file=path) from None
    alpha = None
    if arr.ndim == 3:
        if mode in ("RGBA", "LA"):
            alpha = arr[..., -1]
            arr = arr[..., :-1]
        arr = arr.astype(np.float64).mean(axis=2)
    elif mode in ("I;16", "I"):
        arr = arr.astype(np.float64) * 255.0 / max(float(arr.max()), 1.0)
    return arr.astype(np.float64), alpha


def load_map(yaml_path: str | Path, *, max_cells: int = 200_000_000) -> OccupancyGrid:
    """Load a map_server map as an :class:`OccupancyGrid` (cells[iy, ix], iy grows with y)."""
    meta = read_map_yaml(yaml_path)
    try:
        data = meta.image.read_bytes()
    except OSError as exc:
        raise FormatError(f"cannot read image {meta.image}: {exc.strerror}", file=yaml_path,
                          field="image") from None
    w, h = _image_size(meta.image, data)
    if w * h > max_cells:
        raise MapError(f"image is {w}x{h} = {w * h} cells, above the limit of {max_cells}",
                       file=meta.image)
    colour, alpha = _read_pixels(meta.image, data)
    return grid_from_pixels(colour, meta, alpha)


def grid_from_pixels(colour: np.ndarray, meta: MapMetadata, alpha=None) -> OccupancyGrid:
    """Apply map_server's thresholds to an image (row 0 = top)."""
    if meta.mode == "raw":
        cells = np.clip(colour, -128, 127).astype(np.int8)
    else:
        p = colour / 255.0 if meta.negate else (255.0 - colour) / 255.0
        cells = np.full(colour.shape, UNKNOWN, dtype=np.int8)
        cells[p > meta.occupied_thresh] = OCCUPIED
        cells[p < meta.free_thresh] = FREE
        if meta.mode == "scale":
            mid = (p <= meta.occupied_thresh) & (p >= meta.free_thresh)
            ratio = (p - meta.free_thresh) / max(meta.occupied_thresh - meta.free_thresh, 1e-12)
            cells[mid] = (99.0 * ratio[mid]).astype(np.int8)
        if alpha is not None:
            cells[alpha == 0] = UNKNOWN
    return OccupancyGrid(np.flipud(cells).copy(), meta.resolution_m, meta.origin_xytheta)


def load_image_map(image_path: str | Path, resolution_m: float,
                   origin_xytheta=(0.0, 0.0, 0.0)) -> OccupancyGrid:
    """A bare image with map_server's default thresholds (e.g. the radish PNGs)."""
    path = Path(image_path)
    meta = MapMetadata(path, float(resolution_m), tuple(origin_xytheta))
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise FormatError(f"cannot read: {exc.strerror}", file=path) from None
    colour, alpha = _read_pixels(path, data)
    return grid_from_pixels(colour, meta, alpha)


def save_map(grid: OccupancyGrid, yaml_path: str | Path, *, image_format: str = "pgm") -> Path:
    """Write ``yaml_path`` and its image (map_saver's trinary convention: occupied 0, free 254,
    unknown 205, thresholds 0.65 / 0.196) so that ``load_map`` gives ``grid`` back exactly.
    Scale values 1..99 are written as grey levels that map_server's ``scale`` mode reads back."""
    from PIL import Image

    yaml_path = Path(yaml_path)
    if image_format not in ("pgm", "png"):
        raise FormatError(f"unknown image format {image_format!r}: pgm | png", field="image")
    img_path = yaml_path.with_suffix("." + image_format)
    cells = np.flipud(grid.cells)
    img = np.full(cells.shape, 205, dtype=np.uint8)
    img[cells == FREE] = 254
    img[cells == OCCUPIED] = 0
    buf = _stdio.BytesIO()
    Image.fromarray(img, mode="L").save(buf, format="PPM" if image_format == "pgm" else "PNG")
    atomic_write_bytes(img_path, buf.getvalue())
    doc = {
        "image": img_path.name,
        "resolution": grid.resolution_m,
        "origin": [float(v) for v in grid.origin_xytheta],
        "negate": 0,
        "occupied_thresh": 0.65,
        "free_thresh": 0.196,
        "mode": "trinary",
    }
    atomic_write_text(yaml_path, yaml.safe_dump(doc, sort_keys=False))
    return yaml_path
