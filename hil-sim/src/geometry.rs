//! The simulator's 3-D geometry on passangle-geom's nalgebra types: vectors, rotation matrices and
//! rigid transforms, with the simulator's closed-form roll-pitch-yaw rotation and the robot's pose
//! on the ground.
//!
//! Everything is `f64` and `Copy`. Frames follow docs/architecture.md section 8: right-handed, z up, metres and
//! radians. A transform named `world_from_robot` maps points expressed in the robot frame into the
//! world frame (`world_from_robot.apply(p_in_robot) == p_in_world`).

/// A 3-D vector or point, metres unless the name says otherwise (`v.x`, `v.y`, `v.z`).
pub type Vec3 = passangle_geom::V3;

/// A 3x3 rotation matrix (`m[(row, column)]`).
pub type Rot3 = passangle_geom::M3;

/// A rigid transform `p -> rotation * p + translation`: passangle-geom's [`passangle_geom::Pose`].
pub type Isometry = passangle_geom::Pose;

/// Rotation from roll (about x), pitch (about y) and yaw (about z), applied in that order to a
/// vector: `R = Rz(yaw) * Ry(pitch) * Rx(roll)` (the usual aerospace/ROS convention), each entry
/// from the angles' sines and cosines (nalgebra's `Rotation3::from_euler_angles`). The pipeline's
/// [`passangle_geom::rot_from_rpy`] is the same rotation as a product of three exponentials, which
/// rounds differently; the simulator's scenes and sensors are built with this one.
pub fn rot_from_rpy(roll_rad: f64, pitch_rad: f64, yaw_rad: f64) -> Rot3 {
    passangle_geom::nalgebra::Rotation3::from_euler_angles(roll_rad, pitch_rad, yaw_rad)
        .into_inner()
}

/// A transform from a translation and roll/pitch/yaw (see [`rot_from_rpy`]).
pub fn isometry_from_xyz_rpy(
    translation: Vec3,
    roll_rad: f64,
    pitch_rad: f64,
    yaw_rad: f64,
) -> Isometry {
    Isometry {
        rotation: rot_from_rpy(roll_rad, pitch_rad, yaw_rad),
        translation,
    }
}

/// The vector scaled to unit length by multiplying with the reciprocal of its norm (nalgebra's
/// `normalize` divides, which rounds differently); a zero vector is returned unchanged.
pub trait Normalized {
    /// This vector at unit length, or unchanged if it is zero.
    #[must_use]
    fn normalized(self) -> Self;
}

impl Normalized for Vec3 {
    fn normalized(self) -> Self {
        let n = self.norm();
        if n > 0.0 { self * (1.0 / n) } else { self }
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
        isometry_from_xyz_rpy(self.position_m, self.roll_rad, self.pitch_rad, self.yaw_rad)
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
        let r = rot_from_rpy(0.0, 0.0, std::f64::consts::FRAC_PI_2);
        assert!(close(
            r * Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0)
        ));
    }

    #[test]
    fn positive_pitch_tips_x_down() {
        // Right-handed rotation about +y turns +x toward -z.
        let r = rot_from_rpy(0.0, 0.1, 0.0);
        assert!((r * Vec3::new(1.0, 0.0, 0.0)).z < 0.0);
    }

    #[test]
    fn inverse_and_compose_round_trip() {
        let a = isometry_from_xyz_rpy(Vec3::new(1.0, -2.0, 0.5), 0.1, -0.2, 2.5);
        let b = isometry_from_xyz_rpy(Vec3::new(-0.3, 0.7, 0.1), -0.05, 0.3, -1.0);
        let p = Vec3::new(0.4, 0.9, -1.3);
        assert!(close(a.inverse().apply(a.apply(p)), p));
        assert!(close(a.compose(&b).apply(p), a.apply(b.apply(p))));
    }
}
