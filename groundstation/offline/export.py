"""``skyfix export SESSION|positions.csv --format geojson|kml|gpx|csv [--out FILE] [--qgis]``: the fixes for GIS tools.

Reads ``positions.csv`` (a recorded session has one; ``skyfix process SESSION --out DIR``
writes one into DIR) and writes one file for QGIS, Google Earth or a GPS tool, with each
fix's accuracy and status:

- ``geojson`` (RFC 7946): a Point feature per frame, ``null`` geometry where there is no
  fix; coordinates ``[lon, lat, height above the WGS84 ellipsoid]`` as the RFC says, or
  ``[lon, lat]`` when the ellipsoid height is unknown; every value in ``properties``.
- ``kml`` (Google Earth): a placemark per fix (time stamp, values as ExtendedData), the
  track as lines through consecutive fixes, and one placemark without position per
  stretch of frames without a fix (its status, time span and frame count). KML altitudes
  are above mean sea level: ``alt_amsl_m``; drawn clamped to the ground (the UUV is
  under water), the values stay in the data.
- ``gpx`` (1.1): a track, one segment per stretch of consecutive fixes; ``ele`` is
  ``alt_amsl_m``, ``geoidheight`` the geoid separation where known (as NMEA GGA),
  ``hdop``/``vdop`` the 1-sigma accuracies in metres (as skyfix's GPS_INPUT, a nominal
  1 m range error), the rest under ``extensions``.
- ``csv``: every frame, with an ISO 8601 time; QGIS opens it as a delimited-text layer
  with X = ``lon``, Y = ``lat`` (EPSG:4326).

With ``--qgis`` (or ``--mosaic PATH``) also a QGIS project beside the export, ``FILE.qgs`` (:func:`qgis_project`):
the track over the bottom's mosaic (:func:`map_mosaic`: given, found beside, or made by
:func:`groundstation.offline.mosaic.mosaic_of`), each layer with its CRS, paths relative to the project.

Times: ``time`` is the exposure in UTC from ``t_gnss`` (the UAV's GNSS clock) where it is
known, else from ``t`` (the station clock); ``time_source`` says which.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import uuid
from datetime import UTC, datetime
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np

from groundstation.session.positions import read_positions_csv
from groundstation.session.read import SessionError
from localizer.fix import Fixes
from localizer.status import runs

FORMATS = {"geojson": ".geojson", "kml": ".kml", "gpx": ".gpx", "csv": ".csv"}
KML_NS = "http://www.opengis.net/kml/2.2"
GPX_NS = "http://www.topografix.com/GPX/1/1"
SKYFIX_NS = "urn:skyfix:gpx:1"
#: values per fix, as in positions.csv and the fix message (t is the station clock)
VALUES = (
    "t",
    "t_gnss",
    "status",
    "lat",
    "lon",
    "alt_amsl_m",
    "alt_ellipsoid_m",
    "depth_m",
    "h_acc_m",
    "v_acc_m",
    "sigma_n_m",
    "sigma_e_m",
    "cov_ne_m2",
    "u",
    "v",
    "north_m",
    "east_m",
)
HEIGHTS = (
    "alt_amsl_m: metres above mean sea level (the UAV autopilot's GLOBAL_POSITION_INT alt, its geoid); "
    "alt_ellipsoid_m: metres above the WGS84 ellipsoid (alt_amsl_m plus the geoid separation GPS_RAW_INT "
    "gives), empty where the autopilot sent no alt_ellipsoid"
)


def _num(x) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def _value(fixes: Fixes, name: str, i: int):
    if name == "status":
        return str(fixes.status[i])
    return _num(getattr(fixes, "t_unix" if name == "t" else name)[i])


def _time(fixes: Fixes, i: int) -> tuple[str, str]:
    """ISO 8601 UTC of frame ``i`` and which clock it comes from."""
    t_gnss = fixes.t_gnss[i]
    t, source = (t_gnss, "gnss") if math.isfinite(t_gnss) else (fixes.t_unix[i], "station")
    return datetime.fromtimestamp(float(t), UTC).isoformat(timespec="milliseconds").replace(
        "+00:00", "Z"
    ), source


def _text(x: float | None, digits: int = 4) -> str:
    return "" if x is None else f"{x:.{digits}f}".rstrip("0").rstrip(".")


def _coord(x: float) -> str:
    return f"{x:.9f}"


def to_geojson(fixes: Fixes, name: str) -> str:
    features = []
    for i in range(len(fixes)):
        props = {k: _value(fixes, k, i) for k in VALUES}
        props["time"], props["time_source"] = _time(fixes, i)
        geometry = None
        if fixes.status[i] == "ok":
            z = _num(fixes.alt_ellipsoid_m[i])
            coords = [round(float(fixes.lon[i]), 9), round(float(fixes.lat[i]), 9)]
            geometry = {
                "type": "Point",
                "coordinates": coords if z is None else [*coords, round(z, 4)],
            }
        features.append({"type": "Feature", "geometry": geometry, "properties": props})
    doc = {"type": "FeatureCollection", "name": name, "heights": HEIGHTS, "features": features}
    return json.dumps(doc, allow_nan=False, ensure_ascii=False) + "\n"


def _sub(parent, tag: str, text: str | None = None, **attrib) -> ET.Element:
    el = ET.SubElement(parent, tag, attrib)
    if text is not None:
        el.text = text
    return el


def _xml(root: ET.Element) -> str:
    ET.indent(root, space=" ")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def _summary(fixes: Fixes) -> str:
    ok = int(np.sum(fixes.status == "ok"))
    return f"{len(fixes)} frames, {ok} with a fix. {HEIGHTS}."


def to_kml(fixes: Fixes, name: str) -> str:
    k = f"{{{KML_NS}}}"
    ET.register_namespace("", KML_NS)
    root = ET.Element(f"{k}kml")
    doc = _sub(root, f"{k}Document")
    _sub(doc, f"{k}name", name)
    _sub(doc, f"{k}description", _summary(fixes))
    style = _sub(doc, f"{k}Style", id="fix")
    icon = _sub(style, f"{k}IconStyle")
    _sub(icon, f"{k}color", "ff00ff55")
    _sub(icon, f"{k}scale", "0.5")
    _sub(
        _sub(icon, f"{k}Icon"),
        f"{k}href",
        "http://maps.google.com/mapfiles/kml/shapes/shaded_dot.png",
    )
    _sub(_sub(style, f"{k}LabelStyle"), f"{k}scale", "0")
    _sub(_sub(_sub(doc, f"{k}Style", id="track"), f"{k}LineStyle"), f"{k}color", "ff00aaff")
    schema = _sub(doc, f"{k}Schema", name="fix", id="fix_schema")
    for v in VALUES:
        _sub(schema, f"{k}SimpleField", name=v, type="string" if v == "status" else "double")

    fix_folder = _sub(doc, f"{k}Folder")
    _sub(fix_folder, f"{k}name", "fixes")
    track_folder = _sub(doc, f"{k}Folder")
    _sub(track_folder, f"{k}name", "track")
    gap_folder = _sub(doc, f"{k}Folder")
    _sub(gap_folder, f"{k}name", "no fix")
    for start, end, word in runs(fixes.status):
        if word != "ok":
            pm = _sub(gap_folder, f"{k}Placemark")
            _sub(pm, f"{k}name", f"{word}: {end - start} frames")
            span = _sub(pm, f"{k}TimeSpan")
            _sub(span, f"{k}begin", _time(fixes, start)[0])
            _sub(span, f"{k}end", _time(fixes, end - 1)[0])
            continue
        line = _sub(track_folder, f"{k}Placemark")
        _sub(line, f"{k}styleUrl", "#track")
        ls = _sub(line, f"{k}LineString")
        _sub(ls, f"{k}tessellate", "1")
        _sub(ls, f"{k}altitudeMode", "clampToGround")
        coords = []
        for i in range(start, end):
            xyz = f"{_coord(fixes.lon[i])},{_coord(fixes.lat[i])},{_text(_num(fixes.alt_amsl_m[i])) or 0}"
            coords.append(xyz)
            pm = _sub(fix_folder, f"{k}Placemark")
            _sub(_sub(pm, f"{k}TimeStamp"), f"{k}when", _time(fixes, i)[0])
            _sub(pm, f"{k}styleUrl", "#fix")
            data = _sub(_sub(pm, f"{k}ExtendedData"), f"{k}SchemaData", schemaUrl="#fix_schema")
            for v in VALUES:
                value = _value(fixes, v, i)
                if value is not None:
                    _sub(data, f"{k}SimpleData", value if v == "status" else repr(value), name=v)
            point = _sub(pm, f"{k}Point")
            _sub(point, f"{k}altitudeMode", "clampToGround")
            _sub(point, f"{k}coordinates", xyz)
        if len(coords) == 1:
            coords.append(coords[0])  # a LineString needs two points
        _sub(ls, f"{k}coordinates", " ".join(coords))
    return _xml(root)


def to_gpx(fixes: Fixes, name: str) -> str:
    g, s = f"{{{GPX_NS}}}", f"{{{SKYFIX_NS}}}"
    ET.register_namespace("", GPX_NS)
    ET.register_namespace("skyfix", SKYFIX_NS)
    root = ET.Element(f"{g}gpx", version="1.1", creator="skyfix")
    meta = _sub(root, f"{g}metadata")
    _sub(meta, f"{g}name", name)
    _sub(
        meta,
        f"{g}desc",
        _summary(fixes) + " hdop and vdop are the 1-sigma horizontal and vertical accuracies "
        "in metres.",
    )
    trk = _sub(root, f"{g}trk")
    _sub(trk, f"{g}name", name)
    for start, end, word in runs(fixes.status):
        if word != "ok":
            continue
        seg = _sub(trk, f"{g}trkseg")
        for i in range(start, end):
            pt = _sub(seg, f"{g}trkpt", lat=_coord(fixes.lat[i]), lon=_coord(fixes.lon[i]))
            amsl, ell = _num(fixes.alt_amsl_m[i]), _num(fixes.alt_ellipsoid_m[i])
            if amsl is not None:
                _sub(pt, f"{g}ele", _text(amsl))
            _sub(pt, f"{g}time", _time(fixes, i)[0])
            if amsl is not None and ell is not None:
                _sub(pt, f"{g}geoidheight", _text(ell - amsl))
            for tag, v in (("hdop", fixes.h_acc_m[i]), ("vdop", fixes.v_acc_m[i])):
                if _num(v) is not None:
                    _sub(pt, f"{g}{tag}", _text(_num(v)))
            ext = _sub(pt, f"{g}extensions")
            for v in VALUES:
                value = _value(fixes, v, i)
                if v not in ("lat", "lon") and value is not None:
                    _sub(ext, f"{s}{v}", value if v == "status" else repr(value))
    return _xml(root)


def to_csv(fixes: Fixes, name: str) -> str:
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow(("time", "time_source", *VALUES))
    for i in range(len(fixes)):
        cells = []
        for v in VALUES:
            value = _value(fixes, v, i)
            cells.append(value if v == "status" else "" if value is None else repr(value))
        w.writerow((*_time(fixes, i), *cells))
    return out.getvalue()


WRITERS = {"geojson": to_geojson, "kml": to_kml, "gpx": to_gpx, "csv": to_csv}


def positions_path(path: Path) -> Path:
    """positions.csv of a session or output folder, or the file itself."""
    if path.is_dir():
        found = path / "positions.csv"
        if not found.is_file():
            raise SessionError(
                f"{found}: missing (a recorded session has one; for others run "
                f"`skyfix process {path} --out DIR` and export DIR)"
            )
        return found
    if not path.is_file():
        raise SessionError(f"{path}: no such session folder or positions.csv")
    return path


def export(path, fmt: str, out=None) -> tuple[Path, Fixes]:
    """Write the export; returns where it went and the fixes."""
    src = positions_path(Path(path))
    fixes = read_positions_csv(src)
    name = src.parent.resolve().name
    dest = Path(out) if out else src.with_name("fixes" + FORMATS[fmt])
    if dest.resolve() == src.resolve():
        raise SessionError(f"{dest}: is the positions.csv being exported; choose another --out")
    text = WRITERS[fmt](fixes, name)
    tmp = dest.with_name(dest.name + ".partial")
    try:
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, dest)
    except OSError as e:
        raise SessionError(f"{dest}: cannot write: {e.strerror or e}") from None
    return dest, fixes


#: how a QGIS project opens each export: (provider, the source after the file's path, geometry)
QGIS_LAYERS = {
    "geojson": ("ogr", "", "Point"),
    "kml": ("ogr", "|layername=track", "Line"),
    "gpx": ("ogr", "|layername=tracks", "Line"),
    "csv": (
        "delimitedtext",
        "?type=csv&xField=lon&yField=lat&crs=EPSG:4326&geomType=point",
        "Point",
    ),
}


def _layer_id(name: str) -> str:
    """A QGIS layer id: the name and a UUID (QGIS replaces a bare name with a new id, unlinking the layer tree)."""
    return f"{name}_{uuid.uuid5(uuid.NAMESPACE_URL, 'urn:skyfix:qgis:' + name)}".replace("-", "_")


def _relative(target: Path, base: Path) -> str:
    return "./" + Path(os.path.relpath(target.resolve(), base.resolve())).as_posix()


def _srs(parent: ET.Element, epsg: int) -> None:
    """A QGIS ``<spatialrefsys>`` of EPSG ``epsg``: its WKT (what QGIS reads when no internal id is given), PROJ
    string and authority id."""
    from rasterio.crs import CRS

    crs = CRS.from_epsg(epsg)
    srs = _sub(parent, "spatialrefsys")
    _sub(srs, "wkt", crs.to_wkt())
    _sub(srs, "proj4", crs.to_proj4())
    _sub(srs, "srid", str(epsg))
    _sub(srs, "authid", f"EPSG:{epsg}")
    _sub(srs, "description", crs.to_wkt().split('"')[1])  # the name: WKT's first quoted text
    _sub(srs, "geographicflag", "true" if crs.is_geographic else "false")


def _map_layer(
    layers, kind: str, layer_id: str, name: str, source: str, provider: str, epsg: int, **attrib
):
    layer = _sub(layers, "maplayer", type=kind, **attrib)
    _sub(layer, "id", layer_id)
    _sub(layer, "datasource", source)
    _sub(layer, "layername", name)
    _srs(_sub(layer, "srs"), epsg)
    _sub(layer, "provider", provider, encoding="UTF-8")


def qgis_project(qgs: Path, track: Path, fmt: str, mosaic: Path, name: str) -> str:
    """A QGIS project (``.qgs`` XML) for ``qgs``: the exported ``track`` (format ``fmt``, EPSG:4326) drawn over the
    ``mosaic`` GeoTIFF (in its own CRS, the project's too), paths relative to the project's folder, the map
    opening on the mosaic's extent."""
    import rasterio

    with rasterio.open(mosaic) as d:
        epsg, bounds = d.crs.to_epsg(), d.bounds
    if epsg is None:
        raise SessionError(
            f"{mosaic}: its CRS has no EPSG code ({d.crs}); QGIS project not written"
        )
    provider, suffix, geometry = QGIS_LAYERS[fmt]
    base = qgs.parent
    track_source = _relative(track, base) + suffix
    if provider == "delimitedtext":
        track_source = "file:" + track_source
    root = ET.Element("qgis", projectname=name, version="3.22.0-skyfix")
    _sub(root, "title", f"{name}: the track over the bottom's mosaic")
    _srs(_sub(root, "projectCrs"), epsg)
    tree = _sub(root, "layer-tree-group")
    for layer_id, label, source, prov in (
        (_layer_id("track"), f"{name} track ({fmt})", track_source, provider),
        (_layer_id("mosaic"), "mosaic", _relative(mosaic, base), "gdal"),
    ):  # the first is drawn on top
        _sub(
            tree,
            "layer-tree-layer",
            id=layer_id,
            name=label,
            source=source,
            providerKey=prov,
            checked="Qt::Checked",
            expanded="1",
        )
    canvas = _sub(root, "mapcanvas", name="theMapCanvas")
    _sub(canvas, "units", "meters")
    extent = _sub(canvas, "extent")
    for tag, value in zip(("xmin", "ymin", "xmax", "ymax"), bounds, strict=True):
        _sub(extent, tag, repr(float(value)))
    _srs(_sub(canvas, "destinationsrs"), epsg)
    layers = _sub(root, "projectlayers")
    _map_layer(
        layers,
        "vector",
        _layer_id("track"),
        f"{name} track ({fmt})",
        track_source,
        provider,
        4326,
        geometry=geometry,
    )
    _map_layer(
        layers, "raster", _layer_id("mosaic"), "mosaic", _relative(mosaic, base), "gdal", epsg
    )
    props = _sub(root, "properties")
    _sub(_sub(props, "Paths"), "Absolute", "false", type="bool")
    # without it QGIS reads a project as one without a CRS (no reprojection of the layers)
    _sub(_sub(props, "SpatialRefSys"), "ProjectionsEnabled", "1", type="int")
    return (
        "<!DOCTYPE qgis PUBLIC 'http://mrcc.com/qgis.dtd' 'SYSTEM'>\n"
        + _xml(root).split("\n", 1)[1]
    )


def map_mosaic(
    src: Path, dest: Path, mosaic=None, session=None, floor_depth_m=None, progress=False
) -> Path:
    """The mosaic a project shows: ``mosaic`` when given, else ``mosaic.tif`` beside the export ``dest``, made there
    when missing (:func:`groundstation.offline.mosaic.mosaic_of`) from ``session`` (default: the folder of the
    positions.csv ``src``, a recorded session), the UUV left out around ``src``'s tracked pixels, the floor at
    ``floor_depth_m`` or estimated from the bottom."""
    from groundstation.offline.mosaic import NAME, mosaic_of

    if mosaic is not None:
        if not Path(mosaic).is_file():
            raise SessionError(f"--mosaic {mosaic}: no such file")
        return Path(mosaic)
    found = dest.parent / NAME
    if found.is_file():
        return found
    folder = Path(session) if session else src.parent
    if not (folder / "session.toml").is_file():
        raise SessionError(
            f"{found}: missing, and {folder} is not a session to make it from "
            "(give --session DIR, or --mosaic PATH, or run skyfix mosaic)"
        )
    mosaic_of(
        folder,
        dest.parent,
        floor_depth_m,
        pose_from_bottom="off" if floor_depth_m is not None else "auto",
        positions=src,
        progress=progress,
    )
    return found


def write_project(src: Path, dest: Path, fmt: str, mosaic: Path) -> Path:
    """``<export's file name>.qgs`` beside the export ``dest`` (``fixes.geojson.qgs``: one per format,
    :func:`qgis_project`); returns its path."""
    qgs = dest.with_name(dest.name + ".qgs")
    name = src.parent.resolve().name
    qgs.write_text(qgis_project(qgs, dest, fmt, mosaic, name), encoding="utf-8")
    return qgs


def run(args) -> int:
    dest, fixes = export(args.session, args.format, args.out)
    ok = int(np.sum(fixes.status == "ok"))
    print(f"{len(fixes)} frames, {ok} with a fix -> {dest}")
    if args.qgis or args.mosaic:
        src = positions_path(Path(args.session))
        mosaic = map_mosaic(
            src, dest, args.mosaic, args.session_dir, args.floor_depth_m, not args.quiet
        )
        qgs = write_project(src, dest, args.format, mosaic)
        print(f"QGIS project: the track over {mosaic} -> {qgs}")
    return 0


def register(subparsers, name: str, help: str | None = None) -> None:
    """Adds the subcommand ``name`` with its one-line ``help`` (both from :data:`groundstation.cli.COMMANDS`)."""
    p = subparsers.add_parser(
        name,
        help=help,
        description="Writes the fixes of positions.csv, with each fix's accuracy, status and heights "
        "(above mean sea level and above the WGS84 ellipsoid), for QGIS (any format), Google "
        "Earth (kml) or GPS tools (gpx).",
    )
    p.add_argument(
        "session",
        metavar="SESSION|positions.csv",
        help="a folder with positions.csv (a recorded session, skyfix process's output) or the file",
    )
    p.add_argument("--format", required=True, choices=FORMATS, help="output format")
    p.add_argument(
        "--out", metavar="FILE", help="output file (default: fixes.<format> next to positions.csv)"
    )
    p.add_argument(
        "--qgis",
        action="store_true",
        help="also write a QGIS project (FILE.qgs, e.g. fixes.geojson.qgs) showing the track over the bottom's "
        "mosaic: --mosaic, else mosaic.tif beside FILE, made there when missing (skyfix mosaic)",
    )
    p.add_argument(
        "--mosaic", metavar="PATH", help="the mosaic GeoTIFF the project shows (implies --qgis)"
    )
    p.add_argument(
        "--session",
        dest="session_dir",
        metavar="DIR",
        help="the session to make the mosaic from (default: positions.csv's folder)",
    )
    p.add_argument(
        "--floor-depth-m",
        type=float,
        default=None,
        metavar="M",
        help="the floor's depth for making the mosaic, m (default: estimated from the bottom)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)
