"""Orientation conversions with the Xsens conventions, shared by drivers and emulators.

Xsens Euler angles are roll about X, pitch about Y, yaw about Z, applied as the
aerospace (Z-Y-X) sequence: R_GS = Rz(yaw) Ry(pitch) Rx(roll); the quaternion
q = (q0, q1, q2, q3) has its real part first and rotates sensor to global frame
(MTi user manual, "Orientation output modes"). Keeping both directions in one module
makes the emulator and the driver agree by construction, and the round trip is tested.
"""

from __future__ import annotations

import math

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]


def quat_to_euler_deg(q: Quat) -> Vec3:
    """(roll, pitch, yaw) in degrees from a unit quaternion (normalised here)."""
    q0, q1, q2, q3 = q
    n = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    if n == 0.0:
        return (math.nan, math.nan, math.nan)
    q0, q1, q2, q3 = q0 / n, q1 / n, q2 / n, q3 / n
    roll = math.atan2(2.0 * (q2 * q3 + q0 * q1), 2.0 * (q0 * q0 + q3 * q3) - 1.0)
    s = 2.0 * (q1 * q3 - q0 * q2)
    pitch = -math.asin(max(-1.0, min(1.0, s)))
    yaw = math.atan2(2.0 * (q1 * q2 + q0 * q3), 2.0 * (q0 * q0 + q1 * q1) - 1.0)
    return (math.degrees(roll), math.degrees(pitch), math.degrees(yaw))


def euler_deg_to_quat(roll_deg: float, pitch_deg: float, yaw_deg: float) -> Quat:
    """Unit quaternion (q0 real first) of R = Rz(yaw) Ry(pitch) Rx(roll)."""
    hr, hp, hy = (math.radians(a) * 0.5 for a in (roll_deg, pitch_deg, yaw_deg))
    cr, sr = math.cos(hr), math.sin(hr)
    cp, sp = math.cos(hp), math.sin(hp)
    cy, sy = math.cos(hy), math.sin(hy)
    return (cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy)


def euler_deg_to_matrix(roll_deg: float, pitch_deg: float, yaw_deg: float
                        ) -> tuple[Vec3, Vec3, Vec3]:
    """Rows of R_GS = Rz(yaw) Ry(pitch) Rx(roll)."""
    r, p, y = (math.radians(a) for a in (roll_deg, pitch_deg, yaw_deg))
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), \
        math.sin(y)
    return ((cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr),
            (sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr),
            (-sp, cp * sr, cp * cr))


def gravity_in_sensor(roll_deg: float, pitch_deg: float, g: float = 9.81) -> Vec3:
    """Specific force a still accelerometer reads (Z up): R_GS^T (0, 0, g)."""
    r, p = math.radians(roll_deg), math.radians(pitch_deg)
    return (-g * math.sin(p), g * math.sin(r) * math.cos(p), g * math.cos(r) * math.cos(p))


def body_rates(euler_deg: Vec3, euler_rate_deg_s: Vec3) -> Vec3:
    """Sensor-frame angular rate (rad/s) from Euler angles and their time derivatives."""
    r, p = math.radians(euler_deg[0]), math.radians(euler_deg[1])
    dr, dp, dy = (math.radians(a) for a in euler_rate_deg_s)
    return (dr - dy * math.sin(p),
            dp * math.cos(r) + dy * math.cos(p) * math.sin(r),
            -dp * math.sin(r) + dy * math.cos(p) * math.cos(r))
