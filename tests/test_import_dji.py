"""``skyfix import --dji-csv ... --srt ...``: DJI flight records written here to the exporters' published column
layouts (dji-log-parser's ``csv.rs``, PhantomHelp's units in brackets) and camera SRTs to DJI's subtitle layout, from
a trajectory known in closed form; a real camera's SRT excerpt (``fixtures/dji``). Conventions are checked on
hand-worked cases through the localizer's own rotations, never the reader's arithmetic."""

from __future__ import annotations

import json
import math
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pytest
from live_helpers import ROOT
from test_import_flight import write_video

from groundstation.cli import main
from groundstation.offline.import_flight import import_flight
from groundstation.session import SessionError
from groundstation.session.dji import read_dji_csv, read_srt, srt_clock, srt_video_start
from groundstation.session.read import load_session
from groundstation.session.tlog import read_tlog
from localizer.attitude import R_ned_from_mount_orientation, euler_to_R
from localizer.geodesy import geodetic_to_ned

FIXTURES = Path(__file__).parent / "fixtures" / "dji"
# 2023-05-14T12:34:56.789Z (`date -u -d 2023-05-14T12:34:56Z +%s` = 1684067696)
T0_UNIX = 1684067696.789
LAT0, LON0, R_EARTH_M = 43.5, 16.4, 6_371_000.0
VIDEO_AT_S, FPS, FRAMES = 40.0, 30, 90  # the video's first frame 40 s into the record
ZONE_H, CAMERA_CLOCK_ERROR_S = 2.0, 0.3  # the camera's clock: local time UTC+2, 0.3 s fast
DJI_LOG_PARSER = [
    "CUSTOM.dateTime",
    "OSD.flyTime",
    "OSD.latitude",
    "OSD.longitude",
    "OSD.height",
    "OSD.heightMax",
    "OSD.vpsHeight",
    "OSD.altitude",
    "OSD.xSpeed",
    "OSD.ySpeed",
    "OSD.zSpeed",
    "OSD.pitch",
    "OSD.roll",
    "OSD.yaw",
    "OSD.flycState",
    "OSD.gpsNum",
    "GIMBAL.mode",
    "GIMBAL.pitch",
    "GIMBAL.roll",
    "GIMBAL.yaw",
    "GIMBAL.isPitchAtLimit",
    "CAMERA.isVideo",
]


def truth(t_s):
    """The flight at ``t_s`` s after T0: lat, lon (deg), height above take-off (m), roll, pitch, yaw, gimbal roll,
    pitch, yaw from North (deg). It flies north at 2 m/s, weaving 20 m east and west."""
    t_s = np.asarray(t_s, dtype=float)
    north, east = 2.0 * t_s, 20.0 * np.sin(t_s / 10.0)
    lat = LAT0 + np.degrees(north / R_EARTH_M)
    lon = LON0 + np.degrees(east / (R_EARTH_M * math.cos(math.radians(LAT0))))
    yaw = 30.0 * np.sin(t_s / 7.0)
    return (
        lat,
        lon,
        20.0 + 0.05 * t_s,
        3.0 * np.sin(t_s),
        np.full_like(t_s, -5.0),
        yaw,
        np.zeros_like(t_s),
        -60.0 + 10.0 * np.sin(t_s / 5.0),
        yaw + 15.0,
    )


def iso_utc(t_unix: float) -> str:
    return (
        datetime.fromtimestamp(t_unix, UTC)
        .isoformat(timespec="milliseconds")
        .replace("+00:00", "Z")
    )


def write_dji_csv(path: Path, t_s, columns=DJI_LOG_PARSER, edit=None) -> None:
    """dji-log-parser's layout: every listed column, the values of :func:`truth` (``edit(row_dict)`` may change
    cells)."""
    lat, lon, h, roll, pitch, yaw, g_roll, g_pitch, g_yaw = truth(t_s)
    lines = [",".join(columns)]
    for k, t in enumerate(np.asarray(t_s, dtype=float)):
        row = {
            "CUSTOM.dateTime": iso_utc(T0_UNIX + t),
            "OSD.flyTime": f"{t:.1f}",
            "OSD.latitude": repr(float(lat[k])),
            "OSD.longitude": repr(float(lon[k])),
            "OSD.height": f"{h[k]:.1f}",
            "OSD.altitude": f"{h[k] + 100.0:.1f}",
            "OSD.pitch": f"{pitch[k]:.1f}",
            "OSD.roll": f"{roll[k]:.1f}",
            "OSD.yaw": f"{yaw[k]:.1f}",
            "GIMBAL.pitch": f"{g_pitch[k]:.1f}",
            "GIMBAL.roll": f"{g_roll[k]:.1f}",
            "GIMBAL.yaw": f"{(g_yaw[k] + 180) % 360 - 180:.1f}",
            "OSD.flycState": "GPSAtti",
            "GIMBAL.mode": "YawFollow",
            "CAMERA.isVideo": "true",
        }
        if edit:
            edit(k, row)
        lines.append(",".join(row.get(c, "0") for c in columns))
    path.write_text("\n".join(lines) + "\n")


def write_srt(
    path: Path,
    frames: int = FRAMES,
    offset_s: float = ZONE_H * 3600 + CAMERA_CLOCK_ERROR_S,
    at_s: float = VIDEO_AT_S,
    where=truth,
) -> None:
    """DJI's modern SRT: one subtitle a frame, the camera's local clock ``offset_s`` ahead of UTC, positions and
    gimbal angles at the frame's true time rounded as the camera writes them."""
    out = []
    for i in range(frames):
        t_s = at_s + i / FPS
        lat, lon, h, *_, g_roll, g_pitch, g_yaw = (float(x) for x in where(t_s))
        a, b = (
            datetime.fromtimestamp(round(k * 1000 / FPS) / 1000, UTC).strftime("%H:%M:%S,%f")[:-3]
            for k in (i, i + 1)
        )
        clock = datetime.fromtimestamp(T0_UNIX + t_s + offset_s, UTC).strftime(
            "%Y-%m-%d %H:%M:%S.%f"
        )[:-3]
        out.append(
            f"{i + 1}\n{a} --> {b}\n"
            f'<font size="28">FrameCnt: {i + 1}, DiffTime: 33ms\n{clock}\n'
            f"[iso: 100] [shutter: 1/500.0] [fnum: 2.8] [ev: 0] [latitude: {lat:.6f}] [longitude: {lon:.6f}] "
            f"[rel_alt: {h:.3f} abs_alt: {h + 100:.3f}] [gb_yaw: {g_yaw:.1f} gb_pitch: {g_pitch:.1f} "
            f"gb_roll: {g_roll:.1f}] </font>\n"
        )
    path.write_text("\n".join(out))


@pytest.fixture
def calibration(tmp_path):
    cal = tmp_path / "cal.toml"
    cal.write_text(
        (ROOT / "deploy" / "calibration.toml")
        .read_text()
        .replace('attitude_source = "gimbal_device"', 'attitude_source = "mount_orientation"')
    )
    return cal


@pytest.fixture
def depth(tmp_path):
    path = tmp_path / "depth.csv"
    path.write_text("t,depth_m\n" + "".join(f"{T0_UNIX + s:.3f},1.5\n" for s in range(0, 120, 2)))
    return path


def test_a_record_and_srt_become_a_session_with_the_cameras_zone_found(
    tmp_path, calibration, depth
):
    """End to end through the command line: the video's start comes from the SRT, its clock's zone (UTC+2, and the
    0.3 s it runs fast) found from its track against the record's."""
    csv_path, srt, video, out = (
        tmp_path / "flight.csv",
        tmp_path / "DJI_0001.SRT",
        tmp_path / "DJI_0001.MP4",
        tmp_path / "session",
    )
    write_dji_csv(csv_path, np.arange(0, 1200) / 10.0)
    write_srt(srt)
    write_video(video, frames=FRAMES, fps=FPS, size=(320, 240))
    assert (
        main(
            [
                "import",
                "--dji-csv",
                str(csv_path),
                "--srt",
                str(srt),
                "--video",
                str(video),
                "--depth",
                str(depth),
                "--calibration",
                str(calibration),
                "--out",
                str(out),
                "--quiet",
            ]
        )
        == 0
    )
    report = json.loads((out / "import.json").read_text())
    print(
        f"\nzone {report['srt_utc_offset_h'] * 3600 - 7200:+.3f} s past UTC+2, residual "
        f"{report['srt_track_residual_m']} m, start {report['video_start_unix'] - T0_UNIX - VIDEO_AT_S:+.4f} s"
    )
    assert report["srt_utc_offset_h"] * 3600 == pytest.approx(
        ZONE_H * 3600 + CAMERA_CLOCK_ERROR_S, abs=0.03
    )
    assert (
        report["srt_utc_offset_found"]
        and report["srt_track_residual_m"] < 0.2
        and report["srt_frames"] == FRAMES
    )
    assert report["video_start_unix"] == pytest.approx(T0_UNIX + VIDEO_AT_S, abs=0.03)
    assert report["video_start_from"].startswith("the SRT's frame times") and report[
        "dji_csv"
    ] == str(csv_path)
    assert report["unix_minus_boot_s"] == pytest.approx(T0_UNIX, abs=1e-6)
    session = load_session(out)
    assert len(session.frames["t"]) == FRAMES
    assert session.frames["t"][1] - session.frames["t"][0] == pytest.approx(1 / FPS, abs=1e-4)
    kinds = {}
    for t_rec, m in read_tlog(out / "uav.tlog"):
        kinds[m.get_type()] = kinds.get(m.get_type(), 0) + 1
        if (
            m.get_type() == "MOUNT_ORIENTATION"
        ):  # the gimbal's yaw from North and against the nose: 15 deg apart
            assert m.yaw == pytest.approx(15.0, abs=0.11)
            assert m.time_boot_ms / 1000 + T0_UNIX == pytest.approx(t_rec, abs=1e-3)
        if m.get_type() == "SYSTEM_TIME":
            assert m.time_unix_usec / 1e6 - m.time_boot_ms / 1e3 == pytest.approx(T0_UNIX, abs=1e-3)
    assert kinds["ATTITUDE"] == kinds["MOUNT_ORIENTATION"] == kinds["GLOBAL_POSITION_INT"] == 1200
    assert kinds["GPS_RAW_INT"] == kinds["SYSTEM_TIME"] == 1200
    track = read_srt(srt)
    g_yaw, g_pitch = float(truth(VIDEO_AT_S)[8]), float(truth(VIDEO_AT_S)[7])
    assert (
        track.gimbal_ypr_deg[0] == pytest.approx([g_yaw, g_pitch, 0.0], abs=0.05)
        and track.frame[-1] == FRAMES - 1
    )


def test_dji_angles_mean_what_dji_says(tmp_path, calibration, depth):
    """Hand-worked: heading West is OSD.yaw −90 → ATTITUDE yaw −π/2, the nose along −East; the gimbal at pitch −30
    and yaw 0 (North) under that heading looks North and 30° down; at pitch −90 straight down."""
    csv_path = tmp_path / "flight.csv"

    def edit(k, row):
        row |= {
            "OSD.yaw": "-90.0",
            "OSD.roll": "0.0",
            "OSD.pitch": "0.0",
            "GIMBAL.roll": "0.0",
            "GIMBAL.yaw": "0.0",
            "GIMBAL.pitch": "-30.0" if k < 2 else "-90.0",
        }

    write_dji_csv(csv_path, [0.0, 0.1, 0.2, 0.3], edit=edit)
    import_flight(None, None, depth, calibration, tmp_path / "s", dji_csv=csv_path)
    msgs = read_tlog(tmp_path / "s" / "uav.tlog")
    att = next(m for _, m in msgs if m.get_type() == "ATTITUDE")
    assert att.yaw == pytest.approx(-math.pi / 2, abs=1e-6)
    assert euler_to_R(att.roll, att.pitch, att.yaw) @ [1, 0, 0] == pytest.approx(
        [0, -1, 0], abs=1e-6
    )
    mounts = [m for _, m in msgs if m.get_type() == "MOUNT_ORIENTATION"]
    axes = [
        R_ned_from_mount_orientation(m.roll, m.pitch, m.yaw, att.yaw) @ [1, 0, 0] for m in mounts
    ]
    assert axes[0] == pytest.approx([math.cos(math.radians(30)), 0, 0.5], abs=1e-6)
    assert axes[3] == pytest.approx([0, 0, 1], abs=1e-6)
    assert (mounts[0].yaw, mounts[0].yaw_absolute) == (90.0, 0.0)


PHANTOMHELP = [
    "CUSTOM.date [local]",
    "CUSTOM.updateTime [local]",
    "OSD.flyTime [s]",
    "OSD.latitude",
    "OSD.longitude",
    "OSD.height [ft]",
    "OSD.altitude [ft]",
    "OSD.pitch",
    "OSD.roll",
    "OSD.yaw",
    "OSD.yaw [360]",
    "GIMBAL.pitch",
    "GIMBAL.roll",
    "GIMBAL.yaw",
    "GIMBAL.yaw [360]",
    "BATTERY.voltage [V]",
]
PH_ROW = [
    "5/14/2023",
    "{time}",
    "0.0",
    "43.5",
    "16.4",
    "100.0",
    "328.084",
    "-5.0",
    "0.0",
    "-90.0",
    "270.0",
    "-90.0",
    "0.0",
    "-90.0",
    "270.0",
    "15.2",
]


def write_phantomhelp(
    path: Path, headers=PHANTOMHELP, rows=(("2:34:56.78 PM", "2:34:56.88 PM"))
) -> None:
    lines = ["sep=,", ",".join(headers)]
    lines += [",".join(PH_ROW).replace("{time}", t) for t in rows]
    path.write_text("\n".join(lines) + "\n")


def test_phantomhelp_feet_and_local_times(tmp_path):
    path = tmp_path / "DJIFlightRecord_2023-05-14_[14-34-56].csv"
    write_phantomhelp(path)
    flight = read_dji_csv(path, utc_offset_h=2.0)
    # 14:34:56.78 at UTC+2
    assert flight.unix_minus_boot_s == pytest.approx(1684067696.78, abs=1e-6)
    # ft → m
    assert flight.pos[0, 4] == pytest.approx(30.48) and flight.pos[0, 3] == pytest.approx(
        100.0, abs=1e-4
    )
    assert math.degrees(flight.att[0, 3]) == pytest.approx(-90.0) and flight.mnt[
        0, 3
    ] == pytest.approx(0.0)
    with pytest.raises(
        SessionError, match=r"CUSTOM.updateTime \[local\]: local times .* --dji-csv-utc-offset-h"
    ):
        read_dji_csv(path)


@pytest.mark.parametrize(
    "header, message",
    [
        ("OSD.height [yd]", r"column 'OSD.height \[yd\]': unknown unit 'yd'"),
        ("OSD.height", r"column 'OSD.height': no unit, while the other headers carry theirs"),
        ("OSD.roll [rad]", r"column 'OSD.roll \[rad\]': unknown unit 'rad'"),
    ],
)
def test_a_unit_that_is_missing_or_unknown_is_an_error_naming_the_column(tmp_path, header, message):
    path = tmp_path / "ph.csv"
    write_phantomhelp(
        path, [header if h.split(" [")[0] == header.split(" [")[0] else h for h in PHANTOMHELP]
    )
    with pytest.raises(SessionError, match=rf"ph.csv: {message}"):
        read_dji_csv(path, utc_offset_h=0.0)


def test_bad_records_are_one_line_errors_naming_file_column_and_value(
    tmp_path, calibration, depth, capsys
):
    missing = tmp_path / "missing.csv"
    write_dji_csv(missing, [0.0, 0.1], columns=[c for c in DJI_LOG_PARSER if c != "OSD.yaw"])
    with pytest.raises(SessionError, match=r"missing.csv: no column OSD.yaw"):
        read_dji_csv(missing)
    garbage = tmp_path / "garbage.csv"
    write_dji_csv(
        garbage,
        [0.0, 0.1, 0.2],
        edit=lambda k, row: row.update({"OSD.latitude": "abc"} if k == 2 else {}),
    )
    with pytest.raises(SessionError, match=r"garbage.csv:4: OSD.latitude = 'abc': not a number"):
        read_dji_csv(garbage)
    naive = tmp_path / "naive.csv"
    write_dji_csv(
        naive,
        [0.0, 0.1],
        edit=lambda k, row: row.update({"CUSTOM.dateTime": "2023-05-14 12:34:56"}),
    )
    with pytest.raises(
        SessionError, match=r"naive.csv:2: CUSTOM.dateTime = '2023-05-14 12:34:56': no time zone"
    ):
        read_dji_csv(naive)
    assert (
        main(
            [
                "import",
                "--dji-csv",
                str(garbage),
                "--depth",
                str(depth),
                "--calibration",
                str(calibration),
                "--out",
                str(tmp_path / "s"),
            ]
        )
        == 2
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "garbage.csv:4: OSD.latitude = 'abc'" in err[0]
    with pytest.raises(SystemExit):  # exactly one flight record
        main(
            [
                "import",
                "--dji-csv",
                str(garbage),
                "--dataflash",
                "x.bin",
                "--depth",
                str(depth),
                "--calibration",
                str(calibration),
                "--out",
                str(tmp_path / "t"),
            ]
        )


def test_repeated_backwards_and_empty_rows_are_dropped_with_one_warning_each(tmp_path):
    path = tmp_path / "dirty.csv"
    t = [0.0, 0.1, 0.2, 0.3, 0.4, 0.4, 0.35, 0.5, 0.6, 0.7, 0.7]
    write_dji_csv(path, t, edit=lambda k, row: row.update({"OSD.roll": ""} if k == 7 else {}))
    flight = read_dji_csv(path)
    assert flight.att[:, 0] == pytest.approx([0.0, 0.1, 0.2, 0.3, 0.4, 0.6, 0.7], abs=1e-6)
    assert len(flight.warnings) == 3
    (repeated,) = (w for w in flight.warnings if "repeating" in w)
    (backwards,) = (w for w in flight.warnings if "earlier" in w)
    (empty,) = (w for w in flight.warnings if "empty" in w)
    assert (
        "2 rows" in repeated
        and "line 7" in repeated
        and "1 rows" in backwards
        and "line 8" in backwards
    )
    assert "line 9" in empty


def test_a_real_cameras_srt_excerpt():
    """DJI Air 2S (DJI_SRT_Parser's sample, MIT): ``SrtCnt``, the ``,ms,µs`` clock, ``[altitude: ...]`` only."""
    track = read_srt(FIXTURES / "air2s_excerpt.SRT")
    assert list(track.frame) == [0, 1, 2] and track.t_video_s == pytest.approx([0.0, 0.033, 0.066])
    # 2022-08-07 13:40:40,774,808
    assert track.t_camera_s[0] == pytest.approx(1659879640 + 0.774808, abs=1e-6)
    assert track.t_camera_s[2] - track.t_camera_s[1] == pytest.approx(0.033367, abs=1e-6)
    assert (track.lat_deg[0], track.lon_deg[1]) == (41.424724, 2.234147)
    assert np.isnan(track.rel_alt_m).all() and np.isnan(track.gimbal_ypr_deg).all()


def test_srt_errors_and_a_given_zone(tmp_path):
    bad = tmp_path / "bad.SRT"
    write_srt(bad, frames=3)
    bad.write_text(bad.read_text().replace("[latitude: ", "[latitude: x", 1))
    with pytest.raises(SessionError, match=r"bad.SRT:1: latitude = 'x43.5.*': not a number"):
        read_srt(bad)
    csv_path, srt = tmp_path / "f.csv", tmp_path / "a.SRT"
    write_dji_csv(csv_path, np.arange(0, 1200) / 10.0)
    write_srt(srt)
    flight = read_dji_csv(csv_path)
    given = srt_clock(read_srt(srt), flight, utc_offset_h=2.0)
    # 0.3 s of a 2-2.9 m/s track: the residual says the given zone leaves the clock's error in
    assert not given.found and given.offset_s == 7200.0 and 0.5 < given.residual_m < 1.0
    with pytest.raises(
        SessionError, match=r"at UTC\+5 h its frames fall outside the flight record"
    ):
        srt_clock(read_srt(srt), flight, utc_offset_h=5.0)


def test_a_hover_fits_many_zones_and_is_refused(tmp_path):
    """A record of 3 h hovering in one place: the SRT's track fits every zone within it alike."""
    csv_path, srt = tmp_path / "hover.csv", tmp_path / "h.SRT"
    write_dji_csv(
        csv_path,
        np.arange(0, 3 * 3600, 2.0),
        edit=lambda k, row: row.update(
            {"OSD.latitude": str(LAT0), "OSD.longitude": str(LON0), "OSD.height": "20.0"}
        ),
    )
    write_srt(srt, offset_s=3600.0, at_s=5400.0, where=lambda t: (LAT0, LON0, 20.0, *truth(t)[3:]))
    with pytest.raises(
        SessionError,
        match=r"h.SRT: its track fits the record at UTC.* alike: give --srt-utc-offset-h",
    ):
        srt_clock(read_srt(srt), read_dji_csv(csv_path))


# Airdata's CSV export: its header as Airdata writes it (verri/m30ttools README; the ``(feet)`` variant in the
# AirDataUAV package's README and MickWest/sitrec's notes), with the leading spaces some of its names carry.
AIRDATA = [
    "time(millisecond)",
    "datetime(utc)",
    "latitude",
    "longitude",
    "height_above_takeoff(feet)",
    "height_above_ground_at_drone_location(feet)",
    "ground_elevation_at_drone_location(feet)",
    "altitude_above_seaLevel(feet)",
    "height_sonar(feet)",
    "speed(mph)",
    "distance(feet)",
    "mileage(feet)",
    "satellites",
    "gpslevel",
    "voltage(v)",
    "max_altitude(feet)",
    "max_ascent(feet)",
    "max_speed(mph)",
    "max_distance(feet)",
    " xSpeed(mph)",
    " ySpeed(mph)",
    " zSpeed(mph)",
    " compass_heading(degrees)",
    " pitch(degrees)",
    " roll(degrees)",
    "isPhoto",
    "isVideo",
    "rc_elevator",
    "rc_aileron",
    "rc_throttle",
    "rc_rudder",
    "rc_elevator(percent)",
    "rc_aileron(percent)",
    "rc_throttle(percent)",
    "rc_rudder(percent)",
    "gimbal_heading(degrees)",
    "gimbal_pitch(degrees)",
    "gimbal_roll(degrees)",
    "battery_percent",
    "voltageCell1",
    "voltageCell2",
    "voltageCell3",
    "voltageCell4",
    "voltageCell5",
    "voltageCell6",
    "current(A)",
    "battery_temperature(f)",
    "altitude(feet)",
    "ascent(feet)",
    "flycStateRaw",
    "flycState",
    "message",
]
# Four rows 100 ms apart, 15.6 s into the record; the true UTC of the first 12:34:56.750, so datetime(utc) (whole
# seconds) reads :56, :56, :56, :57. Heading West (270), the gimbal looking North (0) 30° down; then heading 350,
# the gimbal at 10, straight down. The second position 0.0001° north and east of the first.
AIRDATA_ROWS = [
    {
        "time(millisecond)": "15600",
        "datetime(utc)": "2023-05-14 12:34:56",
        "latitude": "43.5",
        "longitude": "16.4",
        "height_above_takeoff(feet)": "100",
        "altitude_above_seaLevel(feet)": "1000",
        " compass_heading(degrees)": "270",
        " pitch(degrees)": "0",
        " roll(degrees)": "0",
        "gimbal_heading(degrees)": "0",
        "gimbal_pitch(degrees)": "-30",
        "gimbal_roll(degrees)": "0",
    },
    {
        "time(millisecond)": "15700",
        "datetime(utc)": "2023-05-14 12:34:56",
        "latitude": "43.5001",
        "longitude": "16.4001",
    },
    {
        "time(millisecond)": "15800",
        "datetime(utc)": "2023-05-14 12:34:56",
        " compass_heading(degrees)": "350",
        "gimbal_heading(degrees)": "10",
        "gimbal_pitch(degrees)": "-90",
    },
    {"time(millisecond)": "15900", "datetime(utc)": "2023-05-14 12:34:57"},
]


def write_airdata(path: Path, headers=AIRDATA, rows=AIRDATA_ROWS, edit=None) -> None:
    """Airdata's layout: each row the one before with ``rows``' cells changed (``edit(k, row)`` may change row
    ``k``'s, that row's only)."""
    lines, row = [",".join(headers)], {h: "0" for h in headers}
    for k, change in enumerate(rows):
        row = row | change
        out = dict(row)
        if edit:
            edit(k, out)
        lines.append(",".join(out.get(h, "0") for h in headers))
    path.write_text("\n".join(lines) + "\n")


def test_airdata_layout_hand_worked(tmp_path, calibration, depth):
    path = tmp_path / "May-14th-2023-12-34PM-Flight-Airdata.csv"
    write_airdata(path)
    flight = read_dji_csv(path)
    # time(millisecond) 15600..15900 against :56 :56 :56 :57 → 15.6 s into the record is 12:34:56.70–.80
    t56 = 1684067696.0  # 2023-05-14T12:34:56Z
    assert flight.unix_minus_boot_s == pytest.approx(t56 + 0.75, abs=1e-6)
    assert flight.unix_minus_boot_sigma_s == pytest.approx(0.05, abs=1e-6)
    # (UNIX-time arithmetic: 0.2 µs)
    assert flight.att[:, 0] == pytest.approx([0.0, 0.1, 0.2, 0.3], abs=1e-6)
    # 1000 ft AMSL, 100 ft above take-off
    assert flight.pos[0, 1:] == pytest.approx([43.5, 16.4, 304.8, 30.48])
    # 0.0001° of latitude and longitude at 43.5° N: 11.1 m north (a meridian degree 111.1 km there), 8.1 m east
    # (a parallel degree 80.8 km: 111.3 km · cos 43.5°)
    n, e, _ = geodetic_to_ned(flight.pos[1, 1], flight.pos[1, 2], 0.0, 43.5, 16.4, 0.0)
    assert (float(n), float(e)) == pytest.approx((11.11, 8.08), abs=0.02)
    # heading 270 → yaw −90; gimbal North, relative to the nose: 0 − 270 → +90; heading 350 → −10, gimbal 10 → +20
    assert np.degrees(flight.att[:, 3]) == pytest.approx([-90.0, -90.0, -10.0, -10.0])
    assert flight.mnt[:, 3] == pytest.approx([90.0, 90.0, 20.0, 20.0]) and flight.mnt[
        :, 4
    ] == pytest.approx([0.0, 0.0, 10.0, 10.0])
    import_flight(None, None, depth, calibration, tmp_path / "s", dji_csv=path)
    msgs = read_tlog(tmp_path / "s" / "uav.tlog")
    att = [m for _, m in msgs if m.get_type() == "ATTITUDE"]
    assert euler_to_R(att[0].roll, att[0].pitch, att[0].yaw) @ [1, 0, 0] == pytest.approx(
        [0, -1, 0], abs=1e-6
    )
    mounts = [m for _, m in msgs if m.get_type() == "MOUNT_ORIENTATION"]
    axis = R_ned_from_mount_orientation(
        mounts[0].roll, mounts[0].pitch, mounts[0].yaw, att[0].yaw
    ) @ [1, 0, 0]
    assert axis == pytest.approx([math.cos(math.radians(30)), 0, 0.5], abs=1e-6)  # North, 30° down
    axis = R_ned_from_mount_orientation(
        mounts[2].roll, mounts[2].pitch, mounts[2].yaw, att[2].yaw
    ) @ [1, 0, 0]
    assert axis == pytest.approx([0, 0, 1], abs=1e-6)
    gpi = next(m for _, m in msgs if m.get_type() == "GLOBAL_POSITION_INT")
    assert (gpi.alt, gpi.relative_alt) == (304800, 30480)


def test_airdata_in_meters_and_a_clock_with_fractions(tmp_path):
    path = tmp_path / "m.csv"
    headers = [h.replace("(feet)", "(meters)") for h in AIRDATA]
    rows = [{k.replace("(feet)", "(meters)"): v for k, v in r.items()} for r in AIRDATA_ROWS]
    utc = [
        "2023-05-14 12:34:56.75",
        "2023-05-14 12:34:56.85",
        "2023-05-14 12:34:56.95",
        "2023-05-14 12:34:57.05",
    ]
    write_airdata(path, headers, rows, edit=lambda k, row: row.update({"datetime(utc)": utc[k]}))
    flight = read_dji_csv(path)
    assert flight.pos[0, 3:] == pytest.approx([1000.0, 100.0])
    assert (
        flight.unix_minus_boot_s == pytest.approx(1684067696.75, abs=1e-6)
        and flight.unix_minus_boot_sigma_s < 1e-6
    )


@pytest.mark.parametrize(
    "change, message",
    [
        (
            ("height_above_takeoff(feet)", "height_above_takeoff"),
            r"column 'height_above_takeoff': no unit",
        ),
        (
            ("altitude_above_seaLevel(feet)", "altitude_above_seaLevel(yards)"),
            r"column 'altitude_above_seaLevel\(yards\)': unknown unit 'yards'",
        ),
        (
            (" pitch(degrees)", " pitch(radians)"),
            r"column 'pitch\(radians\)': unknown unit 'radians'",
        ),
        (
            ("gimbal_heading(degrees)", "gimbal_yaw(degrees)"),
            r"no column gimbal_heading \(Airdata's CSV export has it\)",
        ),
    ],
)
def test_airdata_columns_wrong_or_missing_are_errors_naming_them(tmp_path, change, message):
    path = tmp_path / "a.csv"
    headers = [change[1] if h == change[0] else h for h in AIRDATA]
    write_airdata(
        path,
        headers,
        [{change[1] if k == change[0] else k: v for k, v in r.items()} for r in AIRDATA_ROWS],
    )
    with pytest.raises(SessionError, match=rf"a.csv: {message}"):
        read_dji_csv(path)


def test_airdata_bad_cells_are_errors_and_empty_rows_dropped(tmp_path):
    path = tmp_path / "a.csv"
    write_airdata(
        path, edit=lambda k, row: row.update({" pitch(degrees)": "abc"} if k == 2 else {})
    )
    with pytest.raises(SessionError, match=r"a.csv:4: pitch\(degrees\) = 'abc': not a number"):
        read_dji_csv(path)
    write_airdata(
        path, edit=lambda k, row: row.update({"datetime(utc)": "14/05/2023"} if k == 1 else {})
    )
    with pytest.raises(
        SessionError, match=r"a.csv:3: datetime\(utc\) = '14/05/2023': not a date and time"
    ):
        read_dji_csv(path)
    # 12:34:58 at 15.9 s: ≥ 12:34:58 − 15.9 s = 12:34:42.1 at time 0, while 12:34:56 at 15.8 s puts it before :41.2
    write_airdata(
        path,
        edit=lambda k, row: row.update({"datetime(utc)": "2023-05-14 12:34:58"} if k == 3 else {}),
    )
    with pytest.raises(
        SessionError,
        match=r"a.csv:5: datetime\(utc\) and time\(millisecond\) disagree with the "
        r"other rows' by 0.900 s beyond its 1 s resolution",
    ):
        read_dji_csv(path)
    write_airdata(
        path,
        edit=lambda k, row: row.update(
            {"latitude": "nan", "gimbal_roll(degrees)": ""} if k == 1 else {}
        ),
    )
    flight = read_dji_csv(path)
    assert flight.att[:, 0] == pytest.approx([0.0, 0.2, 0.3]) and len(flight.warnings) == 1
    assert "1 rows with an empty or nan value dropped (the first at line 3)" in flight.warnings[0]
    write_airdata(path, edit=lambda k, row: row.update({"datetime(utc)": ""}))
    with pytest.raises(
        SessionError, match=r"a.csv: no row with both datetime\(utc\) and time\(millisecond\)"
    ):
        read_dji_csv(path)


# DJI's older SRT (DJI_SRT_Parser's samples/sample2.SRT, MIT: a Phantom/Mavic at Uluru, 131.17° E 25.21° S, so
# GPS(longitude, latitude, ...)); its first three subtitles.
OLD_SRT = """1
00:00:01,000 --> 00:00:02,000
HOME(131.1660,-25.2088) 2017.07.29 15:18:50
GPS(131.1660,-25.2088,14) BAROMETER:0.0
ISO:100 Shutter:60 EV: Fnum:2.2 

2
00:00:02,000 --> 00:00:03,000
HOME(131.1660,-25.2088) 2017.07.29 15:18:51
GPS(131.1660,-25.2088,14) BAROMETER:0.0
ISO:100 Shutter:60 EV: Fnum:2.2 

3
00:00:03,000 --> 00:00:04,000
HOME(131.1660,-25.2088) 2017.07.29 15:18:52
GPS(131.1660,-25.2088,14) BAROMETER:0.0
ISO:100 Shutter:60 EV: Fnum:2.2 
"""


def write_old_srt(
    path: Path,
    seconds: int = 60,
    offset_s: float = ZONE_H * 3600 + CAMERA_CLOCK_ERROR_S,
    at_s: float = VIDEO_AT_S,
    lon_first: bool = True,
    per_second: int = 1,
    where=truth,
) -> None:
    """DJI's older SRT: ``per_second`` subtitles a second, the camera's local clock ``offset_s`` ahead of UTC in
    whole seconds (truncated), GPS with 4 decimals as the samples have them, longitude first or latitude first."""
    out = []
    for i in range(seconds * per_second):
        v = i / per_second
        lat, lon = (float(x) for x in where(at_s + v)[:2])
        a, b = (
            datetime.fromtimestamp(round(x * 1000) / 1000, UTC).strftime("%H:%M:%S,%f")[:-3]
            for x in (v, v + 1 / per_second)
        )
        clock = datetime.fromtimestamp(math.floor(T0_UNIX + at_s + v + offset_s), UTC).strftime(
            "%Y.%m.%d %H:%M:%S"
        )
        pair = f"{lon:.4f},{lat:.4f}" if lon_first else f"{lat:.4f},{lon:.4f}"
        out.append(
            f"{i + 1}\n{a} --> {b}\nHOME({pair}) {clock}\nGPS({pair},15) BAROMETER:20.0\n"
            "ISO:100 Shutter:60 EV: Fnum:2.2 \n"
        )
    path.write_text("\n".join(out))


def test_the_older_srt_form_is_read_as_written(tmp_path):
    path = tmp_path / "DJI_0001.SRT"
    path.write_text(OLD_SRT)
    track = read_srt(path)
    assert (
        track.form == "older"
        and list(track.frame) == [0, 1, 2]
        and list(track.t_video_s) == [1.0, 2.0, 3.0]
    )
    assert track.t_camera_s[0] == 1501341530.0  # `date -u -d '2017-07-29 15:18:50' +%s`
    assert (track.lat_deg[0], track.lon_deg[0]) == (
        131.166,
        -25.2088,
    )  # as written: the order is not known yet
    assert np.isnan(track.rel_alt_m).all() and np.isnan(track.gimbal_ypr_deg).all()
    path.write_text(OLD_SRT.replace("GPS(131.1660,-25.2088,14)", "GPS(131.1660,x,14)", 1))
    with pytest.raises(
        SessionError, match=r"DJI_0001.SRT:1: GPS\(131.1660,x,...\): 'x' is not a number"
    ):
        read_srt(path)
    path.write_text(OLD_SRT.replace(" 2017.07.29 15:18:51", ""))
    with pytest.raises(
        SessionError,
        match=r"DJI_0001.SRT:7: the older SRT form \(GPS\(...\)\) without the camera's",
    ):
        read_srt(path)
    modern = tmp_path / "m.SRT"
    write_srt(modern, frames=2)
    path.write_text(modern.read_text() + "\n" + OLD_SRT.replace("1\n00:00:01", "3\n00:00:01"))
    with pytest.raises(
        SessionError, match=r"DJI_0001.SRT:\d+: a subtitle of the older form among the other form's"
    ):
        read_srt(path)


@pytest.mark.parametrize("lon_first, per_second", [(True, 1), (False, 1), (True, 30)])
def test_the_older_srt_forms_order_and_zone_found_from_the_track(tmp_path, lon_first, per_second):
    """Either order is found (the other puts the flight 3700 km away); the whole-second clock's zone and its
    0.3 s error found from the track, so the video's start lands within a frame of the truth."""
    csv_path, srt = tmp_path / "f.csv", tmp_path / "old.SRT"
    write_dji_csv(csv_path, np.arange(0, 1200) / 10.0)
    write_old_srt(srt, lon_first=lon_first, per_second=per_second)
    track, flight = read_srt(srt), read_dji_csv(csv_path)
    clock = srt_clock(track, flight)
    start, _ = srt_video_start(track, clock)
    print(
        f"\norder {clock.gps_order} fits {clock.order_residuals_m} m; zone {clock.offset_s - 7200:+.2f} s, "
        f"residual {clock.residual_m:.2f} m, start {start - T0_UNIX - VIDEO_AT_S:+.4f} s"
    )
    assert clock.gps_order == ("lon,lat" if lon_first else "lat,lon")
    right, wrong = sorted(clock.order_residuals_m)
    assert right < 6.0 and wrong > 1e6
    assert clock.found and round(clock.offset_s / 900) * 900 == 7200  # UTC+2
    assert start == pytest.approx(T0_UNIX + VIDEO_AT_S, abs=1 / FPS)


def test_an_older_srt_that_fits_either_order_asks_for_it(tmp_path, calibration, depth, capsys):
    """A hover on the line latitude = longitude: GPS(a, a) reads alike both ways."""
    csv_path, srt, video = tmp_path / "hover.csv", tmp_path / "h.SRT", tmp_path / "v.MP4"
    write_dji_csv(
        csv_path,
        np.arange(0, 1200) / 10.0,
        edit=lambda k, row: row.update({"OSD.latitude": str(LAT0), "OSD.longitude": str(LAT0)}),
    )
    write_old_srt(srt, seconds=10, where=lambda t: (LAT0, LAT0))
    flight = read_dji_csv(csv_path)
    with pytest.raises(
        SessionError,
        match=r"h.SRT: the older SRT form's GPS\(...\) fits the flight record in either "
        r"order \(as lat,lon 0.0 m, as lon,lat 0.0 m\): say which, --srt-gps-order",
    ):
        srt_clock(read_srt(srt), flight, utc_offset_h=2.0)
    clock = srt_clock(read_srt(srt), flight, utc_offset_h=2.0, order="lon,lat")
    assert clock.gps_order == "lon,lat" and not clock.found and clock.offset_s == 7200.0
    with pytest.raises(
        SessionError, match=r"h.SRT: the older SRT form's GPS\(...\) read as lat,lon does not fit"
    ):
        srt_clock(
            read_srt(srt), read_dji_csv(tmp_path / "hover.csv"), utc_offset_h=5.0, order="lat,lon"
        )
    with pytest.raises(
        SessionError, match=r"options: --srt-utc-offset-h and --srt-gps-order are the --srt's"
    ):
        import_flight(
            None,
            None,
            depth,
            calibration,
            tmp_path / "u",
            dji_csv=csv_path,
            srt_gps_order="lat,lon",
        )
    write_video(video, frames=FRAMES, fps=FPS, size=(320, 240))
    args = [
        "import",
        "--dji-csv",
        str(csv_path),
        "--srt",
        str(srt),
        "--video",
        str(video),
        "--depth",
        str(depth),
        "--calibration",
        str(calibration),
        "--srt-utc-offset-h",
        "2",
        "--quiet",
    ]
    assert main(args + ["--out", str(tmp_path / "s")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--srt-gps-order" in err[0]
    assert main(args + ["--srt-gps-order", "lat,lon", "--out", str(tmp_path / "t")]) == 0
    report = json.loads((tmp_path / "t" / "import.json").read_text())
    assert (report["srt_form"], report["srt_gps_order"], report["srt_utc_offset_found"]) == (
        "older",
        "lat,lon",
        False,
    )
    # the first subtitle's clock: T0 + 40 s + 2 h 0.3 s, truncated to 14:35:37 local; minus 2 h and its start (0 s)
    assert report["video_start_unix"] == pytest.approx(
        math.floor(T0_UNIX + VIDEO_AT_S + 7200.3) - 7200, abs=1e-6
    )
