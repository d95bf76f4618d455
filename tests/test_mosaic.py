"""``skyfix mosaic``: a georeferenced mosaic of the bottom (groundstation/offline/mosaic.py), checked on a generated
session against what the simulator painted: bottom_survey's drone (its AHRS, compass and GNSS errors; none; or
corrected by the pose from the bottom) for 3 s at
640x360 over a textured floor with a surveyed bullseye ([marker]). The bullseye is found in the mosaic by template
matching, its cell turned into UTM by the GeoTIFF's own transform and compared with reference.toml's lat/lon through
pyproj (not the localizer's geometry)."""

import json
import shutil
import subprocess
import tomllib
from pathlib import Path

import cv2
import numpy as np
import pytest
import rasterio
from pyproj import Transformer

from groundstation.cli import main
from sim_fixtures.generate import generate
from sim_fixtures.scenario import load_scenario, with_overrides

ROOT = Path(__file__).resolve().parents[1]


#: bottom_survey's drone without its attitude errors: what is left is the mosaic's own geometry and the RTK's noise
NO_POSE_ERRORS = {
    "roll_bias_deg": 0.0,
    "pitch_bias_deg": 0.0,
    "yaw_bias_deg": 0.0,
    "wander_deg": 0.0,
}


@pytest.fixture(scope="module", params=["as_flown", "no_pose_errors", "pose_from_bottom"])
def mosaic(tmp_path_factory, request):
    """The session, the mosaic's output folder made by the command line, and whether the mosaic's poses are
    expected right to 2 cells: the drone's attitude errors as the scenario has them (the floor depth given), none,
    or as flown and corrected by the pose from the bottom (its floor depth the estimate's)."""
    session = tmp_path_factory.mktemp("survey")
    sc = load_scenario(ROOT / "sim_fixtures" / "scenarios" / "bottom_survey.toml")
    sc = with_overrides(
        sc, duration_s=3.0, camera={"width": 640, "height": 360}, marker={"enabled": True}
    )
    if request.param == "no_pose_errors":
        sc = with_overrides(sc, sensors=NO_POSE_ERRORS)
    generate(sc, session)
    out = tmp_path_factory.mktemp("mosaic")
    if request.param == "pose_from_bottom":
        how = ["--pose-from-bottom", "auto"]
    else:
        how = ["--floor-depth-m", str(sc.site.floor_depth_m)]
    assert main(["mosaic", str(session), "--out", str(out), *how, "--quiet"]) == 0
    return session, out, request.param != "as_flown"


def bullseye_centre_px(grey: np.ndarray, radius_px: float) -> tuple[float, float]:
    """The (col, row) of a bullseye's centre (a white disc, a black centre of half its radius) in a grey image, by
    normalised cross-correlation with a drawn one and a parabola through the peak's neighbours."""
    half = int(np.ceil(1.6 * radius_px))
    yy, xx = np.mgrid[-half : half + 1, -half : half + 1]
    dist = np.hypot(xx, yy)
    template = np.full(dist.shape, 128, np.uint8)
    template[dist <= radius_px] = 255
    template[dist <= radius_px / 2] = 0
    score = cv2.matchTemplate(grey, template, cv2.TM_CCOEFF_NORMED)
    _, peak, _, (c, r) = cv2.minMaxLoc(score)
    assert peak > 0.6, peak

    def vertex(a, b, m):
        return 0.5 * (a - b) / (a - 2 * m + b)

    dc = vertex(score[r, c - 1], score[r, c + 1], score[r, c])
    dr = vertex(score[r - 1, c], score[r + 1, c], score[r, c])
    return float(c + dc + half), float(r + dr + half)  # float64: UTM coordinates need it


def test_mosaic_is_a_cog_in_utm_with_the_marker_where_it_was_surveyed(mosaic):
    """The COG opens with rasterio in the UTM zone of the site (EPSG 32632 at 63.44 N, 10.4 E), tiled with
    overviews, its bounds the sidecar's and around the marker; the bullseye found in it lies within the stated
    1-sigma of reference.toml's position with the drone's attitude errors, within 2 cells without them or with
    them corrected from the bottom."""
    session, out, exact = mosaic
    side = json.loads((out / "mosaic.json").read_text())
    ref = tomllib.loads((session / "reference.toml").read_text())
    with rasterio.open(out / "mosaic.tif") as d:
        assert d.crs.to_epsg() == 32632
        assert d.profile["tiled"] and d.overviews(1)
        assert d.count == 4
        rgb = np.transpose(d.read((1, 2, 3)), (1, 2, 0))
        alpha = d.read(4)
        transform, bounds = d.transform, d.bounds
    assert side["crs"] == "EPSG:32632"
    b = side["bounds_m"]
    assert np.allclose(
        [bounds.left, bounds.bottom, bounds.right, bounds.top],
        [b["west"], b["south"], b["east"], b["north"]],
    )
    assert transform.a == pytest.approx(side["gsd_m"]) and transform.e == pytest.approx(
        -side["gsd_m"]
    )
    assert 0.3 < np.mean(alpha == 255) <= 1.0
    x_ref, y_ref = Transformer.from_crs(4326, 32632, always_xy=True).transform(
        ref["lon_deg"], ref["lat_deg"]
    )
    assert bounds.left < x_ref < bounds.right and bounds.bottom < y_ref < bounds.top

    grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    col, row = bullseye_centre_px(grey, ref["radius_m"] / side["gsd_m"])
    assert alpha[round(row), round(col)] == 255
    x, y = rasterio.transform.xy(transform, row, col)  # the cell's centre
    error_m = float(np.hypot(x - x_ref, y - y_ref))
    print(
        f"marker: {error_m:.3f} m = {error_m / side['gsd_m']:.1f} cells; stated 1-sigma "
        f"{side['horizontal_sigma_m']:.3f} m"
    )
    if exact:
        assert error_m <= 2 * side["gsd_m"], (error_m, side)
    else:
        assert error_m <= side["horizontal_sigma_m"], (error_m, side)


def test_gdalinfo_reads_the_crs_and_the_bounds(mosaic):
    """gdalinfo (GDAL's own, not rasterio's) says the UTM zone and the sidecar's corners, and that it is a COG."""
    if shutil.which("gdalinfo") is None:
        pytest.skip("gdalinfo not installed")
    _, out, _ = mosaic
    side = json.loads((out / "mosaic.json").read_text())
    info = json.loads(
        subprocess.run(
            ["gdalinfo", "-json", str(out / "mosaic.tif")],
            capture_output=True,
            check=True,
            text=True,
        ).stdout
    )
    assert '"EPSG",32632' in info["coordinateSystem"]["wkt"].replace(" ", "")
    corners = info["cornerCoordinates"]
    b = side["bounds_m"]
    assert np.allclose(corners["upperLeft"], [b["west"], b["north"]], atol=1e-3)
    assert np.allclose(corners["lowerRight"], [b["east"], b["south"]], atol=1e-3)
    assert info["metadata"]["IMAGE_STRUCTURE"]["LAYOUT"] == "COG"


def test_bad_floor_depth_is_one_line_naming_it(mosaic, capsys):
    session, out, _ = mosaic
    assert (
        main(["mosaic", str(session), "--out", str(out), "--floor-depth-m", "-1", "--quiet"]) == 2
    )
    err = capsys.readouterr().err.strip()
    assert "--floor-depth-m -1" in err and len(err.splitlines()) == 1


def test_the_blend_spilled_to_disk_is_the_blend_held_in_memory(tmp_path):
    """The blend's tiles (groundstation.offline.mosaic.Accumulator): random weighted blocks added across tile
    borders give the same weighted mean with 1 tile held in memory (the rest spilled and read back) as with all
    held, and that mean is the one computed here over a whole-grid array."""
    from groundstation.offline.mosaic import TILE, Accumulator

    rng = np.random.default_rng(3)
    height, width = 2 * TILE + 37, 3 * TILE + 5
    whole = np.zeros((height, width, 4))
    spilled, held = tmp_path / "spilled", tmp_path / "held"
    spilled.mkdir()
    held.mkdir()
    small, large = Accumulator(spilled, max_tiles=1), Accumulator(held, max_tiles=100)
    for _ in range(12):
        h, w = rng.integers(1, 300, size=2)
        r0, c0 = rng.integers(0, height - h), rng.integers(0, width - w)
        weight = rng.uniform(0, 1, (h, w)) * (rng.uniform(size=(h, w)) > 0.3)
        block = np.dstack([rng.uniform(0, 255, (h, w, 3)) * weight[..., None], weight])
        whole[r0 : r0 + h, c0 : c0 + w] += block
        small.add(int(r0), int(c0), block.astype(np.float32))
        large.add(int(r0), int(c0), block.astype(np.float32))
    assert small.painted() == large.painted() and any(spilled.iterdir())
    for tr, tc in large.painted():
        a, b = small.rgba((tr, tc)), large.rgba((tr, tc))
        assert np.array_equal(a, b)
        ref = whole[tr * TILE : (tr + 1) * TILE, tc * TILE : (tc + 1) * TILE]
        w = ref[:, :, 3]
        h_, w_ = w.shape
        assert np.array_equal(a[:h_, :w_, 3] == 255, w > 0)
        mean = ref[:, :, :3] / np.where(w > 0, w, 1)[..., None]
        assert np.max(np.abs(a[:h_, :w_, :3] - np.round(mean))[w > 0]) <= 1


def marker_error_in_tiles(tile, z: int, ref: dict) -> tuple[float, float]:
    """The bullseye of reference.toml (``ref``) found in the 3 x 3 zoom-``z`` tiles around its surveyed position
    (``tile(z, x, y)``: a tile's PNG or None), its tile pixel turned into a position by pyproj's web Mercator (not
    groundstation.map.tiles' formulas): its distance from the surveyed position and a tile pixel's size, m."""
    to_merc = Transformer.from_crs(4326, 3857, always_xy=True)
    half_world = to_merc.transform(180.0, 0.0)[0]
    tile_m = 2 * half_world / 2**z
    x_ref, y_ref = to_merc.transform(ref["lon_deg"], ref["lat_deg"])
    tx, ty = int((x_ref + half_world) // tile_m), int((half_world - y_ref) // tile_m)
    block = np.zeros((3 * 256, 3 * 256, 4), np.uint8)
    for i in range(3):
        for j in range(3):
            png = tile(z, tx - 1 + i, ty - 1 + j)
            if png is not None:
                bgra = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_UNCHANGED)
                block[j * 256 : (j + 1) * 256, i * 256 : (i + 1) * 256] = bgra
    assert block[..., 3].any()
    cos_lat = np.cos(np.radians(ref["lat_deg"]))  # web Mercator's scale is 1 / cos(lat)
    pixel_m = tile_m / 256
    col, row = bullseye_centre_px(
        cv2.cvtColor(block[..., :3], cv2.COLOR_BGR2GRAY), ref["radius_m"] / (pixel_m * cos_lat)
    )
    x = (tx - 1) * tile_m - half_world + (col + 0.5) * pixel_m
    y = half_world - (ty - 1) * tile_m - (row + 0.5) * pixel_m
    return float(np.hypot(x - x_ref, y - y_ref) * cos_lat), float(pixel_m * cos_lat)


def test_the_map_tiles_hold_the_marker_where_web_mercator_says(mosaic):
    """``tiles/Z/X/Y.png`` and ``mosaic.mbtiles`` (the same tiles, TMS rows) written beside the COG: at the finest
    zoom the bullseye found in the tiles (:func:`marker_error_in_tiles`) lies as near the truth as in the COG:
    within 2 cells and a tile pixel without attitude errors or with them corrected, within the stated 1-sigma as
    flown."""
    from groundstation.map.tiles import open_basemap

    session, out, exact = mosaic
    side = json.loads((out / "mosaic.json").read_text())
    ref = tomllib.loads((session / "reference.toml").read_text())
    folder, mb = open_basemap(out / "tiles"), open_basemap(out / "mosaic.mbtiles")
    z = folder.info()["maxzoom"]
    assert mb.info()["maxzoom"] == z and mb.info()["sigma_m"] == side["horizontal_sigma_m"]

    def tile(z, x, y):
        png = folder.tile(z, x, y)
        assert png == mb.tile(z, x, y)
        return png

    error_m, pixel_m = marker_error_in_tiles(tile, z, ref)
    print(f"marker in the zoom-{z} tiles: {error_m:.3f} m (tile pixel {pixel_m:.3f} m)")
    if exact:
        assert error_m <= 2 * side["gsd_m"] + pixel_m, (error_m, side)
    else:
        assert error_m <= side["horizontal_sigma_m"], (error_m, side)
