//! Conversions between the sensor and file types of this crate and the pipeline's inputs and
//! outputs, which live here because the `pipeline` crate knows neither the VLP-16 decoder nor the
//! cloud files.

use crate::cloud::Cloud;
use crate::vlp16::Frame;
use pipeline::{BuiltCloud, LidarFrame, LidarPoint};

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

impl From<&BuiltCloud> for Cloud {
    /// The built cloud's points, for the writers and the angle calculator.
    fn from(built: &BuiltCloud) -> Self {
        Cloud {
            points_m: built.points_in_world.clone(),
        }
    }
}
