"""``skyfix export --qgis`` and ``skyfix report`` with the bottom's mosaic, on a generated session: bottom_survey's
drone without attitude errors for 3 s at 640x360 over a textured floor with a surveyed bullseye ([marker]), its video
tracked by ``skyfix process`` (the tracker's pixels, not the truth's, leave the UUV out of the mosaic).

The QGIS project is read back as XML (layer order, CRS, paths resolving beside it; GDAL/OGR open the layers) and,
where a Python with QGIS's own ``qgis.core`` is installed (Debian's python3-qgis), opened by QGIS itself. The report's
top view is checked where it matters: the bullseye found in the PNG lies at the pixel the figure's axes give for
reference.toml's lat/lon, computed here by pyproj (an azimuthal equidistant plane at the plot's origin), not by the
plot's geodesy."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import textwrap
import tomllib
from pathlib import Path
from xml.etree import ElementTree as ET

import cv2
import numpy as np
import pytest
import rasterio
from matplotlib.image import imread
from pyproj import Transformer
from test_mosaic import NO_POSE_ERRORS, bullseye_centre_px

from groundstation.cli import main
from groundstation.offline.plots import top_view
from groundstation.session.positions import read_positions_csv
from sim_fixtures.generate import generate
from sim_fixtures.scenario import load_scenario, with_overrides

ROOT = Path(__file__).resolve().parents[1]
FLOOR_DEPTH_M = 4.0  # bottom_survey's site.floor_depth_m
QGIS_PYTHON = "/usr/bin/python3"  # Debian's python3-qgis installs qgis.core for the system's Python


def _scenario(**overrides):
    sc = load_scenario(ROOT / "sim_fixtures" / "scenarios" / "bottom_survey.toml")
    return with_overrides(
        sc,
        duration_s=3.0,
        camera={"width": 640, "height": 360},
        marker={"enabled": True},
        sensors=NO_POSE_ERRORS,
        **overrides,
    )


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """The session, its processed output folder (positions.csv from tracking the video) and the GeoJSON export's
    folder with the mosaic made by ``export --qgis``."""
    session = tmp_path_factory.mktemp("survey")
    generate(_scenario(), session)
    out = tmp_path_factory.mktemp("processed")
    assert main(["process", str(session), "--out", str(out), "--quiet"]) == 0
    args = ["--session", str(session), "--floor-depth-m", str(FLOOR_DEPTH_M), "--quiet"]
    assert main(["export", str(out), "--format", "geojson", "--qgis", *args]) == 0
    return session, out


def _layers(qgs: Path) -> list[dict]:
    """The project's layers in the layer tree's order (the first drawn on top): id, source, provider, CRS."""
    root = ET.parse(qgs).getroot()
    maps = {m.findtext("id"): m for m in root.iter("maplayer")}
    found = []
    for node in root.find("layer-tree-group").iter("layer-tree-layer"):
        m = maps[node.get("id")]
        found.append(
            {
                "type": m.get("type"),
                "source": m.findtext("datasource"),
                "provider": m.findtext("provider"),
                "crs": m.findtext("srs/spatialrefsys/authid"),
                "tree_source": node.get("source"),
            }
        )
    return found


def _file_of(source: str, base: Path) -> Path:
    """The file a QGIS data source names, relative to the project's folder."""
    path = source.removeprefix("file:").split("|")[0].split("?")[0]
    return (base / path).resolve()


def test_export_makes_the_mosaic_and_a_project_with_the_track_over_it(run):
    _, out = run
    side = json.loads((out / "mosaic.json").read_text())
    assert side["uuv_left_out"]["pixels_from"] == str(out / "positions.csv")  # the tracker's pixels
    assert side["uuv_left_out"]["frames"] > 0 and side["floor_depth_m"] == FLOOR_DEPTH_M
    qgs = out / "fixes.geojson.qgs"
    root = ET.parse(qgs).getroot()
    with rasterio.open(out / "mosaic.tif") as d:
        epsg = d.crs.to_epsg()
    assert root.findtext("projectCrs/spatialrefsys/authid") == f"EPSG:{epsg}"
    track, mosaic = _layers(qgs)  # the track first: drawn over the mosaic
    assert (track["type"], track["provider"], track["crs"]) == ("vector", "ogr", "EPSG:4326")
    assert (mosaic["type"], mosaic["provider"], mosaic["crs"]) == ("raster", "gdal", f"EPSG:{epsg}")
    assert all(not layer["source"].startswith("/") for layer in (track, mosaic))  # movable folder
    assert _file_of(track["source"], qgs.parent) == (out / "fixes.geojson").resolve()
    assert _file_of(mosaic["source"], qgs.parent) == (out / "mosaic.tif").resolve()


def test_gdal_opens_the_project_layers(run):
    """GDAL/OGR (what QGIS reads them with) open the layers by the project's paths, in the project's CRSs."""
    if shutil.which("ogrinfo") is None or shutil.which("gdalinfo") is None:
        if os.environ.get("CI"):
            pytest.fail("ogrinfo/gdalinfo missing: ./dev installs gdal-bin")
        pytest.skip("gdal-bin not installed")
    _, out = run
    qgs = out / "fixes.geojson.qgs"
    track, mosaic = _layers(qgs)
    vector = subprocess.run(
        ["ogrinfo", "-ro", "-so", "-al", str(_file_of(track["source"], qgs.parent))],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    pos = read_positions_csv(out / "positions.csv")
    assert f"Feature Count: {len(pos)}" in vector and "WGS 84" in vector
    raster = json.loads(
        subprocess.run(
            ["gdalinfo", "-json", str(_file_of(mosaic["source"], qgs.parent))],
            capture_output=True,
            text=True,
            check=True,
        ).stdout
    )
    assert mosaic["crs"].split(":")[1] in raster["coordinateSystem"]["wkt"]


QGIS_READ = textwrap.dedent(
    """
    import json, sys
    from qgis.core import QgsApplication, QgsProject
    app = QgsApplication([], False)
    app.initQgis()
    project = QgsProject.instance()
    layers = []
    if project.read(sys.argv[1]):
        for node in project.layerTreeRoot().findLayers():
            layer = node.layer()
            entry = {"loaded": layer is not None}
            if layer is not None:
                entry.update(valid=layer.isValid(), crs=layer.crs().authid())
                if hasattr(layer, "featureCount"):
                    points = [f.geometry().vertexAt(0) for f in layer.getFeatures()]
                    entry["first_xy"] = [points[0].x(), points[0].y()] if points else None
                    entry["features"] = layer.featureCount()
            layers.append(entry)
    print(json.dumps({"crs": project.crs().authid(), "layers": layers}))
    """
)


def _qgis_available() -> bool:
    if not Path(QGIS_PYTHON).is_file():
        return False
    return (
        subprocess.run(
            [QGIS_PYTHON, "-c", "import qgis.core"], capture_output=True, check=False
        ).returncode
        == 0
    )


@pytest.mark.parametrize("fmt", ["geojson", "kml", "gpx", "csv"])
def test_qgis_opens_the_project(run, fmt, tmp_path):
    """QGIS reads the project of each format: both layers loaded and valid, in their CRSs, the track's first
    point positions.csv's first fix (lon, lat), the mosaic given by --mosaic from another folder."""
    if not _qgis_available():
        pytest.skip("no Python with QGIS's qgis.core (apt install python3-qgis)")
    _, out = run
    dest = tmp_path / f"run.{fmt}"
    mosaic = out / "mosaic.tif"
    args = ["--format", fmt, "--out", str(dest), "--mosaic", str(mosaic)]
    assert main(["export", str(out), *args]) == 0
    assert not (tmp_path / "mosaic.tif").exists()  # the given one, not a new one
    found = subprocess.run(
        [QGIS_PYTHON, "-c", QGIS_READ, str(tmp_path / f"run.{fmt}.qgs")],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "QT_QPA_PLATFORM": "offscreen"},
        check=True,
    )
    project = json.loads(found.stdout.strip().splitlines()[-1])
    with rasterio.open(mosaic) as d:
        epsg = d.crs.to_epsg()
    assert project["crs"] == f"EPSG:{epsg}"
    track, raster = project["layers"]
    assert track["valid"] and raster["valid"], project
    assert track["crs"] == "EPSG:4326" and raster["crs"] == f"EPSG:{epsg}"
    pos = read_positions_csv(out / "positions.csv")
    first = int(np.flatnonzero(pos.status == "ok")[0])
    assert track["first_xy"] == pytest.approx([pos.lon[first], pos.lat[first]], abs=1e-8)


def test_export_without_a_session_or_mosaic_is_one_line(tmp_path, capsys):
    (tmp_path / "positions.csv").write_text(
        "t,lat,lon,depth_m,h_acc_m,status\n1,63.44,10.4,2,0.1,ok\n"
    )
    assert main(["export", str(tmp_path), "--format", "csv", "--qgis"]) == 2
    err = capsys.readouterr().err.strip()
    assert "mosaic.tif: missing" in err and "--mosaic" in err and len(err.splitlines()) == 1


def test_report_draws_the_top_view_over_the_mosaic_in_place(run, tmp_path):
    """The bullseye of the mosaic under the top view is where the figure's axes put reference.toml's position:
    within 2 mosaic cells (the mosaic's own error without attitude errors) and a figure pixel."""
    session, out = run
    ref = tomllib.loads((session / "reference.toml").read_text())
    png = tmp_path / "top_view.png"
    fixes = read_positions_csv(out / "positions.csv")
    where = top_view(png, "survey", {"fixes": fixes}, None, out / "mosaic.tif")
    lat0, lon0 = where["origin_deg"]
    plane = Transformer.from_crs(
        4326, f"+proj=aeqd +lat_0={lat0} +lon_0={lon0} +ellps=WGS84 +units=m", always_xy=True
    )
    east_m, north_m = plane.transform(ref["lon_deg"], ref["lat_deg"])
    (e0, e1), (n0, n1) = where["east_m"], where["north_m"]
    left, top, right, bottom = where["axes_px"]
    px_per_m = (right - left) / (e1 - e0)
    assert px_per_m == pytest.approx((bottom - top) / (n1 - n0), rel=0.01)  # equal aspect
    col_ref = left + (east_m - e0) * px_per_m - 0.5  # pixel centres at integers
    row_ref = top + (n1 - north_m) * px_per_m - 0.5

    rgb = (imread(png)[..., :3] * 255).astype(np.uint8)
    grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    # search the figure around the marker (the legend, the bar aside)
    half = int(3 * ref["radius_m"] * px_per_m)
    r0, c0 = int(row_ref) - half, int(col_ref) - half
    col, row = bullseye_centre_px(
        grey[r0 : r0 + 2 * half, c0 : c0 + 2 * half], ref["radius_m"] * px_per_m
    )
    error_px = float(np.hypot(c0 + col - col_ref, r0 + row - row_ref))
    gsd_m = json.loads((out / "mosaic.json").read_text())["gsd_m"]
    print(
        f"report: the marker {error_px:.1f} px = {error_px / px_per_m:.3f} m from its surveyed place"
    )
    assert error_px <= 2 * gsd_m * px_per_m + 1.0


def test_report_command_uses_the_mosaic_beside_positions(run, capsys):
    """``skyfix report`` of the folder with mosaic.tif draws over it: most of the plot's area is the mosaic, not the
    white of the plain top view; a --mosaic that is not there is one line."""
    _, out = run
    assert main(["report", str(out), "--out", str(out / "with")]) == 0
    fixes = read_positions_csv(out / "positions.csv")
    name = out.resolve().name

    def plot_area(png, mosaic):  # the same figure drawn again tells where its axes are
        where = top_view(out / "again.png", name, {"fixes": fixes}, None, mosaic)
        left, top, right, bottom = (round(x) for x in where["axes_px"])
        return imread(png)[top + 2 : bottom - 2, left + 2 : right - 2, :3]

    plain = plot_area(out / "again.png", None)
    over = plot_area(out / "with" / "top_view.png", out / "mosaic.tif")
    assert np.mean(plain.min(axis=-1) > 0.95) > 0.5  # white
    assert np.mean(over.min(axis=-1) > 0.95) < 0.05
    capsys.readouterr()
    assert main(["report", str(out), "--mosaic", str(out / "none.tif")]) == 2
    err = capsys.readouterr().err.strip()
    assert "--mosaic" in err and "none.tif" in err and len(err.splitlines()) == 1


def _rgba(path: Path) -> tuple[np.ndarray, np.ndarray]:
    with rasterio.open(path) as d:
        return np.moveaxis(d.read((1, 2, 3)), 0, -1).astype(float), d.read(4) == 255


def test_the_uuv_is_left_out_around_the_trackers_pixels(run, tmp_path):
    """The mosaic export made (the UUV left out around positions.csv's tracked pixels) against the same flight over
    the same floor with a UUV too small to see (5 cm): few cells differ by more than 10 levels; with no pixels to
    leave out (positions.csv's u, v emptied) the UUV's trail shows: several times as many."""
    session, out = run
    ghost = tmp_path / "ghost"
    generate(_scenario(uuv={"size_m": [0.05, 0.05, 0.05]}), ghost)
    depth = ["--floor-depth-m", str(FLOOR_DEPTH_M), "--quiet"]
    assert main(["mosaic", str(ghost), "--out", str(tmp_path / "floor"), *depth]) == 0
    rows = (out / "positions.csv").read_text().splitlines()
    header = rows[0].split(",")
    iu, iv = header.index("u"), header.index("v")
    blank = []
    for line in rows[1:]:
        cells = line.split(",")
        cells[iu] = cells[iv] = ""
        blank.append(",".join(cells))
    (tmp_path / "no_pixels.csv").write_text("\n".join([rows[0], *blank]) + "\n")
    no_pixels = ["--positions", str(tmp_path / "no_pixels.csv")]
    assert main(["mosaic", str(session), "--out", str(tmp_path / "kept"), *no_pixels, *depth]) == 0
    assert (
        json.loads((tmp_path / "kept" / "mosaic.json").read_text())["uuv_left_out"]["frames"] == 0
    )

    floor, a_floor = _rgba(tmp_path / "floor" / "mosaic.tif")
    left_out, a_left = _rgba(out / "mosaic.tif")
    kept, a_kept = _rgba(tmp_path / "kept" / "mosaic.tif")
    assert floor.shape == left_out.shape == kept.shape  # the same poses: the same grid
    both = a_floor & a_left & a_kept
    differ_left_out = int(np.sum((np.abs(left_out - floor).max(axis=-1) > 10) & both))
    differ_kept = int(np.sum((np.abs(kept - floor).max(axis=-1) > 10) & both))
    print(f"cells > 10 levels off the floor: UUV left out {differ_left_out}, kept {differ_kept}")
    assert differ_kept > 200
    assert differ_left_out < 0.25 * differ_kept
