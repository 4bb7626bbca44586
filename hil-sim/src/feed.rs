//! A simulated run's sensor data fed to the offline pipeline in the order it would arrive, for
//! the benches and the evaluation that drive `pipeline` directly.

use pipeline::{DepthImage, LidarFrame, Pipeline, PipelineError, WheelOdometry};

/// One input of the pipeline.
#[derive(Debug, Clone, Copy)]
pub enum Input<'a> {
    /// A VLP-16 frame.
    Lidar(&'a LidarFrame),
    /// A D435 depth frame.
    Depth(&'a DepthImage),
    /// A wheel odometry sample.
    Wheel(&'a WheelOdometry),
}

impl Input<'_> {
    /// Hands this input to `pipeline`.
    pub fn push_to(self, pipeline: &mut Pipeline) -> Result<(), PipelineError> {
        match self {
            Self::Lidar(f) => pipeline.push_lidar_frame(f.clone()),
            Self::Depth(d) => pipeline.push_depth_frame(d.clone()),
            Self::Wheel(w) => pipeline.push_wheel_odometry(*w),
        }
    }
}

/// The inputs in the order they become available: a lidar frame once its 0.1 s sweep is
/// complete, a depth frame at its exposure, a wheel sample at its stamp.
pub fn arrival_order<'a>(
    lidar: &'a [LidarFrame],
    depth: &'a [DepthImage],
    wheel: &'a [WheelOdometry],
) -> Vec<Input<'a>> {
    let mut events: Vec<(f64, Input<'a>)> = lidar
        .iter()
        .map(|f| (f.stamp_s + 0.1, Input::Lidar(f)))
        .chain(depth.iter().map(|d| (d.stamp_s, Input::Depth(d))))
        .chain(wheel.iter().map(|w| (w.stamp_s, Input::Wheel(w))))
        .collect();
    events.sort_by(|a, b| a.0.total_cmp(&b.0));
    events.into_iter().map(|(_, e)| e).collect()
}
