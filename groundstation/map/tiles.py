"""Map tiles of a site: web-Mercator XYZ tiles (EPSG:3857, 256 px, ``z/x/y`` with ``y`` counted from the north) read
from a GeoTIFF, an MBTiles file or a folder of tiles, and written as a folder or an MBTiles file.

- :func:`open_basemap`: a base map for the live page (``skyfix run --basemap``): a GeoTIFF (the mosaic of an earlier
  flight, ``skyfix mosaic``, or an orthophoto the team brings; any CRS, 8-bit grey or RGB, with an alpha band,
  a nodata value or neither) rendered tile by tile when asked (:class:`GeoTiffTiles`: each tile warped by
  rasterio's GDAL, bilinear, from the coarsest of the image's overviews that is fine enough); an MBTiles file
  (:class:`MbTiles`, SQLite: its ``metadata`` and ``tiles``, rows in TMS order as the MBTiles 1.3 specification
  has them); or a folder ``Z/X/Y.png`` (or ``.jpg``, ``.webp``:
  :class:`TileFolder`; XYZ order, as ``gdal2tiles.py --xyz`` writes). Each says its ``info()``: its name, the
  tiles' format, its bounds (degrees west, south, east, north), zoom levels and ``sigma_m``: the horizontal
  1-sigma of the image's placement that ``skyfix mosaic``'s sidecar states (``mosaic.json`` beside
  ``mosaic.tif``; None for other base maps), and gives ``tile(z, x, y)``: the tile's bytes, or None where it has
  none.
- ``skyfix tiles GEOTIFF --out DIR [--mbtiles FILE]``: a GeoTIFF written as tiles, zoom :func:`zoom_range`
  (from the one where the image fits in a tile to its native resolution), only tiles with a pixel of the image.

The ground size of a tile's pixel at zoom ``z`` and latitude ``lat`` is ``2 pi a cos(lat) / (256 2^z)`` (``a``:
WGS84's equatorial radius, :data:`EARTH_RADIUS_M`).
"""

from __future__ import annotations

import json
import math
import sqlite3
import sys
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

EARTH_RADIUS_M = 6378137.0  # WGS84 a, the web-Mercator sphere
HALF_WORLD_M = math.pi * EARTH_RADIUS_M
TILE_PX = 256
MAX_ZOOM = 26  # finer than any site needs (0.6 mm a pixel at the equator)
FORMATS = {"png": "image/png", "jpg": "image/jpeg", "jpeg": "image/jpeg", "webp": "image/webp"}


class BaseMapError(ValueError):
    """A base map that cannot be read; one line naming the file and why."""


def tile_bounds_m(z: int, x: int, y: int) -> tuple[float, float, float, float]:
    """Tile ``z/x/y``'s edges in web-Mercator metres (EPSG:3857): west, south, east, north."""
    size = 2.0 * HALF_WORLD_M / 2**z
    west, north = -HALF_WORLD_M + x * size, HALF_WORLD_M - y * size
    return west, north - size, west + size, north


def tile_of(lat_deg: float, lon_deg: float, z: int) -> tuple[int, int]:
    """``(x, y)`` of the zoom-``z`` tile holding a point."""
    n = 2**z
    x = (lon_deg + 180.0) / 360.0 * n
    lat = math.radians(lat_deg)
    y = (1.0 - math.asinh(math.tan(lat)) / math.pi) / 2.0 * n
    return min(max(int(x), 0), n - 1), min(max(int(y), 0), n - 1)


def pixel_m(z: float, lat_deg: float) -> float:
    """Ground size (m) of a zoom-``z`` tile pixel at latitude ``lat_deg``."""
    return 2.0 * HALF_WORLD_M * math.cos(math.radians(lat_deg)) / (TILE_PX * 2**z)


def zoom_range(bounds: tuple[float, float, float, float], gsd_m: float) -> tuple[int, int]:
    """``(min, max)`` zoom of an image of ``bounds`` (degrees w, s, e, n) and ground pixel ``gsd_m``: from the zoom
    where it fits in one tile to the first whose pixels are no larger than its own."""
    w, s, e, n = bounds
    lat = (s + n) / 2.0
    extent_m = max(
        (e - w) / 360.0 * 2 * HALF_WORLD_M * math.cos(math.radians(lat)),
        math.radians(n - s) * EARTH_RADIUS_M,
    )
    top = min(MAX_ZOOM, max(0, math.ceil(math.log2(pixel_m(0, lat) / gsd_m))))
    low = min(top, max(0, math.floor(math.log2(pixel_m(0, lat) * TILE_PX / max(extent_m, 1e-3)))))
    return low, top


def tiles_in(bounds: tuple[float, float, float, float], z: int):
    """Every zoom-``z`` tile ``(x, y)`` that meets ``bounds`` (degrees w, s, e, n)."""
    w, s, e, n = bounds
    x0, y0 = tile_of(n, w, z)
    x1, y1 = tile_of(s, e, z)
    for x in range(x0, x1 + 1):
        for y in range(y0, y1 + 1):
            yield x, y


def encode_png(rgba: np.ndarray) -> bytes:
    """An RGBA tile (4 x H x W, uint8) as PNG."""
    bgra = np.ascontiguousarray(rgba[[2, 1, 0, 3]].transpose(1, 2, 0))
    ok, buf = cv2.imencode(".png", bgra)
    if not ok:
        raise ValueError("cv2.imencode could not encode a tile")
    return buf.tobytes()


class GeoTiffTiles:
    """Tiles of a GeoTIFF (or any raster GDAL reads), rendered on request: 8-bit grey or RGB, with an alpha band
    (the mosaic's), a nodata value or neither. Not thread-safe: one caller at a time (the page serves tiles from
    one thread)."""

    def __init__(self, path: Path):
        import rasterio
        from rasterio.enums import ColorInterp
        from rasterio.errors import RasterioError
        from rasterio.warp import transform_bounds

        self.path = path
        try:
            self.ds = rasterio.open(path)
        except RasterioError as e:
            raise BaseMapError(f"{path}: not an image GDAL reads ({e})") from None
        ds = self.ds
        if ds.crs is None:
            raise BaseMapError(f"{path}: no CRS (georeference it, e.g. gdal_translate -a_srs)")
        if set(ds.dtypes) != {"uint8"}:
            raise BaseMapError(
                f"{path}: bands of type {', '.join(sorted(set(ds.dtypes)))}; base maps are 8-bit "
                "(gdal_translate -ot Byte -scale)"
            )
        alpha = [i + 1 for i, c in enumerate(ds.colorinterp) if c == ColorInterp.alpha]
        self.alpha = alpha[0] if alpha else 0
        colour = [b for b in range(1, ds.count + 1) if b != self.alpha]
        if len(colour) not in (1, 3):
            raise BaseMapError(f"{path}: {ds.count} bands; base maps are grey or RGB (and alpha)")
        self.bands = colour + ([self.alpha] if self.alpha else [])
        self.grey = len(colour) == 1
        self.bounds = tuple(transform_bounds(ds.crs, "EPSG:4326", *ds.bounds))
        lat = (self.bounds[1] + self.bounds[3]) / 2.0
        if (
            ds.crs.is_projected and ds.crs.to_epsg() != 3857
        ):  # metres (or feet) on the ground: UTM, a national grid
            self.gsd_m = ds.res[0] * ds.crs.linear_units_factor[1]
        else:  # degrees, or web Mercator's metres: its width on the ground over its pixels
            ground = transform_bounds(ds.crs, "EPSG:3857", *ds.bounds)
            self.gsd_m = (ground[2] - ground[0]) * math.cos(math.radians(lat)) / ds.width
        self.minzoom, self.maxzoom = zoom_range(self.bounds, self.gsd_m)
        self.lat_deg = lat
        self._overviews = {}  # overview level -> its dataset, opened once

    def info(self) -> dict:
        return {
            "name": self.path.name,
            "format": "png",
            "bounds": [round(b, 8) for b in self.bounds],
            "minzoom": self.minzoom,
            "maxzoom": self.maxzoom,
            "sigma_m": sidecar_sigma_m(self.path),
        }

    def render(self, z: int, x: int, y: int) -> np.ndarray | None:
        """Tile ``z/x/y`` as RGBA (4 x 256 x 256, uint8), None where the image has no pixel in it."""
        import rasterio
        from affine import Affine
        from rasterio.warp import Resampling, reproject

        west, _, east, north = tile_bounds_m(z, x, y)
        size = (east - west) / TILE_PX
        n = len(self.bands) - (1 if self.alpha else 0)
        out = np.zeros((n + 1, TILE_PX, TILE_PX), np.uint8)
        reproject(
            rasterio.band(self._level(z), self.bands),
            out,
            dst_transform=Affine(size, 0.0, west, 0.0, -size, north),  # a tile pixel's size, m
            dst_crs="EPSG:3857",
            src_alpha=self.alpha,
            dst_alpha=n + 1,
            resampling=Resampling.bilinear,
        )
        if not out[-1].any():
            return None
        return out[[0, 0, 0, 1]] if self.grey else out

    def _level(self, z: int):
        """The dataset a zoom-``z`` tile is warped from: the coarsest of the image's overviews (a COG's, the
        mosaic's) whose cells are no larger than the tile's pixels, else the image (GDAL's warper would read it
        whole for a tile of a low zoom)."""
        import rasterio

        factors = self.ds.overviews(1)
        coarser = pixel_m(z, self.lat_deg) / self.gsd_m
        level = max((i for i, f in enumerate(factors) if f <= coarser), default=None)
        if level is None:
            return self.ds
        if level not in self._overviews:
            self._overviews[level] = rasterio.open(self.path, overview_level=level)
        return self._overviews[level]

    def tile(self, z: int, x: int, y: int) -> bytes | None:
        rgba = self.render(z, x, y)
        return None if rgba is None else encode_png(rgba)

    def close(self) -> None:
        for ds in (self.ds, *self._overviews.values()):
            ds.close()


class MbTiles:
    """Tiles of an MBTiles file (read only; its ``tiles`` rows are in TMS order: row 0 is the south)."""

    def __init__(self, path: Path):
        self.path = path
        try:
            self.db = sqlite3.connect(f"file:{path}?mode=ro", uri=True, check_same_thread=False)
            meta = dict(self.db.execute("SELECT name, value FROM metadata"))
            zooms = self.db.execute("SELECT min(zoom_level), max(zoom_level) FROM tiles").fetchone()
        except sqlite3.Error as e:
            raise BaseMapError(f"{path}: not an MBTiles file ({e})") from None
        if zooms[0] is None:
            raise BaseMapError(f"{path}: no tiles in it")
        self.format = meta.get("format", "png")
        if self.format not in FORMATS:
            raise BaseMapError(
                f"{path}: format = {self.format!r}: not an image format the page shows"
            )
        try:
            bounds = [float(v) for v in meta["bounds"].split(",")]
        except (KeyError, ValueError):
            bounds = [-180.0, -85.0511, 180.0, 85.0511]  # the specification's default: the world
        self.meta = {
            "name": meta.get("name", path.stem),
            "format": self.format,
            "bounds": bounds,
            "minzoom": int(meta.get("minzoom", zooms[0])),
            "maxzoom": int(meta.get("maxzoom", zooms[1])),
            # as write_tiles wrote it: skyfix mosaic's sidecar's (None for others)
            "sigma_m": _finite_or_none(meta.get("sigma_m")),
        }

    def info(self) -> dict:
        return self.meta

    def tile(self, z: int, x: int, y: int) -> bytes | None:
        row = self.db.execute(
            "SELECT tile_data FROM tiles WHERE zoom_level=? AND tile_column=? AND tile_row=?",
            (z, x, 2**z - 1 - y),
        ).fetchone()
        return None if row is None else bytes(row[0])

    def close(self) -> None:
        self.db.close()


class TileFolder:
    """Tiles of a folder ``Z/X/Y.<format>`` (XYZ order); its bounds are those of its tiles at its finest zoom."""

    def __init__(self, path: Path):
        self.path = path
        zooms = sorted(int(p.name) for p in path.iterdir() if p.is_dir() and p.name.isdigit())
        if not zooms:
            raise BaseMapError(
                f"{path}: no Z/X/Y tiles in this folder (zoom folders 0..{MAX_ZOOM})"
            )
        top = zooms[-1]
        tiles = [p for p in (path / str(top)).glob("*/*.*") if p.stem.isdigit()]
        formats = {p.suffix[1:].lower() for p in tiles}
        if len(formats) != 1 or not formats <= FORMATS.keys():
            raise BaseMapError(
                f"{path}: tiles of format {', '.join(sorted(formats)) or 'none'} at zoom {top}; "
                f"expected one of {', '.join(FORMATS)}"
            )
        self.format = formats.pop()
        xs = [int(p.parent.name) for p in tiles]
        ys = [int(p.stem) for p in tiles]
        w, _, _, n = _tile_degrees(top, min(xs), min(ys))
        _, s, e, _ = _tile_degrees(top, max(xs), max(ys))
        self.meta = {
            "name": path.name,
            "format": self.format,
            "bounds": [round(v, 8) for v in (w, s, e, n)],
            "minzoom": zooms[0],
            "maxzoom": top,
            "sigma_m": None,
        }

    def info(self) -> dict:
        return self.meta

    def tile(self, z: int, x: int, y: int) -> bytes | None:
        p = self.path / str(z) / str(x) / f"{y}.{self.format}"
        return p.read_bytes() if p.is_file() else None

    def close(self) -> None:
        pass


def _finite_or_none(text: str | None) -> float | None:
    """A metadata value as a finite number, else None."""
    try:
        value = float(text)
    except (TypeError, ValueError):
        return None
    return value if math.isfinite(value) else None


def sidecar_sigma_m(path: Path) -> float | None:
    """The horizontal 1-sigma (m) of an image's placement as ``skyfix mosaic``'s sidecar states it (its name with
    ``.json``: ``mosaic.json`` beside ``mosaic.tif``, ``horizontal_sigma_m``); None without one."""
    try:
        value = json.loads(path.with_suffix(".json").read_text()).get("horizontal_sigma_m")
    except (OSError, ValueError, AttributeError):
        return None
    return float(value) if isinstance(value, int | float) and math.isfinite(value) else None


def _tile_degrees(z: int, x: int, y: int) -> tuple[float, float, float, float]:
    """Tile ``z/x/y``'s edges in degrees: west, south, east, north."""
    w, s, e, n = tile_bounds_m(z, x, y)
    lon = lambda m: m / HALF_WORLD_M * 180.0
    lat = lambda m: math.degrees(math.atan(math.sinh(m / EARTH_RADIUS_M)))
    return lon(w), lat(s), lon(e), lat(n)


def open_basemap(path: Path) -> GeoTiffTiles | MbTiles | TileFolder:
    """The base map at ``path``: a folder of tiles, an ``.mbtiles`` file, or an image GDAL reads (a GeoTIFF)."""
    path = Path(path)
    if path.is_dir():
        return TileFolder(path)
    if not path.is_file():
        raise BaseMapError(f"{path}: no such file or folder")
    if path.suffix.lower() == ".mbtiles":
        return MbTiles(path)
    return GeoTiffTiles(path)


@dataclass
class Written:
    """What :func:`write_tiles` wrote: the tiles per zoom and the zoom range."""

    tiles: dict[int, int]
    minzoom: int
    maxzoom: int


def write_tiles(
    source: GeoTiffTiles,
    folder: Path | None,
    mbtiles: Path | None,
    zooms: tuple[int, int] | None = None,
) -> Written:
    """``source``'s tiles (zooms ``zooms``, default its own range) into a ``Z/X/Y.png`` folder and/or an MBTiles
    file (a new one; MBTiles 1.3: ``metadata`` and ``tiles``); tiles without an image pixel are left out."""
    low, top = zooms or (source.minzoom, source.maxzoom)
    db = None
    if mbtiles is not None:
        mbtiles.unlink(missing_ok=True)
        db = sqlite3.connect(mbtiles)
        db.execute("CREATE TABLE metadata (name text, value text)")
        db.execute(
            "CREATE TABLE tiles (zoom_level integer, tile_column integer, tile_row integer, "
            "tile_data blob)"
        )
        db.execute("CREATE UNIQUE INDEX tile_index ON tiles (zoom_level, tile_column, tile_row)")
        meta = {**source.info(), "minzoom": low, "maxzoom": top, "type": "overlay"}
        meta["bounds"] = ",".join(str(b) for b in meta["bounds"])
        w, s, e, n = source.bounds
        meta["center"] = f"{(w + e) / 2},{(s + n) / 2},{top}"
        db.executemany("INSERT INTO metadata VALUES (?, ?)", [(k, str(v)) for k, v in meta.items()])
    counts = {}
    for z in range(low, top + 1):
        counts[z] = 0
        for x, y in tiles_in(source.bounds, z):
            png = source.tile(z, x, y)
            if png is None:
                continue
            counts[z] += 1
            if folder is not None:
                (folder / str(z) / str(x)).mkdir(parents=True, exist_ok=True)
                (folder / str(z) / str(x) / f"{y}.png").write_bytes(png)
            if db is not None:
                db.execute("INSERT INTO tiles VALUES (?, ?, ?, ?)", (z, x, 2**z - 1 - y, png))
    if db is not None:
        db.commit()
        db.close()
    return Written(counts, low, top)


def _zooms(text: str) -> tuple[int, int]:
    low, _, top = text.partition("-")
    a, b = int(low), int(top or low)
    if not 0 <= a <= b <= MAX_ZOOM:
        raise ValueError
    return a, b


def run(args) -> int:
    from groundstation.outputs import output_dir

    if args.out is None and args.mbtiles is None:
        print("skyfix tiles: give --out DIR, --mbtiles FILE or both", file=sys.stderr)
        return 2
    try:
        source = open_basemap(args.geotiff)
        if not isinstance(source, GeoTiffTiles):
            raise BaseMapError(f"{args.geotiff}: not a GeoTIFF (tiles are made from an image)")
    except BaseMapError as e:
        print(f"skyfix tiles: {e}", file=sys.stderr)
        return 2
    folder = output_dir(args.out) if args.out else None
    done = write_tiles(source, folder, Path(args.mbtiles) if args.mbtiles else None, args.zoom)
    source.close()
    where = " and ".join(str(p) for p in (folder, args.mbtiles) if p)
    print(
        f"{sum(done.tiles.values())} tiles, zoom {done.minzoom}-{done.maxzoom} "
        f"(image pixel {source.gsd_m:.3f} m, tile pixel {pixel_m(done.maxzoom, (source.bounds[1] + source.bounds[3]) / 2):.3f} m "
        f"at zoom {done.maxzoom}) -> {where}"
    )
    return 0


def register(subparsers, name: str, help: str | None = None) -> None:
    """Adds the subcommand ``name`` with its one-line ``help`` (both from :data:`groundstation.cli.COMMANDS`)."""
    p = subparsers.add_parser(name, help=help)
    p.add_argument(
        "geotiff",
        type=Path,
        help="the image: skyfix mosaic's mosaic.tif or an orthophoto (GeoTIFF)",
    )
    p.add_argument("--out", default=None, help="folder for the tiles, Z/X/Y.png (XYZ order)")
    p.add_argument(
        "--mbtiles", default=None, help="an MBTiles file to write (replaced if it exists)"
    )
    p.add_argument(
        "--zoom",
        type=_zooms,
        default=None,
        metavar="MIN-MAX",
        help="zoom levels (default: from the one where the image fits in a tile to its own resolution)",
    )
    p.set_defaults(func=run)
