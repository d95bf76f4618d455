"""The UAV's own GNSS accuracy, from what GPS_RAW_INT says.

GPS_RAW_INT carries the receiver's 1-sigma ``h_acc``/``v_acc`` (0 when it gives none: ArduPilot
sends 0 when its GPS driver has no accuracy, and MAVLink 1 has no such fields) and, always,
``eph``/``epv``: HDOP and VDOP (× 100; 65535 unknown). Where the receiver states its accuracy,
that is used; otherwise the dilution of precision times the user equivalent range error of
the fix type (:data:`UERE_M`): ``sigma_h = HDOP · UERE`` (DRMS), ``sigma_v = VDOP · UERE``, with
HDOP 1 and VDOP :data:`TYPICAL_VDOP` when the DOPs are unknown too.

:data:`UERE_M` is the receiver's horizontal DRMS at HDOP 1, from the u-blox ZED-F9P data sheet
(UBX-17051259: horizontal accuracy 1.5 m CEP standalone, 1.0 m CEP with SBAS, 0.01 m + 1 ppm
CEP RTK; DRMS = 1.2 × CEP for a circular normal error): 3D 1.8 m, DGPS/SBAS 1.2 m, RTK fixed
0.012 m. The data sheet gives nothing for RTK float and PPP: 0.5 m (decimetres, a judgement);
a static fix (7) counts as 3D. No fix, or a 2D fix (no usable altitude), has no accuracy (NaN).
Metres throughout.

The position a fix starts from is the EKF's (GLOBAL_POSITION_INT), not the receiver's: the EKF follows the
receiver through its own filter (a lag behind it, the antenna's lever arm, the IMU's and the receiver's timing),
a few centimetres that a receiver's metre hides but an RTK fix's centimetre does not.
:func:`position_sigma_m` adds :data:`EKF_OWN_M` to an RTK fix's (a judgement: ArduPilot RTK multicopters hold
position to 2–5 cm; the EKF's estimate against the RTK solution is of that order in steady flight).
"""

from __future__ import annotations

import numpy as np

# MAVLink GPS_FIX_TYPE
FIX_3D = 3
RTK_FLOAT = 5
RTK_FIXED = 6
#: user equivalent range error (m) per GPS_FIX_TYPE: the horizontal DRMS at HDOP 1 (see the module doc)
UERE_M = {2: 1.8, 3: 1.8, 4: 1.2, 5: 0.5, 6: 0.012, 7: 1.8, 8: 0.5}
TYPICAL_VDOP = 1.5  # VDOP when the receiver gives none (open sky: about 1.5 × HDOP)
#: the EKF position's own horizontal error (m, DRMS) added to an RTK receiver's accuracy (see the module doc)
EKF_OWN_M = 0.03


def uere_m(fix_type) -> np.ndarray:
    """:data:`UERE_M` of fix types (array); NaN for no fix and unknown types."""
    ft = np.asarray(fix_type, dtype=float)
    out = np.full(ft.shape, np.nan)
    for k, v in UERE_M.items():
        out[ft == k] = v
    return out


def _stated(acc_m):
    a = np.asarray(acc_m, dtype=float)
    return np.isfinite(a) & (a > 0)


def horizontal_sigma_m(fix_type, h_acc_m, eph_m) -> np.ndarray:
    """The UAV position's horizontal 1-sigma (DRMS): ``h_acc``, else HDOP (``eph_m``: eph / 100, NaN unknown)
    times the fix type's UERE. NaN without a 2D/3D fix."""
    dop = np.where(_stated(eph_m), eph_m, 1.0)
    return np.where(_stated(h_acc_m), h_acc_m, dop * uere_m(fix_type))


def position_sigma_m(fix_type, h_acc_m, eph_m) -> np.ndarray:
    """The EKF position's horizontal 1-sigma (DRMS): the receiver's (:func:`horizontal_sigma_m`), with an RTK fix
    :data:`EKF_OWN_M` added in quadrature. NaN without a 2D/3D fix."""
    sigma = horizontal_sigma_m(fix_type, h_acc_m, eph_m)
    return np.where(is_rtk(fix_type), np.hypot(sigma, EKF_OWN_M), sigma)


def vertical_sigma_m(fix_type, v_acc_m, epv_m) -> np.ndarray:
    """The GNSS altitude's 1-sigma: ``v_acc``, else VDOP (``epv_m``: epv / 100, NaN unknown; else
    :data:`TYPICAL_VDOP`) times the fix type's UERE. NaN without a 3D fix (a 2D fix has no altitude)."""
    ft = np.asarray(fix_type, dtype=float)
    dop = np.where(_stated(epv_m), epv_m, TYPICAL_VDOP)
    sigma = np.where(_stated(v_acc_m), v_acc_m, dop * uere_m(ft))
    return np.where(ft >= FIX_3D, sigma, np.nan)


def is_rtk(fix_type) -> np.ndarray:
    """RTK float or fixed (GPS_FIX_TYPE 5, 6): a centimetre-to-decimetre solution."""
    ft = np.asarray(fix_type, dtype=float)
    return (ft == RTK_FLOAT) | (ft == RTK_FIXED)
