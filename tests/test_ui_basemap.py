"""The live page's map over a base map of the site, served by skyfix with nothing from the internet.

- ``skyfix tiles``: a GeoTIFF in UTM (RGB and alpha, as ``skyfix mosaic`` writes) with a green disc at a known
  latitude and longitude becomes XYZ tiles and an MBTiles file; in the tile holding the disc, the disc's centre is
  at the pixel pyproj's web Mercator (EPSG:3857) says, within a pixel; the folder and the MBTiles hold the same
  tiles (the MBTiles rows in TMS order); GDAL opens the MBTiles. Bad base maps are one-line errors naming the file.
- In Chromium (``skyfix run --basemap`` of an RGB GeoTIFF, the replay of nadir_hover tracking from its first box):
  the screenshot shows the base map's disc (3 m east and 1.5 m south of the UUV's true position halfway through)
  at the pixel pyproj's web Mercator gives for the page's view (centre, zoom) within 2 px and at its scale; the
  UUV's track, drawn over the tiles, lies on its true path; every request the page made was to 127.0.0.1 (the page, Leaflet, the
  tiles).
"""

from __future__ import annotations

import math
import sqlite3
import subprocess

import cv2
import numpy as np
import pytest
from live_helpers import ROOT, LiveRun, free_port, skyfix, ui_url, wait_for
from pyproj import Geod
from test_ui_access import _get, service  # noqa: F401 (the fixture: skyfix run without inputs)
from ui_browser import available, chromium

from groundstation.map.tiles import BaseMapError, GeoTiffTiles, open_basemap, tiles_in, write_tiles

SESSION = ROOT / "sim_fixtures" / "bundled" / "nadir_hover"
A_M = 6378137.0  # web Mercator's sphere
GREEN = (0, 255, 0)
SAND = (200, 190, 150)


def _mercator_m(lat: float, lon: float) -> tuple[float, float]:
    from pyproj import Transformer

    return Transformer.from_crs("EPSG:4326", "EPSG:3857", always_xy=True).transform(lon, lat)


def _geotiff(path, lat, lon, half_m, gsd_m, radius_m, alpha, mark=None):
    """A north-up GeoTIFF in the point's UTM zone, ``2 half_m`` wide around (lat, lon), sand-coloured with a green
    disc of ``radius_m`` centred on ``mark`` (lat, lon; default the centre); with ``alpha``, an alpha band (the
    disc's half of the image opaque)."""
    import rasterio
    from affine import Affine
    from pyproj import CRS, Transformer

    zone = int((lon + 180) // 6) + 1
    epsg = 32600 + zone
    to_utm = Transformer.from_crs(CRS(4326), CRS(epsg), always_xy=True)
    ec, nc = to_utm.transform(lon, lat)
    e0, n0 = to_utm.transform(mark[1], mark[0]) if mark else (ec, nc)
    size = round(2 * half_m / gsd_m)
    west, north = ec - half_m, nc + half_m
    cols = west + (np.arange(size) + 0.5) * gsd_m
    rows = north - (np.arange(size) + 0.5) * gsd_m
    disc = (cols[None, :] - e0) ** 2 + (rows[:, None] - n0) ** 2 <= radius_m**2
    bands = [np.where(disc, g, s).astype(np.uint8) for g, s in zip(GREEN, SAND, strict=True)]
    if alpha:
        bands.append(
            np.where(rows[:, None] >= n0 - 3 * radius_m, 255, 0).astype(np.uint8).repeat(size, 1)
        )
    profile = {
        "driver": "GTiff",
        "width": size,
        "height": size,
        "count": len(bands),
        "dtype": "uint8",
        "crs": CRS(epsg).to_wkt(),
        "transform": Affine(gsd_m, 0, west, 0, -gsd_m, north),
        "photometric": "RGB",
        **({"alpha": "YES"} if alpha else {}),
    }
    with rasterio.open(path, "w", **profile) as dst:
        for i, b in enumerate(bands):
            dst.write(b, i + 1)
    return path


def _green(rgb: np.ndarray) -> np.ndarray:
    r, g, b = (rgb[..., i].astype(int) for i in range(3))
    return (g > 170) & (r < 90) & (b < 120)


def _tile_xy(lat: float, lon: float, z: int) -> tuple[float, float]:
    """The zoom-``z`` tile coordinates of a point (fractional), by pyproj's web Mercator."""
    x_m, y_m = _mercator_m(lat, lon)
    tile_m = 2 * math.pi * A_M / 2**z
    return (x_m + math.pi * A_M) / tile_m, (math.pi * A_M - y_m) / tile_m


def _disc_where_mercator_says(png: bytes, tx: float, ty: float, radius_px: float) -> None:
    """The green disc in the tile (PNG) at the tile position (``tx``, ``ty``) within a pixel, at its radius; the
    tile transparent south of it (the image's alpha 0 there)."""
    rgba = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_UNCHANGED)[..., [2, 1, 0, 3]]
    ys, xs = np.nonzero(_green(rgba) & (rgba[..., 3] == 255))
    want = ((tx % 1) * 256 - 0.5, (ty % 1) * 256 - 0.5)  # pixel centres
    assert len(xs) > 20
    # the disc may run over the tile's edge: its centre from its extent on the sides inside the tile
    got = ((xs.min() + xs.max()) / 2, (ys.min() + ys.max()) / 2)
    inside = [
        c for c, lo, hi in ((0, xs.min(), xs.max()), (1, ys.min(), ys.max())) if lo > 0 and hi < 255
    ]
    assert inside, "the disc fills its tile's width and height"
    for c in inside:
        assert abs(got[c] - want[c]) <= 1.0, (got, want)
    assert abs((xs.max() - xs.min() + 1) / 2 - radius_px) <= 1.5 if 0 in inside else True
    south = int(want[1] + 4 * radius_px)
    assert south >= 256 or not rgba[south:, :, 3].any()


def test_a_geotiff_becomes_tiles_with_its_mark_where_web_mercator_says(tmp_path):
    lat, lon = 63.44, 10.40
    tif = _geotiff(tmp_path / "site.tif", lat, lon, 12.0, 0.03, 0.5, alpha=True)
    out = subprocess.run(
        skyfix("tiles", str(tif), "--out", str(tmp_path / "xyz"), "--mbtiles", str(tmp_path / "site.mbtiles")),
        check=False, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    print(out.stdout.strip())
    folder, mb = open_basemap(tmp_path / "xyz"), open_basemap(tmp_path / "site.mbtiles")
    assert folder.info()["maxzoom"] == mb.info()["maxzoom"]
    z = mb.info()["maxzoom"]
    # a tile pixel no larger than the image's, one zoom less larger
    pixel = lambda zoom: 2 * math.pi * A_M * math.cos(math.radians(lat)) / (256 * 2**zoom)
    assert pixel(z) <= 0.03 < pixel(z - 1)
    w, s, e, n = mb.info()["bounds"]
    assert w < lon < e and s < lat < n and (e - w) * 111e3 * math.cos(math.radians(lat)) < 25
    # the disc in its tile, at pyproj's web Mercator
    tx, ty = _tile_xy(lat, lon, z)
    png = mb.tile(z, int(tx), int(ty))
    assert png == folder.tile(z, int(tx), int(ty)) and png is not None
    _disc_where_mercator_says(png, tx, ty, 0.5 / pixel(z))
    # a tile of a coarser zoom, from the image's overviews (a COG's: 2, 4, 8 times coarser): there too
    import rasterio

    with rasterio.open(tif, "r+") as ds:
        ds.build_overviews([2, 4, 8])
    coarse = GeoTiffTiles(tif)
    assert coarse.ds.overviews(1) == [2, 4, 8]
    tx, ty = _tile_xy(lat, lon, z - 2)
    _disc_where_mercator_says(coarse.tile(z - 2, int(tx), int(ty)), tx, ty, 0.5 / pixel(z - 2))
    assert 0 in coarse._overviews  # taken from the first overview (0.06 m cells for 0.068 m pixels)
    # the MBTiles: rows in TMS order (row 0 in the south), one per tile of the folder; GDAL reads it
    db = sqlite3.connect(tmp_path / "site.mbtiles")
    rows = db.execute("SELECT zoom_level, tile_column, tile_row FROM tiles").fetchall()
    files = {
        (int(p.parts[-3]), int(p.parts[-2]), int(p.stem))
        for p in (tmp_path / "xyz").glob("*/*/*.png")
    }
    assert {(zz, x, 2**zz - 1 - r) for zz, x, r in rows} == files
    info = subprocess.run(
        ["gdalinfo", str(tmp_path / "site.mbtiles")], check=False, capture_output=True, text=True
    )
    if info.returncode == 0 or "not found" not in info.stderr:
        assert "Pseudo-Mercator" in info.stdout, info.stdout[:500] + info.stderr


def test_the_service_serves_an_mbtiles_base_maps_tiles(service, tmp_path):  # noqa: F811
    """``skyfix run --basemap FILE.mbtiles``: its tiles at /basemap/Z/X/Y byte for byte; 404 where it has none."""
    tif = _geotiff(tmp_path / "site.tif", 63.44, 10.40, 12.0, 0.03, 0.5, alpha=True)
    source = GeoTiffTiles(tif)
    write_tiles(source, None, tmp_path / "site.mbtiles")
    mb = open_basemap(tmp_path / "site.mbtiles")
    assert mb.info()["sigma_m"] is None and source.info()["sigma_m"] is None  # no sidecar
    z = mb.info()["maxzoom"]
    x, y = next((x, y) for x, y in tiles_in(source.bounds, z) if mb.tile(z, x, y))
    base, _ = service("--basemap", str(tmp_path / "site.mbtiles"))
    status, headers, body = _get(f"{base}/basemap/{z}/{x}/{y}")
    assert status == 200 and headers["Content-Type"] == "image/png" and body == mb.tile(z, x, y)
    for path in (
        f"{z}/0/0",
        "3/8/0",
        "31/0/0",
        "2/1/-1",
    ):  # none there; beyond the zoom's tiles; not a tile
        assert _get(f"{base}/basemap/{path}")[0] == 404, path


def test_bad_base_maps_are_one_line_errors_naming_the_file(tmp_path):
    text = tmp_path / "notes.tif"
    text.write_text("not an image")
    empty = tmp_path / "empty"
    empty.mkdir()
    for path, why in (
        (text, "not an image GDAL reads"),
        (empty, "no Z/X/Y tiles"),
        (tmp_path / "missing.mbtiles", "no such file"),
    ):
        with pytest.raises(BaseMapError) as e:
            open_basemap(path)
        assert str(path) in str(e.value) and why in str(e.value) and "\n" not in str(e.value)
    # skyfix run stops at the start (exit 2), naming the option and the file
    run = subprocess.run(
        skyfix("run", "--calibration", str(SESSION / "session.toml"), "--video", "none", "--gps-input",
               "none", "--mavlink", f"udpin:127.0.0.1:{free_port()}", "--basemap", str(text),
               "--duration-s", "20"),
        check=False, capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert run.returncode == 2
    assert f"skyfix run: error: --basemap: {text}: not an image GDAL reads" in run.stderr


@pytest.mark.skipif(available() is not None, reason=str(available()))
def test_the_page_draws_the_base_map_under_the_fixes_at_the_right_pixel(tmp_path):
    truth = np.genfromtxt(SESSION / "truth.csv", delimiter=",", names=True)
    mid = len(truth) // 2
    uuv = float(truth["lat"][mid]), float(truth["lon"][mid])  # the UUV halfway through
    az = math.degrees(math.atan2(3.0, -1.5))  # 3 m east, 1.5 m south
    lon, lat, _ = Geod(ellps="WGS84").fwd(uuv[1], uuv[0], az, math.hypot(3.0, 1.5))
    radius_m = 0.4
    tif = _geotiff(tmp_path / "site.tif", *uuv, 30.0, 0.02, radius_m, alpha=False, mark=(lat, lon))
    # as skyfix mosaic's sidecar
    (tmp_path / "site.json").write_text('{"horizontal_sigma_m": 0.123}')
    with LiveRun(
        tmp_path,
        SESSION,
        "--calibration",
        str(SESSION / "session.toml"),  # its first box: tracking from the start
        "--basemap",
        str(tif),
        video_latency_ms=0,
        replay_now=False,
    ) as live:
        url = ui_url(tmp_path / "run.log")
        origin = url.rstrip("/")
        with chromium(tmp_path, origin) as browser:
            page = browser.page
            page.goto(url)
            page.wait_for_selector("#conn.ok", timeout=20_000)
            live.start_replay()
            wait_for(lambda: live.replay.poll() is not None, 40, "the replay's end")
            wait_for(
                lambda: int(page.eval_on_selector("#map", "m => m.dataset.points")) >= 10,
                10,
                "ten fixes on the map",
            )
            page.click("#follow")  # the view stays where it is
            wait_for(
                lambda: page.eval_on_selector("#map", "m => m.dataset.tiles") == "loaded",
                20,
                "the base map's tiles loaded",
            )
            view = page.evaluate(
                """() => { const c = lmap.getCenter(), r = document.getElementById("map")
                             .getBoundingClientRect(), s = lmap.getSize();
                           return [c.lat, c.lng, lmap.getZoom(), r.left + r.width / 2, r.top + r.height / 2,
                                   r.left, r.top, s.x, s.y]; }"""
            )
            png = browser.screenshot("basemap")
            assert "base map site.tif (placed to ±0.12 m, 1σ)" in page.inner_text("#map-info")
            assert not browser.errors, browser.errors
            assert browser.outside == [] and all(u.startswith(origin) for u in browser.requests)
            requested = " ".join(browser.requests)
            assert "/static/vendor/leaflet/leaflet.js" in requested and "/basemap/" in requested
        live.finish()

    c_lat, c_lon, zoom, cx, cy, left, top, width, height = view
    k = 256 * 2**zoom / (2 * math.pi * A_M)  # screen pixels per web-Mercator metre
    xc, yc = _mercator_m(c_lat, c_lon)

    def screen(point_lat, point_lon):  # continuous: 0 is a pixel's left edge
        xm, ym = _mercator_m(point_lat, point_lon)
        return cx + (xm - xc) * k, cy - (ym - yc) * k

    want = screen(lat, lon)
    shot = cv2.imread(str(png))[..., ::-1]
    x0, y0 = round(left) + 2, round(top) + 2
    area = shot[y0 : round(top + height) - 2, x0 : round(left + width) - 2]
    ys, xs = np.nonzero(_green(area))
    assert len(xs) > 20, "no disc of the base map on the page"
    got = ((xs.min() + xs.max() + 1) / 2 + x0, (ys.min() + ys.max() + 1) / 2 + y0)
    radius_px = radius_m * k / math.cos(math.radians(lat))  # web Mercator's scale: 1/cos(lat)
    print(
        f"base map's disc at {got[0]:.1f}, {got[1]:.1f} px, web Mercator says {want[0]:.1f}, "
        f"{want[1]:.1f}; radius {(xs.max() - xs.min() + 1) / 2:.1f} px of {radius_px:.1f} (zoom {zoom:.2f})"
    )
    assert math.dist(got, want) <= 2.0
    assert abs((xs.max() - xs.min() + 1) / 2 - radius_px) <= 2.0
    assert radius_px >= 4, f"zoom {zoom:.2f}: the disc too small to place"
    # the track (in the first UUV's colour, #b00000: its line, the last fix's disc and ring), drawn over the tiles,
    # lies on the UUV's true path (the fixes' error: 0.1 m at most; the last fix's ring: 7 px around it)
    r, g, b = (area[..., i].astype(int) for i in range(3))
    ry, rx = np.nonzero((r > 120) & (g < 50) & (b < 50))
    assert len(rx) > 20, "no track on the map"
    path = np.array([screen(a, o) for a, o in zip(truth["lat"], truth["lon"], strict=True)])
    off = np.hypot(
        rx[:, None] + x0 + 0.5 - path[None, :, 0], ry[:, None] + y0 + 0.5 - path[None, :, 1]
    ).min(axis=1)
    px_per_m = k / math.cos(math.radians(lat))
    print(
        f"the track's {len(rx)} pixels from the true path: median {np.median(off):.1f} px, max "
        f"{off.max():.1f} px ({px_per_m:.1f} px/m)"
    )
    assert np.median(off) <= 2 + 0.1 * px_per_m and off.max() <= 7 + 0.1 * px_per_m


def test_leaflet_is_unpacked_only_from_a_tarball_of_the_pinned_integrity(tmp_path, monkeypatch):
    import base64
    import hashlib
    import io
    import tarfile

    from groundstation.live.ui import vendor

    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w:gz") as tar:
        for name in (
            "dist/leaflet.js",
            "dist/leaflet.css",
            "LICENSE",
            "dist/images/layers.png",
            "src/Map.js",
        ):
            data = f"// {name}\n".encode()
            info = tarfile.TarInfo(f"package/{name}")
            info.size = len(data)
            tar.addfile(info, io.BytesIO(data))
    tgz = tmp_path / "leaflet.tgz"
    tgz.write_bytes(buf.getvalue())
    monkeypatch.setenv(vendor.ENV, str(tgz))
    # not the registry's integrity: refused, nothing written
    with pytest.raises(vendor.VendorError, match="is not the registry's integrity"):
        vendor.fetch(tmp_path / "out")
    assert not (tmp_path / "out").exists()
    # its own integrity: the page's files only, and the version
    own = "sha512-" + base64.b64encode(hashlib.sha512(tgz.read_bytes()).digest()).decode()
    monkeypatch.setattr(vendor, "INTEGRITY", own)
    assert vendor.fetch(tmp_path / "out") and vendor.is_present(tmp_path / "out")
    files = sorted(
        p.relative_to(tmp_path / "out").as_posix() for p in (tmp_path / "out").rglob("*.*")
    )
    assert files == ["images/layers.png", "leaflet.css", "leaflet.js"]
    assert (tmp_path / "out" / "LICENSE").read_text() == "// LICENSE\n"
    assert not vendor.fetch(tmp_path / "out")  # there already


@pytest.mark.skipif(available() is not None, reason=str(available()))
def test_without_leaflet_the_page_works_and_says_the_map_is_missing(service, tmp_path):  # noqa: F811
    """An installation without the map library (not fetched): the header, health and commands work, the map says
    why it is empty, no JavaScript error."""
    base, _ = service()
    with chromium(tmp_path, base) as browser:
        page = browser.page
        page.route("**/leaflet.js", lambda route: route.abort())
        page.goto(base + "/")
        page.wait_for_selector("#conn.ok", timeout=20_000)
        wait_for(
            lambda: "Leaflet) is missing" in page.inner_text("#map-info"),
            10,
            "the map saying its library is missing",
        )
        assert page.inner_text("#sending") == "NOT SENDING"  # the run has no --gps-input
        wait_for(lambda: "UAV MAVLink" in page.inner_text("#health"), 10, "the health table")
        assert not browser.errors, browser.errors
