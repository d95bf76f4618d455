"""``skyfix export``: GeoJSON, KML, GPX and CSV parsed back with real parsers (the geojson package,
XML, csv) and opened by GDAL/OGR (``ogr2ogr``, as QGIS reads them), coordinates compared with
positions.csv in both orders' worth of detail (lat 63.44 and lon 10.40 cannot be swapped unseen)."""

from __future__ import annotations

import csv
import json
import os
import shutil
import subprocess
from datetime import datetime
from pathlib import Path
from xml.etree import ElementTree as ET

import geojson
import numpy as np
import pytest

from groundstation.cli import main
from groundstation.session.positions import read_positions_csv
from localizer.status import runs
from sim_fixtures.bundle import BUNDLED_DIR

KML = "{http://www.opengis.net/kml/2.2}"
GPX = "{http://www.topografix.com/GPX/1/1}"
SKYFIX = "{urn:skyfix:gpx:1}"


@pytest.fixture(scope="module")
def processed(tmp_path_factory):
    """The occlusion session processed (geometry only): fixes with a 45-frame gap, GPS_RAW_INT heights."""
    out = tmp_path_factory.mktemp("occlusion")
    assert (
        main(
            ["process", str(BUNDLED_DIR / "occlusion"), "--out", str(out), "--use-track", "--quiet"]
        )
        == 0
    )
    for fmt in ("geojson", "kml", "gpx", "csv"):
        assert main(["export", str(out), "--format", fmt]) == 0
    return out, read_positions_csv(out / "positions.csv")


def test_geojson(processed):
    out, pos = processed
    text = (out / "fixes.geojson").read_text()
    # the geojson package checks the structure (it rounds to 6 decimals: not for values)
    valid = geojson.loads(text)
    assert valid.is_valid, valid.errors()
    doc = json.loads(text)
    assert len(doc["features"]) == len(pos)
    ok = pos.status == "ok"
    assert 0 < ok.sum() < len(pos)
    for f, is_ok, lat, lon, h, h_acc, status in zip(
        doc["features"], ok, pos.lat, pos.lon, pos.alt_ellipsoid_m, pos.h_acc_m, pos.status
    ):
        assert f["properties"]["status"] == status
        if is_ok:
            x, y, z = f["geometry"]["coordinates"]  # RFC 7946: lon, lat, height above the ellipsoid
            assert (x, y) == pytest.approx((lon, lat), abs=1e-9) and z == pytest.approx(h, abs=1e-4)
            assert f["properties"]["h_acc_m"] == pytest.approx(h_acc, abs=1e-4)
        else:
            assert f["geometry"] is None and f["properties"]["lat"] is None


def test_kml(processed):
    out, pos = processed
    root = ET.parse(out / "fixes.kml").getroot()
    folders = {f.findtext(f"{KML}name"): f for f in root.iter(f"{KML}Folder")}
    ok = np.flatnonzero(pos.status == "ok")
    marks = folders["fixes"].findall(f"{KML}Placemark")
    assert len(marks) == len(ok)
    for pm, i in zip(marks, ok):
        # KML: lon,lat,alt (AMSL)
        lon, lat, alt = map(float, pm.findtext(f".//{KML}coordinates").split(","))
        assert (lon, lat, alt) == pytest.approx(
            (pos.lon[i], pos.lat[i], pos.alt_amsl_m[i]), abs=1e-4
        )
        assert abs(lon - pos.lon[i]) < 1e-9 and abs(lat - pos.lat[i]) < 1e-9
        data = {d.get("name"): d.text for d in pm.iter(f"{KML}SimpleData")}
        assert data["status"] == "ok" and float(data["h_acc_m"]) == pytest.approx(
            pos.h_acc_m[i], abs=1e-4
        )
        datetime.fromisoformat(pm.findtext(f".//{KML}when"))
    gaps = [(a, b, w) for a, b, w in runs(pos.status) if w != "ok"]
    names = [pm.findtext(f"{KML}name") for pm in folders["no fix"].findall(f"{KML}Placemark")]
    assert names == [f"{w}: {b - a} frames" for a, b, w in gaps]
    # the gap splits the track
    assert len(folders["track"].findall(f"{KML}Placemark")) == len(gaps) + 1


def test_gpx(processed):
    out, pos = processed
    root = ET.parse(out / "fixes.gpx").getroot()
    segments = root.findall(f"{GPX}trk/{GPX}trkseg")
    assert len(segments) == sum(w == "ok" for _, _, w in runs(pos.status))
    points = [p for s in segments for p in s.findall(f"{GPX}trkpt")]
    ok = np.flatnonzero(pos.status == "ok")
    assert len(points) == len(ok)
    for p, i in zip(points, ok):
        assert float(p.get("lat")) == pytest.approx(pos.lat[i], abs=1e-9)
        assert float(p.get("lon")) == pytest.approx(pos.lon[i], abs=1e-9)
        assert float(p.findtext(f"{GPX}ele")) == pytest.approx(pos.alt_amsl_m[i], abs=1e-4)
        # the scenario's
        assert float(p.findtext(f"{GPX}geoidheight")) == pytest.approx(40.0, abs=2e-4)
        assert float(p.findtext(f"{GPX}hdop")) == pytest.approx(pos.h_acc_m[i], abs=1e-4)
        assert p.findtext(f"{GPX}extensions/{SKYFIX}status") == "ok"
    # the GPX 1.1 schema's order of a point's elements
    order = ["ele", "time", "magvar", "geoidheight", "name", "hdop", "vdop", "extensions"]
    tags = [c.tag.removeprefix(GPX) for c in points[0]]
    assert tags == sorted(tags, key=order.index)


def test_csv(processed):
    out, pos = processed
    with open(out / "fixes.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == len(pos)
    for row, status, lat, t_gnss in zip(rows, pos.status, pos.lat, pos.t_gnss):
        assert row["status"] == status and (row["lat"] == "") == (status != "ok")
        if status == "ok":
            assert float(row["lat"]) == pytest.approx(lat, abs=1e-9)
        assert row["time_source"] == "gnss"
        assert datetime.fromisoformat(row["time"]).timestamp() == pytest.approx(t_gnss, abs=1e-3)


OGR = {
    "geojson": ([], None),
    "kml": ([], "fixes"),
    "gpx": ([], "track_points"),
    "csv": (["-oo", "X_POSSIBLE_NAMES=lon", "-oo", "Y_POSSIBLE_NAMES=lat"], None),
}


@pytest.mark.parametrize("fmt", OGR)
def test_gdal_reads_the_exports(processed, fmt):
    """GDAL/OGR (what QGIS uses) opens each export; its points are positions.csv's, lon/lat in place."""
    if shutil.which("ogr2ogr") is None:
        if os.environ.get("CI"):
            pytest.fail("ogr2ogr missing: ./dev installs gdal-bin")
        pytest.skip("ogr2ogr (gdal-bin) not installed")
    out, pos = processed
    opts, layer = OGR[fmt]
    cmd = [
        "ogr2ogr",
        "-f",
        "GeoJSON",
        "/vsistdout/",
        *opts,
        str(out / f"fixes.{fmt}"),
        *([layer] if layer else []),
    ]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=60, check=False)
    assert res.returncode == 0, res.stderr
    points = [
        f["geometry"]["coordinates"] for f in json.loads(res.stdout)["features"] if f["geometry"]
    ]
    ok = pos.status == "ok"
    assert np.allclose(np.array(points)[:, :2], np.c_[pos.lon[ok], pos.lat[ok]], atol=1e-9)


def test_unknown_ellipsoid_height_is_left_out_not_guessed(tmp_path):
    """positions.csv from another tool (the spec's six columns): 2D GeoJSON points, no geoidheight in GPX."""
    pos = tmp_path / "positions.csv"
    pos.write_text(
        "t,lat,lon,depth_m,h_acc_m,status\n1763800000.0,63.44,10.4,1.0,0.2,ok\n"
        "1763800000.1,,,1.0,,lost\n"
    )
    assert (
        main(["export", str(pos), "--format", "geojson", "--out", str(tmp_path / "a.geojson")]) == 0
    )
    f = json.loads((tmp_path / "a.geojson").read_text())["features"]
    assert (
        f[0]["geometry"]["coordinates"] == [10.4, 63.44]
        and f[0]["properties"]["alt_ellipsoid_m"] is None
    )
    assert f[1]["geometry"] is None and f[0]["properties"]["time_source"] == "station"
    assert main(["export", str(tmp_path), "--format", "gpx"]) == 0
    root = ET.parse(tmp_path / "fixes.gpx").getroot()
    assert root.find(f".//{GPX}geoidheight") is None and root.find(f".//{GPX}ele") is None


def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys):
    assert main(["export", str(tmp_path), "--format", "kml"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        (
            f"skyfix export: error: {tmp_path / 'positions.csv'}: missing (a recorded session has one; "
            f"for others run `skyfix process {tmp_path} --out DIR` and export DIR)"
        )
    ]
    (tmp_path / "positions.csv").write_text(
        "t,lat,lon,depth_m,h_acc_m,status\n1.0,63.4,x,1,0.2,ok\n"
    )
    assert main(["export", str(tmp_path), "--format", "csv"]) == 2
    assert "positions.csv:2: lon = 'x': not a number" in capsys.readouterr().err
    assert (
        main(
            [
                "export",
                str(tmp_path / "positions.csv"),
                "--format",
                "csv",
                "--out",
                str(tmp_path / "positions.csv"),
            ]
        )
        == 2
    )
    assert Path(tmp_path / "positions.csv").read_text().startswith("t,lat")  # nothing lost
