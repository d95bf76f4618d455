"""Hostile input for fuzzing the live service: MAVLink frames and depth payloads that must all be refused.

Every item has at least one reason to be refused, and every item that decodes carries a
*poisoned* payload — values within physical range that, were they used, would move a fix
by metres to tens of metres: the UAV 0.001° (≈ 110 m) off, its attitude 0.4 rad off, the
gimbal 25° off, its GNSS altitude 30 m off (the height's), the UUV 3 m deeper. A run with this input mixed into a valid session must
therefore send the same GPS_INPUT as the valid input alone, within the fixes' own noise.

MAVLink kinds (:data:`MAVLINK_KINDS`, with the service's counter each must land in):
``random`` bytes, ``bit_flip`` (a frame with flipped bits), ``bad_crc``, ``truncated``,
``unknown_id`` (a well-formed MAVLink 2 frame of a message id no dialect has) — all
``bad_data``; ``other_system`` (the UAV's messages from another system id) —
``other_systems``; ``other_component`` (ATTITUDE, GLOBAL_POSITION_INT, SYSTEM_TIME or
GPS_RAW_INT from a component that is not the autopilot), ``absurd`` (NaN, infinite or
out-of-range values: a GNSS altitude of ±thousands of km too), ``time_back`` and ``time_forward`` (the autopilot's boot clock 5 s to 1 h off
the one its other messages follow, valid CRC) — all ``refused``.

Depth kinds (:data:`DEPTH_KINDS`): ``not_json``, ``nan``, ``wrong_type``, ``missing``,
``wrong_shape``, ``nested``, ``huge`` — ``bad``; ``out_of_range``, ``time_future`` and
``time_past`` (the UUV's clock 10 s to 10 days off) — ``refused``.

Deterministic for a seed; pure (no I/O): callers send the bytes.
"""

from __future__ import annotations

import json
import math
import os
import random
from collections.abc import Callable

os.environ.setdefault("MAVLINK20", "1")

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

MAVLINK_KINDS = {
    "random": "bad_data",
    "bit_flip": "bad_data",
    "bad_crc": "bad_data",
    "truncated": "bad_data",
    "unknown_id": "bad_data",
    "other_system": "other_systems",
    "other_component": "refused",
    "absurd": "refused",
    "time_back": "refused",
    "time_forward": "refused",
}
DEPTH_KINDS = {
    "not_json": "bad",
    "nan": "bad",
    "wrong_type": "bad",
    "missing": "bad",
    "wrong_shape": "bad",
    "nested": "bad",
    "huge": "bad",
    "out_of_range": "refused",
    "time_future": "refused",
    "time_past": "refused",
}
POISON_DEG = 0.001
POISON_RAD = 0.4
POISON_DEPTH_M = 3.0
_Q_PITCH_M32 = (math.cos(math.radians(-32) / 2), 0.0, math.sin(math.radians(-32) / 2), 0.0)


class MavlinkFuzzer:
    """Hostile MAVLink frames for a UAV (``sysid``/``compid``) whose boot clock reads ``boot_ms(t_unix)`` now.

    ``position`` is a (lat, lon) near the UAV, the poison is added to it.
    """

    def __init__(
        self,
        sysid: int,
        compid: int,
        boot_ms: Callable[[float], int],
        position: tuple[float, float],
        seed: int = 1,
    ):
        self.sysid, self.compid, self.boot_ms = sysid, compid, boot_ms
        self.lat, self.lon = position
        self.rng = random.Random(seed)
        self._seq = 0

    def _pack(self, msg, sysid: int | None = None, compid: int | None = None) -> bytes:
        mav = mavlink2.MAVLink(
            None,
            srcSystem=self.sysid if sysid is None else sysid,
            srcComponent=self.compid if compid is None else compid,
        )
        mav.seq = self._seq
        self._seq = (self._seq + 1) % 256
        return msg.pack(mav)

    def _poisoned(self, boot: int, kinds=("att", "pos", "gimbal", "time")):
        kind = self.rng.choice(kinds)
        if kind == "att":
            return mavlink2.MAVLink_attitude_message(
                boot, POISON_RAD, -POISON_RAD, 1.0, 0.0, 0.0, 0.0
            )
        if kind == "pos":
            return mavlink2.MAVLink_global_position_int_message(
                boot,
                round((self.lat + POISON_DEG) * 1e7),
                round((self.lon + POISON_DEG) * 1e7),
                12_000,
                8_000,
                0,
                0,
                0,
                0,
            )
        if kind == "gimbal":
            return mavlink2.MAVLink_gimbal_device_attitude_status_message(
                0, 0, boot, 12, _Q_PITCH_M32, math.nan, math.nan, math.nan, 0, math.nan, math.nan, 1
            )
        if (
            kind == "gps"
        ):  # an RTK altitude 30 m above the UAV's (its time since boot, as ArduPilot sends it)
            return mavlink2.MAVLink_gps_raw_int_message(
                boot * 1000,
                6,
                round(self.lat * 1e7),
                round(self.lon * 1e7),
                42_000,
                70,
                110,
                0,
                0,
                14,
                82_000,
                10,
                20,
                0,
                0,
                0,
            )
        return mavlink2.MAVLink_system_time_message(
            int((1_763_800_000 + self.rng.uniform(-1e6, 1e6)) * 1e6), boot
        )

    def _absurd(self, boot: int):
        r = self.rng.randrange(7)
        bad = self.rng.choice((math.nan, math.inf, -math.inf, 7.0, -1e9))
        if r == 0:
            return mavlink2.MAVLink_attitude_message(boot, bad, 0.0, 0.0, 0.0, 0.0, 0.0)
        if r == 1:
            return mavlink2.MAVLink_attitude_message(
                boot, 0.0, 0.0, self.rng.choice((100.0, -57.3, math.nan)), 0.0, 0.0, 0.0
            )
        if r == 2:
            lat = self.rng.choice((950_000_000, -950_000_000, 0))
            return mavlink2.MAVLink_global_position_int_message(
                boot, lat, 0 if lat == 0 else 104_000_000, 12_000, 8_000, 0, 0, 0, 0
            )
        if r == 3:
            return mavlink2.MAVLink_global_position_int_message(
                boot, round(self.lat * 1e7), 2_000_000_000, 12_000, 8_000, 0, 0, 0, 0
            )
        if r == 6:  # a 3D fix at ±2000 km
            return mavlink2.MAVLink_gps_raw_int_message(
                boot * 1000,
                3,
                round(self.lat * 1e7),
                round(self.lon * 1e7),
                self.rng.choice((2_000_000_000, -2_000_000_000)),
                70,
                110,
                0,
                0,
                14,
                0,
                800,
                1600,
                0,
                0,
                0,
            )
        q = self.rng.choice(((0.0, 0.0, 0.0, 0.0), (math.nan, 0.0, 0.0, 1.0), (2.0, 0.0, 0.0, 0.0)))
        return mavlink2.MAVLink_gimbal_device_attitude_status_message(
            0, 0, boot, 12, q, 0.0, 0.0, 0.0, 0, 0.0, 0.0, 1
        )

    def frame(self, kind: str, t_unix: float) -> bytes:
        """One datagram of ``kind`` (a key of :data:`MAVLINK_KINDS`) at station time ``t_unix``."""
        rng = self.rng
        boot = self.boot_ms(t_unix)
        if kind == "random":
            return rng.randbytes(rng.randint(1, 280))
        if kind == "unknown_id":
            n = rng.randint(1, 40)
            msgid = rng.choice((0xABCDEF, 0x7FFF00, 60_000))
            return (
                bytes((0xFD, n, 0, 0, 0, self.sysid, self.compid))
                + msgid.to_bytes(3, "little")
                + rng.randbytes(n + 2)
            )
        if kind == "other_system":
            sysid = rng.choice([s for s in range(2, 251) if s not in (self.sysid, 245)])
            return self._pack(self._poisoned(boot), sysid=sysid)
        if kind == "other_component":
            compid = rng.choice([c for c in (25, 100, 154, 191, 240) if c != self.compid])
            return self._pack(self._poisoned(boot, ("att", "pos", "time", "gps")), compid=compid)
        if kind == "absurd":
            return self._pack(self._absurd(boot))
        if kind in ("time_back", "time_forward"):
            jump_ms = round(rng.uniform(5.0, 3600.0) * 1000) * (1 if kind == "time_forward" else -1)
            return self._pack(self._poisoned(max(0, boot + jump_ms) or 1))
        good = bytearray(self._pack(self._poisoned(boot)))
        if kind == "bad_crc":
            good[-1 - rng.randrange(2)] ^= rng.randint(1, 255)
            return bytes(good)
        if kind == "truncated":
            return bytes(good[: rng.randint(1, len(good) - 1)])
        if (
            kind == "bit_flip"
        ):  # distinct bits: two flips of the same bit would give the poisoned frame back intact
            for bit in rng.sample(range(8, 8 * len(good)), rng.randint(1, 8)):
                good[bit // 8] ^= 1 << (bit % 8)
            return bytes(good)
        raise ValueError(f"unknown MAVLink fuzz kind {kind!r}")


class DepthFuzzer:
    """Hostile payloads for the depth key (skyfix's ``{"t", "depth_m"}`` JSON)."""

    def __init__(self, depth_m: float, seed: int = 2):
        self.poison_m = depth_m + POISON_DEPTH_M
        self.rng = random.Random(seed)

    def payload(self, kind: str, t_unix: float) -> bytes:
        """One payload of ``kind`` (a key of :data:`DEPTH_KINDS`) sent at station time ``t_unix``."""
        rng, d = self.rng, self.poison_m
        if kind == "not_json":
            return rng.choice(
                (rng.randbytes(rng.randint(0, 200)), b"\x00\xffnot json\x80", b"{", b"")
            )
        if kind == "nan":
            return rng.choice(
                (
                    b'{"t": NaN, "depth_m": %.2f}' % d,
                    b'{"t": %.3f, "depth_m": NaN}' % t_unix,
                    b'{"t": %.3f, "depth_m": Infinity}' % t_unix,
                    b'{"t": -Infinity, "depth_m": 1}',
                )
            )
        if kind == "wrong_type":
            return rng.choice(
                (
                    b'{"t": %.3f, "depth_m": "%.2f"}' % (t_unix, d),
                    b'{"t": "now", "depth_m": %.2f}' % d,
                    b'{"t": %.3f, "depth_m": true}' % t_unix,
                    b'{"t": %.3f, "depth_m": null}' % t_unix,
                    b'{"t": %.3f, "depth_m": [%.2f]}' % (t_unix, d),
                )
            )
        if kind == "missing":
            return rng.choice((b'{"t": %.3f}' % t_unix, b'{"depth_m": %.2f}' % d, b"{}"))
        if kind == "wrong_shape":
            return rng.choice((b"[1, 2, 3]", b"%.2f" % d, b"null", b"true", b'"depth"'))
        if kind == "nested":
            return b"[" * rng.randint(2_000, 100_000)
        if kind == "huge":
            return json.dumps(
                {"t": t_unix, "depth_m": d, "pad": "x" * rng.randint(100_000, 2_000_000)}
            ).encode()[:-2]
        if kind == "out_of_range":
            return json.dumps(
                {"t": t_unix, "depth_m": rng.choice((-40.0, 11_001.0, 1e6, -5.5))}
            ).encode()
        if kind in ("time_future", "time_past"):
            off = 10 ** rng.uniform(1.0, 6.0) * (1 if kind == "time_future" else -1)
            return json.dumps({"t": t_unix + off, "depth_m": d}).encode()
        raise ValueError(f"unknown depth fuzz kind {kind!r}")


def schedule(kinds, n: int, seed: int = 3, weights: dict[str, float] | None = None) -> list[str]:
    """``n`` kinds drawn from ``kinds`` (uniformly, or by ``weights``), reproducibly."""
    kinds = list(kinds)
    w = [(weights or {}).get(k, 1.0) for k in kinds]
    return random.Random(seed).choices(kinds, weights=w, k=n)
