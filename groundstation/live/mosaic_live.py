"""The mosaic of the bottom growing live (``live_mosaic = true``, ``floor_depth_m``): the live page's base map made
from the run's own video as the drone flies.

Every ``live_mosaic_every_s`` seconds of video a frame is taken with its camera pose
(:class:`groundstation.live.every_frame.EveryFrame`) and painted with ``skyfix mosaic``'s own painting
(:func:`groundstation.offline.mosaic.paint`, its :class:`~groundstation.offline.mosaic.Accumulator`) onto a grid
in the UTM zone of the first painted frame, centred on it, :data:`HALF_M` m each way (cells made only where a frame
paints). A frame that comes while the painter is still busy with the one before is skipped and counted: the
mosaic takes the CPU the rest of the service leaves. The UUV is not left out (its pixel is the tracker's, per UUV;
the mean over the frames dilutes it).

The painting and the tiles run in a process of their own (:class:`MosaicPainter` in a
:class:`~groundstation.live.side_process.SideProcess`: 10 nice levels below the service and at least at nice 10, as
the painting thread was; ending with the service; the frame handed over through shared memory): they are Python and
NumPy, and a thread of the service at a low priority that ran them held the interpreter's lock while it waited for a
core beside busy programs, the frames' threads waiting with it (``bench/live_latency.py --page open``). The
service's threads only hand work over and wait for it, the lock released. A painting process that ends is started
again with an empty mosaic (one log line).

:meth:`LiveMosaic.tile` renders a web-Mercator tile (EPSG:3857, 256 px) from the blend's cells under it, warped
by rasterio's GDAL (bilinear); ``version`` counts the frames painted, and the page's tiles are fetched anew when it
changes.
"""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np

from groundstation.live.every_frame import EveryFrame
from groundstation.live.side_process import ProcessLost, SideProcess
from groundstation.map.tiles import (
    MAX_ZOOM,
    TILE_PX,
    encode_png,
    pixel_m,
    tile_bounds_m,
    zoom_range,
)
from groundstation.offline.mosaic import (
    N_WATER,
    TILE,
    Accumulator,
    Grid,
    camera_utm,
    footprint_ne_m,
    paint,
    utm_epsg,
)

HALF_M = 500.0  # the grid's extent each way from the first painted frame, m
NO_UUV = (math.nan, math.nan, 0.0)  # the UUV is not left out


class MosaicPainter:
    """The growing mosaic's grid and blend, in the painting process: :meth:`paint_frame` and :meth:`tile`."""

    def __init__(self, cal, floor_depth_m: float, spill: Path):
        self.cal, self.floor_depth_m = cal, floor_depth_m
        self.grid: Grid | None = None
        self.lat_deg = 0.0  # the first painted frame's
        self.acc = Accumulator(spill)

    def paint_frame(self, image: np.ndarray, pose) -> tuple[Grid, float] | None:
        """Paint one frame; the grid and the first painted frame's latitude (deg), None when it painted nothing."""
        cam = self.cal.camera
        if self.grid is None:
            epsg = utm_epsg(pose.lat_deg[0], pose.lon_deg[0])
            xy, _ = camera_utm(pose, epsg)
            gsd_m = float(f"{(pose.height_m[0] + self.floor_depth_m / N_WATER) / cam.fx:.2g}")
            cells = round(2 * HALF_M / gsd_m)
            west = math.floor((xy[0, 0] - HALF_M) / gsd_m) * gsd_m
            north = math.ceil((xy[0, 1] + HALF_M) / gsd_m) * gsd_m
            self.grid = Grid(epsg, west, north, gsd_m, cells, cells)
            self.lat_deg = float(pose.lat_deg[0])
        xy_cam, jac = camera_utm(pose, self.grid.epsg)
        poly = xy_cam[0] + footprint_ne_m(cam, pose, 0, self.floor_depth_m) @ jac[0].T
        if len(poly) < 3:
            return None
        paint(
            image,
            self.grid,
            poly,
            xy_cam[0],
            jac[0],
            cam,
            pose.R_ned_from_cv[0],
            pose.height_m[0],
            self.floor_depth_m,
            NO_UUV,
            self.acc,
        )
        return self.grid, self.lat_deg

    def tile(self, z: int, x: int, y: int) -> bytes | None:
        """Tile ``z/x/y`` as PNG (RGBA, transparent where no frame painted), None where nothing is painted."""
        from affine import Affine
        from rasterio.warp import Resampling, reproject, transform_bounds

        g = self.grid
        if g is None:
            return None
        west, south, east, north = tile_bounds_m(z, x, y)
        w, s, e, n = transform_bounds("EPSG:3857", f"EPSG:{g.epsg}", west, south, east, north)
        step = max(1, int(pixel_m(z, self.lat_deg) / g.gsd_m))  # cells a tile pixel spans
        c0 = max(0, math.floor((w - g.west_m) / g.gsd_m) - step)
        c1 = min(g.width, math.ceil((e - g.west_m) / g.gsd_m) + step)
        r0 = max(0, math.floor((g.north_m - n) / g.gsd_m) - step)
        r1 = min(g.height, math.ceil((g.north_m - s) / g.gsd_m) + step)
        if c1 <= c0 or r1 <= r0:
            return None
        src = self._cells(r0, r1, c0, c1, step)
        if src is None:
            return None
        size = (east - west) / TILE_PX
        out = np.zeros((4, TILE_PX, TILE_PX), np.uint8)
        cell = g.gsd_m * step
        reproject(
            np.ascontiguousarray(src.transpose(2, 0, 1)),
            out,
            src_transform=Affine(
                cell, 0, g.west_m + c0 * g.gsd_m, 0, -cell, g.north_m - r0 * g.gsd_m
            ),
            src_crs=f"EPSG:{g.epsg}",
            dst_transform=Affine(size, 0, west, 0, -size, north),
            dst_crs="EPSG:3857",
            resampling=Resampling.bilinear,
            init_dest_nodata=False,
        )
        out[3] = np.where(out[3] >= 128, 255, 0)
        if not out[3].any():
            return None
        return encode_png(out)

    def _cells(self, r0: int, r1: int, c0: int, c1: int, step: int) -> np.ndarray | None:
        """The blend's RGBA (uint8) at every ``step``-th grid row of r0:r1 and column of c0:c1; None where no
        frame painted."""
        out = np.zeros((-(-(r1 - r0) // step), -(-(c1 - c0) // step), 4), np.uint8)
        any_painted = False
        for tr, tc in self.acc.painted():
            a, b = max(r0, tr * TILE), min(r1, (tr + 1) * TILE)
            c, d = max(c0, tc * TILE), min(c1, (tc + 1) * TILE)
            if b <= a or d <= c:
                continue
            rows = np.arange(-(-(a - r0) // step), -(-(b - r0) // step))
            cols = np.arange(-(-(c - c0) // step), -(-(d - c0) // step))
            if len(rows) == 0 or len(cols) == 0:
                continue
            rgba = self.acc.rgba((tr, tc))
            out[np.ix_(rows, cols)] = rgba[
                np.ix_(r0 + rows * step - tr * TILE, c0 + cols * step - tc * TILE)
            ]
            any_painted = True
        return out if any_painted else None


#: The painting process's one :class:`MosaicPainter` (:func:`start_painter`).
_painter: list[MosaicPainter] = []


def start_painter(cal, floor_depth_m: float, spill: str) -> None:
    """The painting process: its painter, and the imports it needs, now (before the first frame)."""
    _painter[:] = [MosaicPainter(cal, floor_depth_m, Path(spill))]


def paint_now(image: np.ndarray, pose) -> tuple[Grid, float] | None:
    """The painting process: :meth:`MosaicPainter.paint_frame`."""
    return _painter[0].paint_frame(image, pose)


def tile_now(z: int, x: int, y: int) -> bytes | None:
    """The painting process: :meth:`MosaicPainter.tile`."""
    return _painter[0].tile(z, x, y)


class LiveMosaic:
    """The growing mosaic: ``on_frame`` (a frame listener, on the event loop) takes a frame every ``every_s``
    s of video to paint; :meth:`tile` (the page's tile thread) and :meth:`info` serve it as a base map. The
    painting process starts here (its imports before the first frame) and ends with :meth:`close`."""

    def __init__(self, cal, tel, floor_depth_m: float, every_s: float):
        self.cal, self.tel = cal, tel
        self.floor_depth_m, self.every_s = floor_depth_m, every_s
        self.painted = 0  # frames painted
        self.grid: Grid | None = None  # the painting process's, once it painted
        self.lat_deg = 0.0  # the first painted frame's
        self._spill = tempfile.TemporaryDirectory(prefix="skyfix-live-mosaic-")
        self._process = SideProcess(
            "live mosaic", start_painter, cal, floor_depth_m, self._spill.name
        )
        self._painter = EveryFrame(cal, tel, every_s, self._paint_frame, "live mosaic")
        self.on_frame = self._painter.on_frame

    @property
    def version(self) -> int:
        return self.painted

    def _paint_frame(self, image: np.ndarray, pose) -> None:
        """(:class:`EveryFrame`'s thread, at the service's priority) the frame to the painting process, and its
        answer back."""
        done = self._process.call_on(paint_now, image, pose)
        if done is not None:
            self.grid, self.lat_deg = done
            self.painted += 1

    def info(self) -> dict:
        """The base map's ``info()`` (as :mod:`groundstation.map.tiles`' have it), with ``version``."""
        g = self.grid
        if g is None:
            bounds, zooms = [-180.0, -85.0511, 180.0, 85.0511], (0, MAX_ZOOM)
        else:
            from rasterio.warp import transform_bounds

            bounds = [
                round(b, 8) for b in transform_bounds(f"EPSG:{g.epsg}", "EPSG:4326", *g.bounds())
            ]
            zooms = zoom_range(tuple(bounds), g.gsd_m)
        return {
            "name": "live mosaic",
            "format": "png",
            "bounds": bounds,
            "minzoom": zooms[0],
            "maxzoom": zooms[1],
            "sigma_m": None,
            "version": self.version,
        }

    def tile(self, z: int, x: int, y: int) -> bytes | None:
        """Tile ``z/x/y`` as PNG (RGBA, transparent where no frame painted), None where nothing is painted
        (rendered by the painting process, between two frames' painting)."""
        if self.grid is None:
            return None
        try:
            return self._process.call(tile_now, z, x, y)
        except ProcessLost:  # logged; the mosaic starts again
            return None

    def status(self) -> dict:
        return {
            "painted": self.painted,
            "skipped": self._painter.skipped,
            "no_pose": self._painter.no_pose,
            "every_s": self.every_s,
            "floor_depth_m": self.floor_depth_m,
            "gsd_m": None if self.grid is None else self.grid.gsd_m,
        }

    def close(self) -> None:
        self._process.close()
        self._painter.close()
        self._spill.cleanup()
