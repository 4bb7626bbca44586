//! Conversions between the sensor and file types (`vlp16`, `cloud_io`) and the pipeline's inputs
//! and outputs, which live here because the `pipeline` crate knows neither the VLP-16 decoder nor
//! the cloud files.

use cloud_io::Cloud;
use pipeline::{BuiltCloud, LidarFrame, LidarPoint};
use vlp16::Frame;

/// The pipeline's frame from a decoded VLP-16 frame whose first firing is at `stamp_s` on the
/// common clock.
pub fn lidar_frame(frame: &Frame, stamp_s: f64) -> LidarFrame {
    LidarFrame {
        stamp_s,
        points: frame
            .points
            .iter()
            .map(|p| LidarPoint {
                xyz_in_lidar_m: [p.x_m, p.y_m, p.z_m],
                time_offset_s: p.time_us * 1e-6,
                azimuth_rad: p.azimuth_rad,
                ring: p.ring,
            })
            .collect(),
    }
}

/// The built cloud's points, for the writers and the angle calculator (a function, not a `From`
/// impl: neither type is this crate's).
pub fn cloud_of(built: &BuiltCloud) -> Cloud {
    Cloud {
        points_m: built.points_in_world.iter().map(|&p| p.into()).collect(),
    }
}
