"""ArduPilot DataFlash logs written record by record in its binary layout (FMT records, then messages), so that every
value and time is known by construction: for the import tests and bench/import_long.py."""

from __future__ import annotations

import struct
from pathlib import Path

FORMATS = {  # name: (type, struct format, ArduPilot format letters, columns)
    "ATT": (1, "<QffffffB", "QffffffB", "TimeUS,DesRoll,Roll,DesPitch,Pitch,DesYaw,Yaw,AEKF"),
    "POS": (2, "<Qiifff", "QLLfff", "TimeUS,Lat,Lng,Alt,RelHomeAlt,RelOriginAlt"),
    "GPS": (
        3,
        "<QBBIHBhiiiffffB",
        "QBBIHBcLLeffffB",
        "TimeUS,I,Status,GMS,GWk,NSats,HDop,Lat,Lng,Alt,Spd,GCrs,VZ,Yaw,U",
    ),
    "MNT": (
        4,
        "<QBfffffffff",
        "QBfffffffff",
        "TimeUS,I,DRoll,Roll,DPitch,Pitch,DYawB,YawB,DYawE,YawE,Dist",
    ),
    "SIM": (5, "<QhhHfiiffff", "QccCfLLffff", "TimeUS,Roll,Pitch,Yaw,Alt,Lat,Lng,Q1,Q2,Q3,Q4"),
    "TRIG": (6, "<QH", "QH", "TimeUS,Img"),
    "IMU": (7, "<QBfff", "QBfff", "TimeUS,I,GyrX,GyrY,GyrZ"),
    "BARO": (8, "<QBfffIfB", "QBfffIfB", "TimeUS,I,Alt,Press,CRt,SMS,Offset,H"),
    "CTUN": (9, "<Qf", "Qf", "TimeUS,Alt"),
    "PARM": (10, "<Q16sf", "QNf", "TimeUS,Name,Value"),
    "GPA": (11, "<QBI", "QBI", "TimeUS,I,SMS"),
}


class DataflashWriter:
    def __init__(self, path: Path, names=tuple(FORMATS)):
        self.f = open(path, "wb")  # noqa: SIM115 - closed by close()
        for name in names:
            kind, fmt, letters, columns = FORMATS[name]
            length = 3 + struct.calcsize(fmt)
            self.f.write(
                bytes([0xA3, 0x95, 0x80])
                + struct.pack(
                    "<BB4s16s64s", kind, length, name.encode(), letters.encode(), columns.encode()
                )
            )

    def write(self, name: str, *values) -> None:
        kind, fmt, _, _ = FORMATS[name]
        self.f.write(bytes([0xA3, 0x95, kind]) + struct.pack(fmt, *values))

    def close(self) -> None:
        self.f.close()
