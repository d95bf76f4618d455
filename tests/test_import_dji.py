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
from groundstation.session.dji import read_dji_csv, read_srt, srt_clock
from groundstation.session.read import load_session
from groundstation.session.tlog import read_tlog
from localizer.attitude import R_ned_from_mount_orientation, euler_to_R

FIXTURES = Path(__file__).parent / "fixtures" / "dji"
T0_UNIX = 1684067696.789  # 2023-05-14T12:34:56.789Z (`date -u -d 2023-05-14T12:34:56Z +%s` = 1684067696)
LAT0, LON0, R_EARTH_M = 43.5, 16.4, 6_371_000.0
VIDEO_AT_S, FPS, FRAMES = 40.0, 30, 90  # the video's first frame 40 s into the record
ZONE_H, CAMERA_CLOCK_ERROR_S = 2.0, 0.3  # the camera's clock: local time UTC+2, 0.3 s fast
DJI_LOG_PARSER = ["CUSTOM.dateTime", "OSD.flyTime", "OSD.latitude", "OSD.longitude", "OSD.height", "OSD.heightMax",
                  "OSD.vpsHeight", "OSD.altitude", "OSD.xSpeed", "OSD.ySpeed", "OSD.zSpeed", "OSD.pitch", "OSD.roll",
                  "OSD.yaw", "OSD.flycState", "OSD.gpsNum", "GIMBAL.mode", "GIMBAL.pitch", "GIMBAL.roll", "GIMBAL.yaw",
                  "GIMBAL.isPitchAtLimit", "CAMERA.isVideo"]


def truth(t_s):
    """The flight at ``t_s`` s after T0: lat, lon (deg), height above take-off (m), roll, pitch, yaw, gimbal roll,
    pitch, yaw from North (deg). It flies north at 2 m/s, weaving 20 m east and west."""
    t_s = np.asarray(t_s, dtype=float)
    north, east = 2.0 * t_s, 20.0 * np.sin(t_s / 10.0)
    lat = LAT0 + np.degrees(north / R_EARTH_M)
    lon = LON0 + np.degrees(east / (R_EARTH_M * math.cos(math.radians(LAT0))))
    yaw = 30.0 * np.sin(t_s / 7.0)
    return (lat, lon, 20.0 + 0.05 * t_s, 3.0 * np.sin(t_s), np.full_like(t_s, -5.0), yaw,
            np.zeros_like(t_s), -60.0 + 10.0 * np.sin(t_s / 5.0), yaw + 15.0)


def iso_utc(t_unix: float) -> str:
    return datetime.fromtimestamp(t_unix, UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


def write_dji_csv(path: Path, t_s, columns=DJI_LOG_PARSER, edit=None) -> None:
    """dji-log-parser's layout: every listed column, the values of :func:`truth` (``edit(row_dict)`` may change
    cells)."""
    lat, lon, h, roll, pitch, yaw, g_roll, g_pitch, g_yaw = truth(t_s)
    lines = [",".join(columns)]
    for k, t in enumerate(np.asarray(t_s, dtype=float)):
        row = {"CUSTOM.dateTime": iso_utc(T0_UNIX + t), "OSD.flyTime": f"{t:.1f}", "OSD.latitude": repr(float(lat[k])),
               "OSD.longitude": repr(float(lon[k])), "OSD.height": f"{h[k]:.1f}", "OSD.altitude": f"{h[k] + 100.0:.1f}",
               "OSD.pitch": f"{pitch[k]:.1f}", "OSD.roll": f"{roll[k]:.1f}", "OSD.yaw": f"{yaw[k]:.1f}",
               "GIMBAL.pitch": f"{g_pitch[k]:.1f}", "GIMBAL.roll": f"{g_roll[k]:.1f}",
               "GIMBAL.yaw": f"{(g_yaw[k] + 180) % 360 - 180:.1f}", "OSD.flycState": "GPSAtti", "GIMBAL.mode": "YawFollow",
               "CAMERA.isVideo": "true"}
        if edit:
            edit(k, row)
        lines.append(",".join(row.get(c, "0") for c in columns))
    path.write_text("\n".join(lines) + "\n")


def write_srt(path: Path, frames: int = FRAMES, offset_s: float = ZONE_H * 3600 + CAMERA_CLOCK_ERROR_S,
              at_s: float = VIDEO_AT_S, where=truth) -> None:
    """DJI's modern SRT: one subtitle a frame, the camera's local clock ``offset_s`` ahead of UTC, positions and
    gimbal angles at the frame's true time rounded as the camera writes them."""
    out = []
    for i in range(frames):
        t_s = at_s + i / FPS
        lat, lon, h, *_, g_roll, g_pitch, g_yaw = (float(x) for x in where(t_s))
        a, b = (datetime.fromtimestamp(round(k * 1000 / FPS) / 1000, UTC).strftime("%H:%M:%S,%f")[:-3]
                for k in (i, i + 1))
        clock = datetime.fromtimestamp(T0_UNIX + t_s + offset_s, UTC).strftime("%Y-%m-%d %H:%M:%S.%f")[:-3]
        out.append(f"{i + 1}\n{a} --> {b}\n"
                   f'<font size="28">FrameCnt: {i + 1}, DiffTime: 33ms\n{clock}\n'
                   f"[iso: 100] [shutter: 1/500.0] [fnum: 2.8] [ev: 0] [latitude: {lat:.6f}] [longitude: {lon:.6f}] "
                   f"[rel_alt: {h:.3f} abs_alt: {h + 100:.3f}] [gb_yaw: {g_yaw:.1f} gb_pitch: {g_pitch:.1f} "
                   f"gb_roll: {g_roll:.1f}] </font>\n")
    path.write_text("\n".join(out))


@pytest.fixture
def calibration(tmp_path):
    cal = tmp_path / "cal.toml"
    cal.write_text((ROOT / "deploy" / "calibration.toml").read_text()
                   .replace('attitude_source = "gimbal_device"', 'attitude_source = "mount_orientation"'))
    return cal


@pytest.fixture
def depth(tmp_path):
    path = tmp_path / "depth.csv"
    path.write_text("t,depth_m\n" + "".join(f"{T0_UNIX + s:.3f},1.5\n" for s in range(0, 120, 2)))
    return path


def test_a_record_and_srt_become_a_session_with_the_cameras_zone_found(tmp_path, calibration, depth):
    """End to end through the command line: the video's start comes from the SRT, its clock's zone (UTC+2, and the
    0.3 s it runs fast) found from its track against the record's."""
    csv_path, srt, video, out = tmp_path / "flight.csv", tmp_path / "DJI_0001.SRT", tmp_path / "DJI_0001.MP4", \
        tmp_path / "session"
    write_dji_csv(csv_path, np.arange(0, 1200) / 10.0)
    write_srt(srt)
    write_video(video, frames=FRAMES, fps=FPS, size=(320, 240))
    assert main(["import", "--dji-csv", str(csv_path), "--srt", str(srt), "--video", str(video), "--depth",
                 str(depth), "--calibration", str(calibration), "--out", str(out), "--quiet"]) == 0
    report = json.loads((out / "import.json").read_text())
    print(f"\nzone {report['srt_utc_offset_h'] * 3600 - 7200:+.3f} s past UTC+2, residual "
          f"{report['srt_track_residual_m']} m, start {report['video_start_unix'] - T0_UNIX - VIDEO_AT_S:+.4f} s")
    assert report["srt_utc_offset_h"] * 3600 == pytest.approx(ZONE_H * 3600 + CAMERA_CLOCK_ERROR_S, abs=0.03)
    assert report["srt_utc_offset_found"] and report["srt_track_residual_m"] < 0.2 and report["srt_frames"] == FRAMES
    assert report["video_start_unix"] == pytest.approx(T0_UNIX + VIDEO_AT_S, abs=0.03)
    assert report["video_start_from"].startswith("the SRT's frame times") and report["dji_csv"] == str(csv_path)
    assert report["unix_minus_boot_s"] == pytest.approx(T0_UNIX, abs=1e-6)
    session = load_session(out)
    assert len(session.frames["t"]) == FRAMES
    assert session.frames["t"][1] - session.frames["t"][0] == pytest.approx(1 / FPS, abs=1e-4)
    kinds = {}
    for t_rec, m in read_tlog(out / "uav.tlog"):
        kinds[m.get_type()] = kinds.get(m.get_type(), 0) + 1
        if m.get_type() == "MOUNT_ORIENTATION":  # the gimbal's yaw from North and against the nose: 15 deg apart
            assert m.yaw == pytest.approx(15.0, abs=0.11)
            assert m.time_boot_ms / 1000 + T0_UNIX == pytest.approx(t_rec, abs=1e-3)
        if m.get_type() == "SYSTEM_TIME":
            assert m.time_unix_usec / 1e6 - m.time_boot_ms / 1e3 == pytest.approx(T0_UNIX, abs=1e-3)
    assert kinds["ATTITUDE"] == kinds["MOUNT_ORIENTATION"] == kinds["GLOBAL_POSITION_INT"] == 1200
    assert kinds["GPS_RAW_INT"] == kinds["SYSTEM_TIME"] == 1200
    track = read_srt(srt)
    g_yaw, g_pitch = float(truth(VIDEO_AT_S)[8]), float(truth(VIDEO_AT_S)[7])
    assert track.gimbal_ypr_deg[0] == pytest.approx([g_yaw, g_pitch, 0.0], abs=0.05) and track.frame[-1] == FRAMES - 1


def test_dji_angles_mean_what_dji_says(tmp_path, calibration, depth):
    """Hand-worked: heading West is OSD.yaw −90 → ATTITUDE yaw −π/2, the nose along −East; the gimbal at pitch −30
    and yaw 0 (North) under that heading looks North and 30° down; at pitch −90 straight down."""
    csv_path = tmp_path / "flight.csv"

    def edit(k, row):
        row |= {"OSD.yaw": "-90.0", "OSD.roll": "0.0", "OSD.pitch": "0.0", "GIMBAL.roll": "0.0", "GIMBAL.yaw": "0.0",
                "GIMBAL.pitch": "-30.0" if k < 2 else "-90.0"}

    write_dji_csv(csv_path, [0.0, 0.1, 0.2, 0.3], edit=edit)
    import_flight(None, None, depth, calibration, tmp_path / "s", dji_csv=csv_path)
    msgs = read_tlog(tmp_path / "s" / "uav.tlog")
    att = next(m for _, m in msgs if m.get_type() == "ATTITUDE")
    assert att.yaw == pytest.approx(-math.pi / 2, abs=1e-6)
    assert euler_to_R(att.roll, att.pitch, att.yaw) @ [1, 0, 0] == pytest.approx([0, -1, 0], abs=1e-6)
    mounts = [m for _, m in msgs if m.get_type() == "MOUNT_ORIENTATION"]
    axes = [R_ned_from_mount_orientation(m.roll, m.pitch, m.yaw, att.yaw) @ [1, 0, 0] for m in mounts]
    assert axes[0] == pytest.approx([math.cos(math.radians(30)), 0, 0.5], abs=1e-6)
    assert axes[3] == pytest.approx([0, 0, 1], abs=1e-6)
    assert (mounts[0].yaw, mounts[0].yaw_absolute) == (90.0, 0.0)


PHANTOMHELP = ["CUSTOM.date [local]", "CUSTOM.updateTime [local]", "OSD.flyTime [s]", "OSD.latitude",
               "OSD.longitude", "OSD.height [ft]", "OSD.altitude [ft]", "OSD.pitch", "OSD.roll", "OSD.yaw",
               "OSD.yaw [360]", "GIMBAL.pitch", "GIMBAL.roll", "GIMBAL.yaw", "GIMBAL.yaw [360]", "BATTERY.voltage [V]"]
PH_ROW = ["5/14/2023", "{time}", "0.0", "43.5", "16.4", "100.0", "328.084", "-5.0", "0.0", "-90.0", "270.0",
          "-90.0", "0.0", "-90.0", "270.0", "15.2"]


def write_phantomhelp(path: Path, headers=PHANTOMHELP, rows=(("2:34:56.78 PM", "2:34:56.88 PM"))) -> None:
    lines = ["sep=,", ",".join(headers)]
    lines += [",".join(PH_ROW).replace("{time}", t) for t in rows]
    path.write_text("\n".join(lines) + "\n")


def test_phantomhelp_feet_and_local_times(tmp_path):
    path = tmp_path / "DJIFlightRecord_2023-05-14_[14-34-56].csv"
    write_phantomhelp(path)
    flight = read_dji_csv(path, utc_offset_h=2.0)
    assert flight.unix_minus_boot_s == pytest.approx(1684067696.78, abs=1e-6)  # 14:34:56.78 at UTC+2
    assert flight.pos[0, 4] == pytest.approx(30.48) and flight.pos[0, 3] == pytest.approx(100.0, abs=1e-4)  # ft → m
    assert math.degrees(flight.att[0, 3]) == pytest.approx(-90.0) and flight.mnt[0, 3] == pytest.approx(0.0)
    with pytest.raises(SessionError, match=r"CUSTOM.updateTime \[local\]: local times .* --dji-csv-utc-offset-h"):
        read_dji_csv(path)


@pytest.mark.parametrize("header, message", [
    ("OSD.height [yd]", r"column 'OSD.height \[yd\]': unknown unit 'yd'"),
    ("OSD.height", r"column 'OSD.height': no unit, while the other headers carry theirs"),
    ("OSD.roll [rad]", r"column 'OSD.roll \[rad\]': unknown unit 'rad'"),
])
def test_a_unit_that_is_missing_or_unknown_is_an_error_naming_the_column(tmp_path, header, message):
    path = tmp_path / "ph.csv"
    write_phantomhelp(path, [header if h.split(" [")[0] == header.split(" [")[0] else h for h in PHANTOMHELP])
    with pytest.raises(SessionError, match=rf"ph.csv: {message}"):
        read_dji_csv(path, utc_offset_h=0.0)


def test_bad_records_are_one_line_errors_naming_file_column_and_value(tmp_path, calibration, depth, capsys):
    missing = tmp_path / "missing.csv"
    write_dji_csv(missing, [0.0, 0.1], columns=[c for c in DJI_LOG_PARSER if c != "OSD.yaw"])
    with pytest.raises(SessionError, match=r"missing.csv: no column OSD.yaw"):
        read_dji_csv(missing)
    garbage = tmp_path / "garbage.csv"
    write_dji_csv(garbage, [0.0, 0.1, 0.2], edit=lambda k, row: row.update({"OSD.latitude": "abc"} if k == 2 else {}))
    with pytest.raises(SessionError, match=r"garbage.csv:4: OSD.latitude = 'abc': not a number"):
        read_dji_csv(garbage)
    naive = tmp_path / "naive.csv"
    write_dji_csv(naive, [0.0, 0.1], edit=lambda k, row: row.update({"CUSTOM.dateTime": "2023-05-14 12:34:56"}))
    with pytest.raises(SessionError, match=r"naive.csv:2: CUSTOM.dateTime = '2023-05-14 12:34:56': no time zone"):
        read_dji_csv(naive)
    assert main(["import", "--dji-csv", str(garbage), "--depth", str(depth), "--calibration", str(calibration),
                 "--out", str(tmp_path / "s")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "garbage.csv:4: OSD.latitude = 'abc'" in err[0]
    with pytest.raises(SystemExit):  # exactly one flight record
        main(["import", "--dji-csv", str(garbage), "--dataflash", "x.bin", "--depth", str(depth), "--calibration",
              str(calibration), "--out", str(tmp_path / "t")])


def test_repeated_backwards_and_empty_rows_are_dropped_with_one_warning_each(tmp_path):
    path = tmp_path / "dirty.csv"
    t = [0.0, 0.1, 0.2, 0.3, 0.4, 0.4, 0.35, 0.5, 0.6, 0.7, 0.7]
    write_dji_csv(path, t, edit=lambda k, row: row.update({"OSD.roll": ""} if k == 7 else {}))
    flight = read_dji_csv(path)
    assert flight.att[:, 0] == pytest.approx([0.0, 0.1, 0.2, 0.3, 0.4, 0.6, 0.7], abs=1e-6)
    assert len(flight.warnings) == 3
    repeated, = (w for w in flight.warnings if "repeating" in w)
    backwards, = (w for w in flight.warnings if "earlier" in w)
    empty, = (w for w in flight.warnings if "empty" in w)
    assert "2 rows" in repeated and "line 7" in repeated and "1 rows" in backwards and "line 8" in backwards
    assert "line 9" in empty


def test_a_real_cameras_srt_excerpt():
    """DJI Air 2S (DJI_SRT_Parser's sample, MIT): ``SrtCnt``, the ``,ms,µs`` clock, ``[altitude: ...]`` only."""
    track = read_srt(FIXTURES / "air2s_excerpt.SRT")
    assert list(track.frame) == [0, 1, 2] and track.t_video_s == pytest.approx([0.0, 0.033, 0.066])
    assert track.t_camera_s[0] == pytest.approx(1659879640 + 0.774808, abs=1e-6)  # 2022-08-07 13:40:40,774,808
    assert track.t_camera_s[2] - track.t_camera_s[1] == pytest.approx(0.033367, abs=1e-6)
    assert (track.lat_deg[0], track.lon_deg[1]) == (41.424724, 2.234147)
    assert np.isnan(track.rel_alt_m).all() and np.isnan(track.gimbal_ypr_deg).all()


def test_srt_errors_and_a_given_zone(tmp_path):
    old = tmp_path / "old.SRT"
    old.write_text("1\n00:00:00,000 --> 00:00:01,000\n2022.06.21 16:06:17\nGPS(36.6146,-6.1120,0.0M) BAROMETER:0.3M\n")
    with pytest.raises(SessionError, match=r"old.SRT:1: the older SRT form"):
        read_srt(old)
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
    with pytest.raises(SessionError, match=r"at UTC\+5 h its frames fall outside the flight record"):
        srt_clock(read_srt(srt), flight, utc_offset_h=5.0)


def test_a_hover_fits_many_zones_and_is_refused(tmp_path):
    """A record of 3 h hovering in one place: the SRT's track fits every zone within it alike."""
    csv_path, srt = tmp_path / "hover.csv", tmp_path / "h.SRT"
    write_dji_csv(csv_path, np.arange(0, 3 * 3600, 2.0), edit=lambda k, row: row.update(
        {"OSD.latitude": str(LAT0), "OSD.longitude": str(LON0), "OSD.height": "20.0"}))
    write_srt(srt, offset_s=3600.0, at_s=5400.0, where=lambda t: (LAT0, LON0, 20.0, *truth(t)[3:]))
    with pytest.raises(SessionError, match=r"h.SRT: its track fits the record at UTC.* alike: give --srt-utc-offset-h"):
        srt_clock(read_srt(srt), read_dji_csv(csv_path))
