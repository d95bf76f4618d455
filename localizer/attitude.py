"""Rotations and the camera's attitude from each MAVLink source.

Frames: ``ned`` local North-East-Down; ``body`` the UAV's FRD frame; ``gimbal``
the gimbal's FRD frame (x is the optical axis); ``cv`` OpenCV's camera frame
(x right, y down, z optical axis). ``R_a_from_b`` maps vectors in frame b to
frame a. Angles are radians unless the name says ``_deg``. Euler angles are
the aerospace Z-Y-X sequence (yaw, then pitch, then roll), as MAVLink uses.
Functions take scalars or arrays and broadcast; matrices come out ``(..., 3, 3)``.
"""

from __future__ import annotations

import numpy as np

# MAVLink GIMBAL_DEVICE_FLAGS bits (common.xml)
GIMBAL_DEVICE_FLAGS_YAW_LOCK = 16
GIMBAL_DEVICE_FLAGS_YAW_IN_VEHICLE_FRAME = 32
GIMBAL_DEVICE_FLAGS_YAW_IN_EARTH_FRAME = 64

#: OpenCV camera axes expressed in the gimbal's FRD frame: cv x (image right) is
#: gimbal y, cv y (image down) is gimbal z, cv z (optical axis) is gimbal x.
R_GIMBAL_FROM_CV = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def euler_to_R(roll, pitch, yaw):
    """``R_ned_from_frd`` for Z-Y-X Euler angles (radians)."""
    roll, pitch, yaw = np.broadcast_arrays(
        *(np.asarray(a, dtype=float) for a in (roll, pitch, yaw))
    )
    cr, sr = np.cos(roll), np.sin(roll)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cy, sy = np.cos(yaw), np.sin(yaw)
    R = np.empty(roll.shape + (3, 3))
    R[..., 0, 0] = cy * cp
    R[..., 0, 1] = cy * sp * sr - sy * cr
    R[..., 0, 2] = cy * sp * cr + sy * sr
    R[..., 1, 0] = sy * cp
    R[..., 1, 1] = sy * sp * sr + cy * cr
    R[..., 1, 2] = sy * sp * cr - cy * sr
    R[..., 2, 0] = -sp
    R[..., 2, 1] = cp * sr
    R[..., 2, 2] = cp * cr
    return R


def quat_to_R(q):
    """Rotation matrix of a quaternion ``(w, x, y, z)`` (normalized here), MAVLink's order."""
    q = np.asarray(q, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    R = np.empty(q.shape[:-1] + (3, 3))
    R[..., 0, 0] = 1 - 2 * (y * y + z * z)
    R[..., 0, 1] = 2 * (x * y - w * z)
    R[..., 0, 2] = 2 * (x * z + w * y)
    R[..., 1, 0] = 2 * (x * y + w * z)
    R[..., 1, 1] = 1 - 2 * (x * x + z * z)
    R[..., 1, 2] = 2 * (y * z - w * x)
    R[..., 2, 0] = 2 * (x * z - w * y)
    R[..., 2, 1] = 2 * (y * z + w * x)
    R[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return R


def euler_to_quat(roll, pitch, yaw):
    """Quaternion ``(w, x, y, z)`` of Z-Y-X Euler angles (radians)."""
    cr, sr = np.cos(np.asarray(roll) / 2), np.sin(np.asarray(roll) / 2)
    cp, sp = np.cos(np.asarray(pitch) / 2), np.sin(np.asarray(pitch) / 2)
    cy, sy = np.cos(np.asarray(yaw) / 2), np.sin(np.asarray(yaw) / 2)
    return np.stack(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ],
        axis=-1,
    )


def rotation_about(axis, angle):
    """Rotation by ``angle`` (radians) about a unit ``axis`` (Rodrigues); broadcasts over angle."""
    axis = np.asarray(axis, dtype=float)
    angle = np.asarray(angle, dtype=float)
    K = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    s = np.sin(angle)[..., None, None]
    c = np.cos(angle)[..., None, None]
    return np.eye(3) + s * K + (1 - c) * (K @ K)


def rotvec(R):
    """Rotation vector (axis × angle, radians) of rotation matrices (..., 3, 3); angles below π."""
    R = np.asarray(R, dtype=float)
    cos = np.clip((np.trace(R, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)
    angle = np.arccos(cos)
    axis = np.stack(
        [R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]],
        axis=-1,
    )
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = np.where(angle > 1e-12, angle / (2.0 * np.sin(angle)), 0.5)
    return axis * scale[..., None]


def gimbal_yaw_in_earth_frame(flags):
    """Whether a GIMBAL_DEVICE_ATTITUDE_STATUS quaternion has its yaw relative to North.

    The explicit frame flags win; without either, the older rule applies: yaw is
    in the earth frame when YAW_LOCK is set and follows the vehicle otherwise.
    Takes an int or an array of flags.
    """
    flags = np.asarray(flags).astype(np.int64)
    earth = (flags & GIMBAL_DEVICE_FLAGS_YAW_IN_EARTH_FRAME) != 0
    vehicle = (flags & GIMBAL_DEVICE_FLAGS_YAW_IN_VEHICLE_FRAME) != 0
    lock = (flags & GIMBAL_DEVICE_FLAGS_YAW_LOCK) != 0
    return earth | (~vehicle & lock)


def R_yaw(yaw):
    """Rotation about Down by ``yaw`` (radians): the vehicle frame (x forward, level) in NED."""
    yaw = np.asarray(yaw, dtype=float)
    c, s = np.cos(yaw), np.sin(yaw)
    R = np.zeros(yaw.shape + (3, 3))
    R[..., 0, 0], R[..., 0, 1] = c, -s
    R[..., 1, 0], R[..., 1, 1] = s, c
    R[..., 2, 2] = 1.0
    return R


def euler_rates(roll, pitch, p, q, r):
    """Z-Y-X Euler angle rates ``(roll', pitch', yaw')`` (rad/s) of body rates ``p, q, r`` (FRD, rad/s).

    ATTITUDE's ``rollspeed``, ``pitchspeed``, ``yawspeed`` are the body rates (the
    gyros), not the Euler angles' derivatives; they differ once the vehicle leans.
    """
    sr, cr = np.sin(roll), np.cos(roll)
    cp, tp = np.cos(pitch), np.tan(pitch)
    return p + (q * sr + r * cr) * tp, q * cr - r * sr, (q * sr + r * cr) / cp


def R_ned_from_gimbal_device(q, flags, vehicle_yaw, R_ned_from_body=None):
    """Gimbal FRD attitude from GIMBAL_DEVICE_ATTITUDE_STATUS, composed as rotations (no Euler angles).

    ``q`` (w, x, y, z) has roll and pitch relative to the horizon and its yaw
    relative to North or to the vehicle's heading as ``flags`` say
    (:func:`gimbal_yaw_in_earth_frame`): in the vehicle frame, ``R = R_yaw(vehicle_yaw) · R(q)``
    (MAVLink's ``q_earth = q_delta_yaw · q_vehicle``), which holds at pitch −90° too,
    where Euler angles lose the yaw. ``vehicle_yaw`` (radians from North) is the UAV's
    yaw at the same instant.

    ``R_ned_from_body`` given: the quaternion is relative to the airframe (an
    ArduPilot servo mount reports its servo demands, roll and pitch relative to
    the body, under horizon-relative flags), so ``R = R_ned_from_body · R(q)``.
    """
    R = quat_to_R(q)
    if R_ned_from_body is not None:
        return np.asarray(R_ned_from_body) @ R
    earth = np.asarray(gimbal_yaw_in_earth_frame(flags))[..., None, None]
    return np.where(earth, R, R_yaw(vehicle_yaw) @ R)


def R_ned_from_mount_orientation(
    roll_deg, pitch_deg, yaw_rel_deg, vehicle_yaw, R_ned_from_body=None
):
    """Gimbal FRD attitude from ArduPilot's MOUNT_ORIENTATION.

    Roll and pitch are relative to the horizon, ``yaw_rel_deg`` to the vehicle's
    heading: ``R = R_yaw(vehicle_yaw) · R(roll, pitch, yaw_rel)`` with ``vehicle_yaw``
    (radians) from ATTITUDE at the same instant (``yaw_absolute`` is 0 in older
    firmware). With ``R_ned_from_body`` (a servo mount) the angles are relative to
    the airframe: ``R = R_ned_from_body · R(roll, pitch, yaw_rel)``.
    """
    R = euler_to_R(np.radians(roll_deg), np.radians(pitch_deg), np.radians(yaw_rel_deg))
    if R_ned_from_body is not None:
        return np.asarray(R_ned_from_body) @ R
    return R_yaw(vehicle_yaw) @ R


def R_ned_from_fixed_mount(R_ned_from_body, fixed_rpy_deg):
    """Gimbal FRD attitude of a camera rigid on the airframe at ``fixed_rpy_deg`` in body FRD."""
    r, p, y = np.radians(np.asarray(fixed_rpy_deg, dtype=float))
    return np.asarray(R_ned_from_body) @ euler_to_R(r, p, y)


def R_ned_from_cv(R_ned_from_gimbal):
    """OpenCV camera frame in NED, from the gimbal's FRD attitude."""
    return np.asarray(R_ned_from_gimbal) @ R_GIMBAL_FROM_CV
