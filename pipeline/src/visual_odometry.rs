//! Step 6a, visual odometry from D435 depth frames (paper section 3.4 uses image features; this is
//! depth-only point-to-plane ICP, chosen because the D435 under a car looks at a dim, textureless
//! underbody at 0.2-0.5 m where its depth is precise to millimetres but its IR image has few
//! trackable corners).
//!
//! Each depth frame is back-projected with its intrinsics (optical frame: x right, y down, z
//! forward). The current frame's pixels on a `pixel_stride` grid are registered to the previous
//! frame by **projective data association** (KinectFusion): a current point moved by the estimate is
//! projected into the previous image, and the previous frame's vertex at that pixel, with a normal
//! from its image neighbours, is its correspondence. Gauss-Newton on the point-to-plane residuals
//! with a Huber kernel, all six parameters, then the same degeneracy remapping as the laser (a flat
//! underbody alone fixes only z, roll and pitch; the prior fills x, y and yaw).
//!
//! The result is `robot_prev_from_robot_cur`, converted through the camera mount.

use super::config::VisualOdometryConfig;
use super::geom::{Pose, V3, solve_spd, symmetric_eigen};

/// One D435 depth frame with its intrinsics.
#[derive(Debug, Clone, PartialEq)]
pub struct DepthImage {
    /// Exposure time, seconds on the pipeline's common clock.
    pub stamp_s: f64,
    /// Image width, pixels.
    pub width: usize,
    /// Image height, pixels.
    pub height: usize,
    /// Focal lengths and principal point, pixels: `[fx, fy, cx, cy]`.
    pub intrinsics_px: [f64; 4],
    /// Metres per depth unit (D435 default 0.001).
    pub depth_scale_m: f64,
    /// Row-major depth, `width * height` values; 0 means no depth.
    pub depth: Vec<u16>,
}

impl DepthImage {
    /// Checks the sizes and intrinsics; the error names the field.
    pub fn check(&self) -> Result<(), String> {
        if self.depth.len() != self.width * self.height {
            return Err(format!(
                "depth frame at {} s: {} depth values for {}x{} pixels",
                self.stamp_s,
                self.depth.len(),
                self.width,
                self.height
            ));
        }
        if !self.intrinsics_px.iter().all(|v| v.is_finite()) || self.intrinsics_px[0] <= 0.0 {
            return Err(format!("depth frame at {} s: bad intrinsics", self.stamp_s));
        }
        if !(self.depth_scale_m > 0.0) || !self.stamp_s.is_finite() {
            return Err(format!(
                "depth frame at {} s: bad depth scale or stamp",
                self.stamp_s
            ));
        }
        Ok(())
    }

    /// Vertex at pixel `(u, v)` in the optical frame, if it has a depth in range.
    pub fn vertex(&self, u: usize, v: usize, config: &VisualOdometryConfig) -> Option<V3> {
        let d = f64::from(*self.depth.get(v * self.width + u)?) * self.depth_scale_m;
        if !(config.min_depth_m..=config.max_depth_m).contains(&d) {
            return None;
        }
        let [fx, fy, cx, cy] = self.intrinsics_px;
        Some(V3::new(
            (u as f64 - cx) * d / fx,
            (v as f64 - cy) * d / fy,
            d,
        ))
    }

    /// Unit normal at `(u, v)` from the neighbours `step` pixels away, facing the camera.
    fn normal(&self, u: usize, v: usize, step: usize, config: &VisualOdometryConfig) -> Option<V3> {
        if u < step || v < step || u + step >= self.width || v + step >= self.height {
            return None;
        }
        let p = self.vertex(u, v, config)?;
        // Neighbours across a depth discontinuity (more than 5 % of the depth away) would give a
        // normal that belongs to neither surface: no normal there.
        let near = |q: V3| ((q[2] - p[2]).abs() <= 0.05 * p[2]).then_some(q);
        let dx =
            near(self.vertex(u + step, v, config)?)? - near(self.vertex(u - step, v, config)?)?;
        let dy =
            near(self.vertex(u, v + step, config)?)? - near(self.vertex(u, v - step, config)?)?;
        let n = dx.cross(&dy);
        let len = n.norm();
        if !(len > 0.0) {
            return None;
        }
        let n = n * (1.0 / len);
        Some(if n.dot(&p) > 0.0 { -n } else { n })
    }

    /// Points on the stride grid, optical frame.
    pub fn sampled_points(&self, config: &VisualOdometryConfig) -> Vec<V3> {
        let s = config.pixel_stride.max(1);
        let mut out = Vec::new();
        for v in (0..self.height).step_by(s) {
            for u in (0..self.width).step_by(s) {
                if let Some(p) = self.vertex(u, v, config) {
                    out.push(p);
                }
            }
        }
        out
    }
}

/// One visual odometry step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VisualStep {
    /// Stamp of the previous depth frame, seconds.
    pub from_s: f64,
    /// Stamp of this depth frame, seconds.
    pub to_s: f64,
    /// `robot_prev_from_robot_cur`.
    pub robot_prev_from_cur: Pose,
    /// Per parameter `[rx, ry, rz, tx, ty, tz]` (robot frame): not determined by the depth.
    pub degenerate: [bool; 6],
    /// Correspondences used.
    pub residuals: usize,
}

/// Register `current` to `previous`: `camera_prev_from_cur`, from `init`. Returns the pose, the
/// per-residual normal matrix and the residual count.
pub fn register_depth(
    previous: &DepthImage,
    current: &DepthImage,
    init: Pose,
    config: &VisualOdometryConfig,
) -> (Pose, [[f64; 6]; 6], usize) {
    let source = current.sampled_points(config);
    let [fx, fy, cx, cy] = previous.intrinsics_px;
    let step = (config.pixel_stride / 2).max(1);
    let mut pose = init;
    let mut h_last = [[0.0; 6]; 6];
    let mut n_last = 0;
    for _ in 0..config.iterations {
        let mut h = [[0.0; 6]; 6];
        let mut g = [0.0; 6];
        let mut n = 0;
        for &p in &source {
            let q = pose.apply(p);
            if q[2] <= 0.0 {
                continue;
            }
            let u = (fx * q[0] / q[2] + cx).round();
            let v = (fy * q[1] / q[2] + cy).round();
            if u < 0.0 || v < 0.0 {
                continue;
            }
            let (u, v) = (u as usize, v as usize);
            let (Some(target), Some(normal)) = (
                previous.vertex(u, v, config),
                previous.normal(u, v, step, config),
            ) else {
                continue;
            };
            let r = normal.dot(&(q - target));
            if r.abs() > config.max_residual_m {
                continue;
            }
            let k = 0.01;
            let w = if r.abs() <= k { 1.0 } else { k / r.abs() };
            let jw = q.cross(&normal);
            let j = [jw[0], jw[1], jw[2], normal[0], normal[1], normal[2]];
            for a in 0..6 {
                g[a] += w * j[a] * r;
                for b in 0..6 {
                    h[a][b] += w * j[a] * j[b];
                }
            }
            n += 1;
        }
        if n < 6 {
            break;
        }
        h_last = h;
        n_last = n;
        let mut damped = h;
        for (i, row) in damped.iter_mut().enumerate() {
            row[i] += 1e-6 + 1e-3 * h[i][i];
        }
        let Some(x) = solve_spd(&damped, &g.map(|v| -v)) else {
            break;
        };
        pose = Pose::from_increment(x).compose(&pose);
        if x.iter().map(|v| v * v).sum::<f64>() < 1e-14 {
            break;
        }
    }
    if n_last > 0 {
        for row in &mut h_last {
            for v in row.iter_mut() {
                *v /= n_last as f64;
            }
        }
    }
    (pose, h_last, n_last)
}

/// Depth odometry between consecutive frames.
#[derive(Debug, Clone)]
pub struct VisualOdometry {
    config: VisualOdometryConfig,
    robot_from_camera: Pose,
    previous: Option<DepthImage>,
    degeneracy_eigen_min: f64,
}

impl VisualOdometry {
    /// A new tracker for a camera at `robot_from_camera`.
    pub fn new(
        config: VisualOdometryConfig,
        robot_from_camera: Pose,
        degeneracy_eigen_min: f64,
    ) -> Self {
        Self {
            config,
            robot_from_camera,
            previous: None,
            degeneracy_eigen_min,
        }
    }

    /// Track `frame` against the previous one; `prior` is the predicted
    /// `robot_prev_from_robot_cur` (identity if nothing better is known). `None` for the first
    /// frame or when too few pixels matched.
    pub fn push(&mut self, frame: DepthImage, prior: Pose) -> Option<VisualStep> {
        let previous = self.previous.replace(frame);
        let previous = previous?;
        let current = self.previous.as_ref()?;
        let cam_from_robot = self.robot_from_camera.inverse();
        let init = cam_from_robot
            .compose(&prior)
            .compose(&self.robot_from_camera);
        let (cam_pose, h, n) = register_depth(&previous, current, init, &self.config);
        if n < 50 {
            return None;
        }
        let robot_pose = self
            .robot_from_camera
            .compose(&cam_pose)
            .compose(&cam_from_robot);
        let degenerate =
            degenerate_robot_axes(&h, &self.robot_from_camera, self.degeneracy_eigen_min);
        Some(VisualStep {
            from_s: previous.stamp_s,
            to_s: current.stamp_s,
            robot_prev_from_cur: robot_pose,
            degenerate,
            residuals: n,
        })
    }
}

/// Which robot-frame parameters lie mostly in the weak eigen-directions of a camera-frame normal
/// matrix.
fn degenerate_robot_axes(
    h_cam: &[[f64; 6]; 6],
    robot_from_camera: &Pose,
    eigen_min: f64,
) -> [bool; 6] {
    let (values, vectors) = symmetric_eigen(h_cam);
    let r = robot_from_camera.rotation;
    let mut weight = [0.0; 6];
    for (e, &value) in values.iter().enumerate() {
        if value >= eigen_min {
            continue;
        }
        // Rotate the camera-frame direction's rotation and translation parts into the robot frame
        // (the lever arm of the mount is ignored: only which axes are weak matters here).
        let w = r * V3::new(vectors[0][e], vectors[1][e], vectors[2][e]);
        let t = r * V3::new(vectors[3][e], vectors[4][e], vectors[5][e]);
        for k in 0..3 {
            weight[k] += w[k] * w[k];
            weight[k + 3] += t[k] * t[k];
        }
    }
    weight.map(|w| w > 0.5)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// Render a depth image of a ceiling at height `h` above a camera looking up, with a box of
    /// `bump` metres hanging down so the motion along the ceiling is observable.
    pub(crate) fn render(camera_in_world: &Pose, stamp_s: f64) -> DepthImage {
        let (width, height) = (160, 120);
        let intrinsics_px = [120.0, 120.0, 80.0, 60.0];
        let mut depth = vec![0u16; width * height];
        for v in 0..height {
            for u in 0..width {
                let dir_cam = V3::new((u as f64 - 80.0) / 120.0, (v as f64 - 60.0) / 120.0, 1.0);
                let o = camera_in_world.translation;
                let d = camera_in_world.apply_vector(dir_cam);
                // Scene: a ceiling at z = 0.5 with shallow panels hanging 2-4 cm below it (the
                // structure that makes motion along the ceiling observable).
                let mut best = f64::INFINITY;
                for (z, x0, x1, y0, y1) in [
                    (0.5, -9.0, 9.0, -9.0, 9.0),
                    (0.47, 0.1, 0.3, -0.1, 0.1),
                    (0.46, -0.2, -0.05, 0.05, 0.3),
                    (0.48, -9.0, 9.0, 0.25, 0.35),
                    (0.47, 0.35, 0.5, -0.4, -0.15),
                ] {
                    if d[2] <= 0.0 {
                        continue;
                    }
                    let t = (z - o[2]) / d[2];
                    let p = add3(o, d, t);
                    if t > 0.0 && (x0..x1).contains(&p[0]) && (y0..y1).contains(&p[1]) {
                        best = best.min(t);
                    }
                }
                // Two pipes: one along y (pins x), one along x (pins y).
                for (axis, c0, c1, r) in [(1, 0.2, 0.42, 0.04), (0, -0.15, 0.43, 0.035)] {
                    if let Some(t) = ray_cylinder(o, d, axis, c0, c1, r) {
                        best = best.min(t);
                    }
                }
                if best.is_finite() {
                    depth[v * width + u] = (best * 1000.0).round() as u16;
                }
            }
        }
        DepthImage {
            stamp_s,
            width,
            height,
            intrinsics_px,
            depth_scale_m: 0.001,
            depth,
        }
    }

    /// First hit of a ray with an infinite cylinder along world axis `axis` (0 = x, 1 = y) whose
    /// axis passes through (`c0`, `c1`) in the other horizontal coordinate and z.
    fn ray_cylinder(o: V3, d: V3, axis: usize, c0: f64, c1: f64, r: f64) -> Option<f64> {
        let other = 1 - axis;
        let (ox, oz) = (o[other] - c0, o[2] - c1);
        let (dx, dz) = (d[other], d[2]);
        let a = dx * dx + dz * dz;
        let b = 2.0 * (ox * dx + oz * dz);
        let c = ox * ox + oz * oz - r * r;
        let disc = b * b - 4.0 * a * c;
        if a <= 0.0 || disc < 0.0 {
            return None;
        }
        let t = (-b - disc.sqrt()) / (2.0 * a);
        (t > 0.0).then_some(t)
    }

    fn add3(o: V3, d: V3, t: f64) -> V3 {
        V3::new(o[0] + d[0] * t, o[1] + d[1] * t, o[2] + d[2] * t)
    }

    #[test]
    fn recovers_camera_motion_under_a_structured_ceiling() {
        let mounts = super::super::config::MountConfig::default();
        let robot_from_camera = Pose::from_xyz_rpy(mounts.camera_xyz_m, mounts.camera_rpy_rad);
        let robot0 = Pose::IDENTITY;
        let robot1 = Pose::from_xyz_rpy([0.02, 0.004, 0.0], [0.0, 0.0, 0.01]);
        let f0 = render(&robot0.compose(&robot_from_camera), 0.0);
        let f1 = render(&robot1.compose(&robot_from_camera), 0.033);
        let mut vo = VisualOdometry::new(
            VisualOdometryConfig {
                pixel_stride: 2,
                iterations: 20,
                ..VisualOdometryConfig::default()
            },
            robot_from_camera,
            1e-4,
        );
        assert!(vo.push(f0, Pose::IDENTITY).is_none());
        let truth = robot0.inverse().compose(&robot1);
        // The prior (from wheel odometry in the pipeline) is off by 8 mm and 5 mrad.
        let prior = Pose::from_xyz_rpy([0.008, -0.004, 0.0], [0.0, 0.0, 0.005]).compose(&truth);
        let step = vo.push(f1, prior).unwrap();
        let err = step
            .robot_prev_from_cur
            .compose(&truth.inverse())
            .to_increment();
        assert!(err.iter().all(|e| e.abs() < 2e-3), "{err:?} {step:?}");
    }

    #[test]
    fn bad_frames_are_named() {
        let mut f = render(&Pose::IDENTITY, 1.5);
        f.depth.pop();
        let e = f.check().unwrap_err();
        assert!(e.contains("1.5 s") && e.contains("160x120"), "{e}");
    }
}
