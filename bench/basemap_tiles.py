"""What a base map's tile costs the live service: CPU time to warp one web-map tile out of a GeoTIFF and encode it.

    .venv/bin/python bench/basemap_tiles.py [--geotiff FILE] [--tiles 24] [--out bench/results/basemap_tiles.txt]

``skyfix run --basemap FILE.tif`` renders each tile the page asks for (:class:`groundstation.map.tiles.GeoTiffTiles`:
rasterio's GDAL warps the image into the tile, bilinear, then PNG), in one thread at a lower priority, and keeps
the last 512. Per zoom level, from the one where the image fits in a tile to its native one, up to ``--tiles`` tiles
around the image's centre are rendered once each, cold (every tile once, as a page that pans sees them); printed:
the median and the largest CPU time of a tile (the rendering thread's own, ``time.thread_time``), the median PNG
size, and the tiles with image. Without ``--geotiff`` a textured RGB-and-alpha Cloud-Optimised GeoTIFF in UTM
(8000 x 8000 cells of 0.02 m, 160 m square, as ``skyfix mosaic`` writes them) is made once in
``/tmp/skyfix-basemap-bench``. The page's viewport (about 530 x 400 px) shows 6 to 12 tiles at a time.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

import numpy as np

from groundstation.map.tiles import GeoTiffTiles, tile_of, tiles_in

SIZE = 8000
GSD_M = 0.02
CENTRE = (63.44, 10.40)


def synthetic(path: Path) -> Path:
    """A textured RGBA COG around :data:`CENTRE` (UTM zone 32), made once."""
    if path.exists():
        return path
    from affine import Affine
    from rasterio.io import MemoryFile
    from rasterio.shutil import copy as copy_raster

    path.parent.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(1)
    small = rng.integers(60, 200, (3, SIZE // 16, SIZE // 16), dtype=np.uint8)
    bands = [np.kron(b, np.ones((16, 16), np.uint8)) for b in small]  # blocks of 16 cells
    alpha = np.full((SIZE, SIZE), 255, np.uint8)
    alpha[:, : SIZE // 8] = 0  # a strip without image, as a mosaic's edges
    profile = {
        "driver": "GTiff",
        "width": SIZE,
        "height": SIZE,
        "count": 4,
        "dtype": "uint8",
        "crs": "EPSG:32632",
        "transform": Affine(GSD_M, 0, 570000.0, 0, -GSD_M, 7035000.0),
        "photometric": "RGB",
        "alpha": "YES",
    }
    with MemoryFile() as mem, mem.open(**profile) as dst:
        for i, b in enumerate([*bands, alpha]):
            dst.write(b, i + 1)
        copy_raster(dst, str(path), driver="COG", compress="DEFLATE")
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--geotiff", type=Path, default=None)
    parser.add_argument("--tiles", type=int, default=24, help="tiles per zoom level at the most")
    parser.add_argument("--out", type=Path, default=Path("bench/results/basemap_tiles.txt"))
    args = parser.parse_args()
    path = args.geotiff or synthetic(Path("/tmp/skyfix-basemap-bench/site.tif"))
    source = GeoTiffTiles(path)
    w, s, e, n = source.bounds
    head = (
        f"basemap_tiles: {path.name}, {source.ds.width}x{source.ds.height} px of {source.gsd_m:.3f} m, "
        f"zoom {source.minzoom}-{source.maxzoom}, overviews {source.ds.overviews(1)}; "
        f"{time.strftime('%Y-%m-%d %H:%M:%S')}, load average {os.getloadavg()[0]:.1f}"
    )
    lines = [
        head,
        "zoom  tiles  with image  cpu median ms  cpu max ms  png median kB",
    ]
    for z in range(source.minzoom, source.maxzoom + 1):
        cx, cy = tile_of((s + n) / 2, (w + e) / 2, z)
        near = sorted(tiles_in(source.bounds, z), key=lambda t: (t[0] - cx) ** 2 + (t[1] - cy) ** 2)
        cpu_ms, sizes = [], []
        for x, y in near[: args.tiles]:
            t0 = time.thread_time()
            png = source.tile(z, x, y)
            cpu_ms.append((time.thread_time() - t0) * 1000.0)
            if png is not None:
                sizes.append(len(png) / 1000.0)
        lines.append(
            f"{z:>4}  {len(cpu_ms):>5}  {len(sizes):>10}  {statistics.median(cpu_ms):>13.1f}  "
            f"{max(cpu_ms):>10.1f}  {statistics.median(sizes) if sizes else 0:>13.1f}"
        )
    text = "\n".join(lines) + "\n"
    print(text, end="")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)


if __name__ == "__main__":
    main()
