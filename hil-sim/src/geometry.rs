//! Small, dependency-free 3-D geometry for the simulator: vectors, rotations and rigid transforms.
//!
//! Everything is `f64` and `Copy`. Frames follow docs/architecture.md section 8: right-handed, z up, metres and
//! radians. A transform named `world_from_robot` maps points expressed in the robot frame into the
//! world frame (`world_from_robot.apply(p_in_robot) == p_in_world`).

use std::ops::{Add, Mul, Neg, Sub};

/// A 3-D vector or point, metres unless the name says otherwise.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Vec3 {
    /// x component.
    pub x: f64,
    /// y component.
    pub y: f64,
    /// z component.
    pub z: f64,
}

impl Vec3 {
    /// The zero vector.
    pub const ZERO: Self = Self::new(0.0, 0.0, 0.0);

    /// A vector from its components.
    pub const fn new(x: f64, y: f64, z: f64) -> Self {
        Self { x, y, z }
    }

    /// Dot product.
    pub fn dot(self, o: Self) -> f64 {
        self.x * o.x + self.y * o.y + self.z * o.z
    }

    /// Cross product.
    #[must_use]
    pub fn cross(self, o: Self) -> Self {
        Self::new(
            self.y * o.z - self.z * o.y,
            self.z * o.x - self.x * o.z,
            self.x * o.y - self.y * o.x,
        )
    }

    /// Euclidean length.
    pub fn norm(self) -> f64 {
        self.dot(self).sqrt()
    }

    /// This vector scaled to unit length (returns the input unchanged if it is zero).
    #[must_use]
    pub fn normalized(self) -> Self {
        let n = self.norm();
        if n > 0.0 { self * (1.0 / n) } else { self }
    }
}

impl Add for Vec3 {
    type Output = Self;
    fn add(self, o: Self) -> Self {
        Self::new(self.x + o.x, self.y + o.y, self.z + o.z)
    }
}

impl Sub for Vec3 {
    type Output = Self;
    fn sub(self, o: Self) -> Self {
        Self::new(self.x - o.x, self.y - o.y, self.z - o.z)
    }
}

impl Neg for Vec3 {
    type Output = Self;
    fn neg(self) -> Self {
        Self::new(-self.x, -self.y, -self.z)
    }
}

impl Mul<f64> for Vec3 {
    type Output = Self;
    fn mul(self, s: f64) -> Self {
        Self::new(self.x * s, self.y * s, self.z * s)
    }
}

/// A 3x3 rotation matrix, row-major.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rot3(pub [[f64; 3]; 3]);

impl Rot3 {
    /// The identity rotation.
    pub const IDENTITY: Self = Self([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]);

    /// Rotation from roll (about x), pitch (about y) and yaw (about z), applied in that order to a
    /// vector: `R = Rz(yaw) * Ry(pitch) * Rx(roll)` (the usual aerospace/ROS convention).
    pub fn from_rpy(roll_rad: f64, pitch_rad: f64, yaw_rad: f64) -> Self {
        let (sr, cr) = roll_rad.sin_cos();
        let (sp, cp) = pitch_rad.sin_cos();
        let (sy, cy) = yaw_rad.sin_cos();
        Self([
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ])
    }

    /// Rotate a vector.
    pub fn apply(&self, v: Vec3) -> Vec3 {
        let m = &self.0;
        Vec3::new(
            m[0][0] * v.x + m[0][1] * v.y + m[0][2] * v.z,
            m[1][0] * v.x + m[1][1] * v.y + m[1][2] * v.z,
            m[2][0] * v.x + m[2][1] * v.y + m[2][2] * v.z,
        )
    }

    /// Matrix product `self * o`.
    #[must_use]
    pub fn compose(&self, o: &Self) -> Self {
        let (a, b) = (&self.0, &o.0);
        let mut out = [[0.0; 3]; 3];
        for (i, row) in out.iter_mut().enumerate() {
            for (j, cell) in row.iter_mut().enumerate() {
                *cell = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
            }
        }
        Self(out)
    }

    /// The inverse rotation (the transpose).
    #[must_use]
    pub fn transpose(&self) -> Self {
        let m = &self.0;
        Self([
            [m[0][0], m[1][0], m[2][0]],
            [m[0][1], m[1][1], m[2][1]],
            [m[0][2], m[1][2], m[2][2]],
        ])
    }
}

/// A rigid transform `p -> rotation * p + translation`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Isometry {
    /// Rotation part.
    pub rotation: Rot3,
    /// Translation part, metres.
    pub translation: Vec3,
}

impl Isometry {
    /// The identity transform.
    pub const IDENTITY: Self = Self {
        rotation: Rot3::IDENTITY,
        translation: Vec3::ZERO,
    };

    /// A transform from a translation and roll/pitch/yaw (see [`Rot3::from_rpy`]).
    pub fn from_xyz_rpy(translation: Vec3, roll_rad: f64, pitch_rad: f64, yaw_rad: f64) -> Self {
        Self {
            rotation: Rot3::from_rpy(roll_rad, pitch_rad, yaw_rad),
            translation,
        }
    }

    /// Map a point.
    pub fn apply(&self, p: Vec3) -> Vec3 {
        self.rotation.apply(p) + self.translation
    }

    /// Map a direction (rotation only).
    pub fn apply_vector(&self, v: Vec3) -> Vec3 {
        self.rotation.apply(v)
    }

    /// `a_from_c = a_from_b.compose(&b_from_c)`.
    #[must_use]
    pub fn compose(&self, o: &Self) -> Self {
        Self {
            rotation: self.rotation.compose(&o.rotation),
            translation: self.rotation.apply(o.translation) + self.translation,
        }
    }

    /// The inverse transform.
    #[must_use]
    pub fn inverse(&self) -> Self {
        let rt = self.rotation.transpose();
        Self {
            rotation: rt,
            translation: -rt.apply(self.translation),
        }
    }
}

/// A robot pose on (or near) the ground: position and roll/pitch/yaw, in the world (vehicle) frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Pose {
    /// Position of the robot's base origin (on the ground below its centre), metres.
    pub position_m: Vec3,
    /// Roll about x, radians.
    pub roll_rad: f64,
    /// Pitch about y, radians.
    pub pitch_rad: f64,
    /// Yaw about z, radians.
    pub yaw_rad: f64,
}

impl Pose {
    /// This pose as the transform `world_from_robot`.
    pub fn to_isometry(&self) -> Isometry {
        Isometry::from_xyz_rpy(self.position_m, self.roll_rad, self.pitch_rad, self.yaw_rad)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: Vec3, b: Vec3) -> bool {
        (a - b).norm() < 1e-12
    }

    #[test]
    fn yaw_quarter_turn_maps_x_to_y() {
        let r = Rot3::from_rpy(0.0, 0.0, std::f64::consts::FRAC_PI_2);
        assert!(close(
            r.apply(Vec3::new(1.0, 0.0, 0.0)),
            Vec3::new(0.0, 1.0, 0.0)
        ));
    }

    #[test]
    fn positive_pitch_tips_x_down() {
        // Right-handed rotation about +y turns +x toward -z.
        let r = Rot3::from_rpy(0.0, 0.1, 0.0);
        assert!(r.apply(Vec3::new(1.0, 0.0, 0.0)).z < 0.0);
    }

    #[test]
    fn inverse_and_compose_round_trip() {
        let a = Isometry::from_xyz_rpy(Vec3::new(1.0, -2.0, 0.5), 0.1, -0.2, 2.5);
        let b = Isometry::from_xyz_rpy(Vec3::new(-0.3, 0.7, 0.1), -0.05, 0.3, -1.0);
        let p = Vec3::new(0.4, 0.9, -1.3);
        assert!(close(a.inverse().apply(a.apply(p)), p));
        assert!(close(a.compose(&b).apply(p), a.apply(b.apply(p))));
    }
}
