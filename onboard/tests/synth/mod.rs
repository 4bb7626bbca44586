//! Synthetic vehicles for the angle calculator's tests and benchmark, and their true angles.
//!
//! A vehicle is an underside profile (a polyline in the side view, extruded across the lateral band),
//! optional narrow parts (boxes: tow hitch, differential, skid plate), four tyres (inner sidewall,
//! tread, flattened contact patch) under wheel-arch liners, and the ground. Everything is sampled on
//! a regular grid at a chosen spacing; optional range noise is applied along the ray from a simulated
//! sensor on the robot's path (centreline, 0.12 m up, within 1 m of the point along x).
//!
//! The true angles ([`truth`]) come from the exact geometry by brute force: a line tangent to the
//! tyre's static-loaded-radius circle is rotated about the circle (bisection on its slope) until it
//! touches the densely subdivided profile; breakover does the same per crest point for both tyres.
//! This deliberately shares nothing with the calculator (no envelope, no fits, no closed form).
#![allow(
    dead_code,
    clippy::missing_panics_doc,
    clippy::struct_field_names,
    missing_docs
)]

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A box part (vehicle frame, metres).
#[derive(Debug, Clone, Copy)]
pub struct Part {
    pub x: (f64, f64),
    pub y: (f64, f64),
    pub z: (f64, f64),
}

/// A synthetic vehicle, vehicle frame: x forward, y left, z up, origin on the ground mid-wheelbase.
#[derive(Debug, Clone)]
pub struct Vehicle {
    pub name: &'static str,
    pub wheelbase_m: f64,
    pub track_m: f64,
    pub loaded_radius_m: f64,
    pub free_radius_m: f64,
    pub tyre_width_m: f64,
    pub rim_radius_m: f64,
    /// Underside profile (x, z), front to rear.
    pub profile: Vec<(f64, f64)>,
    pub parts: Vec<Part>,
}

impl Vehicle {
    pub fn front_x(&self) -> f64 {
        self.wheelbase_m / 2.0
    }
    pub fn rear_x(&self) -> f64 {
        -self.wheelbase_m / 2.0
    }
    pub fn inner_face_y(&self) -> f64 {
        self.track_m / 2.0 - self.tyre_width_m / 2.0
    }
    /// Half width of the extruded underside (inside the inner tyre faces).
    pub fn body_half_width(&self) -> f64 {
        self.inner_face_y() - 0.03
    }
}

fn arc(cx: f64, cz: f64, r: f64, from_deg: f64, to_deg: f64, step_m: f64) -> Vec<(f64, f64)> {
    let n = ((to_deg - from_deg).abs().to_radians() * r / step_m)
        .ceil()
        .max(1.0) as usize;
    (0..=n)
        .map(|i| {
            let t = (from_deg + (to_deg - from_deg) * i as f64 / n as f64).to_radians();
            (cx + r * t.cos(), cz + r * t.sin())
        })
        .collect()
}

pub fn sedan() -> Vehicle {
    Vehicle {
        name: "sedan",
        wheelbase_m: 2.80,
        track_m: 1.58,
        loaded_radius_m: 0.305,
        free_radius_m: 0.320,
        tyre_width_m: 0.225,
        rim_radius_m: 0.215,
        profile: vec![
            (2.35, 0.52),
            (2.35, 0.27),
            (2.10, 0.215),
            (1.90, 0.175),
            (1.78, 0.17),
            (1.55, 0.16),
            (1.0, 0.15),
            (0.2, 0.135),
            (-0.6, 0.14),
            (-1.1, 0.16),
            (-1.75, 0.19),
            (-2.10, 0.26),
            (-2.42, 0.36),
            (-2.45, 0.55),
        ],
        parts: vec![],
    }
}

pub fn suv() -> Vehicle {
    Vehicle {
        name: "suv",
        wheelbase_m: 2.85,
        track_m: 1.64,
        loaded_radius_m: 0.36,
        free_radius_m: 0.375,
        tyre_width_m: 0.255,
        rim_radius_m: 0.24,
        profile: vec![
            (2.40, 0.65),
            (2.38, 0.45),
            (2.20, 0.36),
            (1.95, 0.30),
            (1.6, 0.25),
            (0.8, 0.22),
            (-0.8, 0.22),
            (-1.6, 0.26),
            (-2.0, 0.34),
            (-2.30, 0.46),
            (-2.33, 0.70),
        ],
        // Rear differential.
        parts: vec![Part {
            x: (-1.55, -1.25),
            y: (-0.15, 0.12),
            z: (0.205, 0.30),
        }],
    }
}

pub fn off_roader() -> Vehicle {
    Vehicle {
        name: "off-roader",
        wheelbase_m: 2.46,
        track_m: 1.60,
        loaded_radius_m: 0.40,
        free_radius_m: 0.42,
        tyre_width_m: 0.28,
        rim_radius_m: 0.22,
        profile: vec![
            (1.98, 0.80),
            (1.98, 0.62),
            (1.85, 0.55),
            (1.62, 0.42),
            (1.2, 0.33),
            (-1.2, 0.33),
            (-1.55, 0.45),
            (-1.80, 0.58),
            (-1.80, 0.85),
        ],
        // Skid plate under the engine, and a front axle differential.
        parts: vec![
            Part {
                x: (0.55, 1.10),
                y: (-0.35, 0.35),
                z: (0.29, 0.33),
            },
            Part {
                x: (1.10, 1.36),
                y: (-0.05, 0.18),
                z: (0.255, 0.36),
            },
        ],
    }
}

pub fn pickup_with_hitch() -> Vehicle {
    Vehicle {
        name: "pickup+hitch",
        wheelbase_m: 3.57,
        track_m: 1.72,
        loaded_radius_m: 0.39,
        free_radius_m: 0.405,
        tyre_width_m: 0.275,
        rim_radius_m: 0.25,
        profile: vec![
            (2.78, 0.80),
            (2.76, 0.52),
            (2.55, 0.42),
            (2.20, 0.32),
            (1.4, 0.27),
            (-1.4, 0.26),
            (-2.2, 0.40),
            (-2.90, 0.58),
            (-2.92, 0.80),
        ],
        // Hitch receiver and ball mount below the bumper.
        parts: vec![
            Part {
                x: (-3.12, -2.70),
                y: (-0.035, 0.035),
                z: (0.46, 0.53),
            },
            Part {
                x: (-3.16, -3.08),
                y: (-0.03, 0.03),
                z: (0.43, 0.53),
            },
        ],
    }
}

pub fn van() -> Vehicle {
    Vehicle {
        name: "van",
        wheelbase_m: 3.66,
        track_m: 1.70,
        loaded_radius_m: 0.335,
        free_radius_m: 0.35,
        tyre_width_m: 0.235,
        rim_radius_m: 0.2,
        profile: vec![
            (2.80, 0.60),
            (2.79, 0.36),
            (2.55, 0.28),
            (2.1, 0.21),
            (1.0, 0.19),
            (-1.0, 0.20),
            (-1.9, 0.22),
            (-2.6, 0.31),
            (-3.05, 0.42),
            (-3.06, 0.65),
        ],
        parts: vec![],
    }
}

/// A car with rounded bumpers: the approach and departure lines touch smooth arcs, not corners.
pub fn rounded_car() -> Vehicle {
    let mut profile = vec![(2.42, 0.56)];
    // Front: arc of radius 0.45 m, lowest at x 2.0, z 0.20.
    profile.extend(
        arc(2.0, 0.65, 0.45, 0.0, -90.0, 0.002)
            .into_iter()
            .filter(|p| p.1 < 0.55),
    );
    profile.extend([(1.6, 0.17), (0.0, 0.145), (-1.5, 0.17)]);
    // Rear: arc of radius 0.5 m, lowest at x -2.0, z 0.24.
    profile.extend(
        arc(-2.0, 0.74, 0.5, -90.0, -180.0, 0.002)
            .into_iter()
            .filter(|p| p.1 < 0.62),
    );
    profile.push((-2.52, 0.66));
    Vehicle {
        name: "rounded",
        wheelbase_m: 2.70,
        track_m: 1.56,
        loaded_radius_m: 0.31,
        free_radius_m: 0.325,
        tyre_width_m: 0.215,
        rim_radius_m: 0.2,
        profile,
        parts: vec![],
    }
}

pub fn all() -> Vec<Vehicle> {
    vec![
        sedan(),
        suv(),
        off_roader(),
        pickup_with_hitch(),
        van(),
        rounded_car(),
    ]
}

// ---------------------------------------------------------------------------------------------
// Sampling.

/// How to sample a vehicle.
#[derive(Debug, Clone, Copy)]
pub struct Scan {
    /// Point spacing on the vehicle (metres).
    pub spacing_m: f64,
    /// Ground grid spacing (metres).
    pub ground_spacing_m: f64,
    /// Range noise sigma (metres), along the sensor ray.
    pub noise_m: f64,
    /// Lone low outliers added under the body (each a single point 5-15 cm below the envelope).
    pub outliers: usize,
    pub seed: u64,
    /// 0: the body grid contains every profile vertex. > 0: body samples every `spacing_m` along
    /// the profile's arc length starting at this offset, so corners are generally missed.
    pub phase_m: f64,
}

impl Scan {
    pub fn noiseless(spacing_m: f64) -> Self {
        Self {
            spacing_m,
            ground_spacing_m: 0.02,
            noise_m: 0.0,
            outliers: 0,
            seed: 1,
            phase_m: 0.0,
        }
    }
}

fn steps(a: f64, b: f64, s: f64) -> impl Iterator<Item = f64> {
    let n = ((b - a).abs() / s).ceil().max(1.0) as usize;
    (0..=n).map(move |i| a + (b - a) * i as f64 / n as f64)
}

/// Points of a polyline's side view, sampled at `s` including every vertex.
fn polyline_samples(profile: &[(f64, f64)], s: f64) -> Vec<(f64, f64)> {
    let mut out = vec![profile[0]];
    for w in profile.windows(2) {
        let ((x0, z0), (x1, z1)) = (w[0], w[1]);
        let len = (x1 - x0).hypot(z1 - z0);
        let n = (len / s).ceil().max(1.0) as usize;
        out.extend((1..=n).map(|i| {
            let t = i as f64 / n as f64;
            (x0 + (x1 - x0) * t, z0 + (z1 - z0) * t)
        }));
    }
    out
}

fn box_faces(p: &Part, s: f64, out: &mut Vec<[f64; 3]>) {
    for x in steps(p.x.0, p.x.1, s) {
        for y in steps(p.y.0, p.y.1, s) {
            out.push([x, y, p.z.0]);
        }
        for z in steps(p.z.0, p.z.1, s) {
            out.push([x, p.y.0, z]);
            out.push([x, p.y.1, z]);
        }
    }
    for y in steps(p.y.0, p.y.1, s) {
        for z in steps(p.z.0, p.z.1, s) {
            out.push([p.x.0, y, z]);
            out.push([p.x.1, y, z]);
        }
    }
}

fn tyre(v: &Vehicle, xc: f64, left: bool, s: f64, out: &mut Vec<[f64; 3]>) {
    let (r, big_r, w) = (v.loaded_radius_m, v.free_radius_m, v.tyre_width_m);
    let sign = if left { 1.0 } else { -1.0 };
    let y_in = sign * v.inner_face_y();
    let y_out = sign * (v.inner_face_y() + w);
    // Inner sidewall annulus.
    for rho in steps(v.rim_radius_m, big_r, s) {
        let n = (std::f64::consts::TAU * rho / s).ceil() as usize;
        for k in 0..n {
            let t = k as f64 / n as f64 * std::f64::consts::TAU;
            let z = r + rho * t.sin();
            if z >= 0.0 {
                out.push([xc + rho * t.cos(), y_in, z]);
            }
        }
    }
    // Tread, flattened where it would go below the ground.
    let n = (std::f64::consts::TAU * big_r / s).ceil() as usize;
    for k in 0..n {
        let t = k as f64 / n as f64 * std::f64::consts::TAU;
        let (x, z) = (xc + big_r * t.cos(), (r + big_r * t.sin()).max(0.0));
        for y in steps(y_in, y_out, s) {
            out.push([x, y, z]);
        }
    }
    // Wheel-arch liner 5 cm above the tread.
    for (x, z) in arc(xc, r, big_r + 0.05, 25.0, 155.0, s) {
        for y in steps(y_in, y_out, s) {
            out.push([x, y, z]);
        }
    }
}

/// Points every `s` along the polyline's arc length, the first at `phase` (vertices not included).
fn polyline_phased(profile: &[(f64, f64)], s: f64, phase: f64) -> Vec<(f64, f64)> {
    let mut out = Vec::new();
    let mut next = phase;
    let mut start = 0.0;
    for w in profile.windows(2) {
        let ((x0, z0), (x1, z1)) = (w[0], w[1]);
        let len = (x1 - x0).hypot(z1 - z0);
        while next <= start + len {
            let t = if len > 0.0 { (next - start) / len } else { 0.0 };
            out.push((x0 + (x1 - x0) * t, z0 + (z1 - z0) * t));
            next += s;
        }
        start += len;
    }
    out
}

/// Sample the vehicle in its own frame.
pub fn sample(v: &Vehicle, scan: Scan) -> Vec<[f64; 3]> {
    let s = scan.spacing_m;
    let mut out = Vec::new();
    let hw = v.body_half_width();
    let profile = if scan.phase_m > 0.0 {
        polyline_phased(&v.profile, s, scan.phase_m)
    } else {
        polyline_samples(&v.profile, s)
    };
    for (x, z) in profile {
        for y in steps(-hw, hw, s) {
            out.push([x, y, z]);
        }
    }
    for p in &v.parts {
        box_faces(p, s, &mut out);
    }
    for xc in [v.front_x(), v.rear_x()] {
        tyre(v, xc, true, s, &mut out);
        tyre(v, xc, false, s, &mut out);
    }
    // Ground, not under the contact patches.
    let x_ext = v
        .profile
        .iter()
        .fold((0.0f64, 0.0f64), |a, p| (a.0.min(p.0), a.1.max(p.0)));
    let half_patch = (v.free_radius_m.powi(2) - v.loaded_radius_m.powi(2)).sqrt();
    let g = scan.ground_spacing_m;
    for x in steps(x_ext.0 - 1.0, x_ext.1 + 1.0, g) {
        for y in steps(-1.4, 1.4, g) {
            let under_tyre = [v.front_x(), v.rear_x()]
                .iter()
                .any(|&xc| (x - xc).abs() < half_patch)
                && (y.abs() - v.inner_face_y()).abs() < v.tyre_width_m + 0.001
                && y.abs() >= v.inner_face_y() - 0.001;
            if !under_tyre {
                out.push([x, y, 0.0]);
            }
        }
    }
    let mut rng = ChaCha8Rng::seed_from_u64(scan.seed);
    if scan.noise_m > 0.0 {
        for p in &mut out {
            let sensor = [p[0] + rng.random_range(-1.0..1.0), 0.0, 0.12];
            let ray = [p[0] - sensor[0], p[1] - sensor[1], p[2] - sensor[2]];
            let len = (ray[0] * ray[0] + ray[1] * ray[1] + ray[2] * ray[2])
                .sqrt()
                .max(1e-9);
            let e = gaussian(&mut rng) * scan.noise_m / len;
            for k in 0..3 {
                p[k] += ray[k] * e;
            }
        }
    }
    // Lone low outliers under the body, inside the band.
    let body: Vec<(f64, f64)> = polyline_samples(&v.profile, 0.05);
    for _ in 0..scan.outliers {
        let (x, z) = body[rng.random_range(0..body.len())];
        let drop = rng.random_range(0.05..0.15);
        out.push([x, rng.random_range(-hw..hw), (z - drop).max(0.05)]);
    }
    out
}

fn gaussian(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = rng.random_range(f64::EPSILON..1.0);
    let u2: f64 = rng.random_range(0.0..1.0);
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// A rigid placement of the vehicle frame in the cloud: yaw about z, then tilt (rotation about a
/// horizontal axis at `tilt_axis_rad` from x), then a shift.
#[derive(Debug, Clone, Copy)]
pub struct Pose {
    pub yaw_rad: f64,
    pub tilt_rad: f64,
    pub tilt_axis_rad: f64,
    pub shift_m: [f64; 3],
}

impl Pose {
    pub const IDENTITY: Pose = Pose {
        yaw_rad: 0.0,
        tilt_rad: 0.0,
        tilt_axis_rad: 0.0,
        shift_m: [0.0; 3],
    };

    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        let (s, c) = self.yaw_rad.sin_cos();
        let q = [c * p[0] - s * p[1], s * p[0] + c * p[1], p[2]];
        // Rodrigues rotation about the unit axis k = (cos a, sin a, 0).
        let k = [self.tilt_axis_rad.cos(), self.tilt_axis_rad.sin(), 0.0];
        let (st, ct) = self.tilt_rad.sin_cos();
        let kxq = [
            k[1] * q[2] - k[2] * q[1],
            k[2] * q[0] - k[0] * q[2],
            k[0] * q[1] - k[1] * q[0],
        ];
        let kdq = k[0] * q[0] + k[1] * q[1] + k[2] * q[2];
        let r: Vec<f64> = (0..3)
            .map(|i| q[i] * ct + kxq[i] * st + k[i] * kdq * (1.0 - ct))
            .collect();
        [
            r[0] + self.shift_m[0],
            r[1] + self.shift_m[1],
            r[2] + self.shift_m[2],
        ]
    }
}

// ---------------------------------------------------------------------------------------------
// Truth by brute force.

/// True angles (radians) from the exact geometry.
#[derive(Debug, Clone, Copy)]
pub struct Truth {
    pub approach_rad: f64,
    pub departure_rad: f64,
    pub breakover_rad: f64,
}

/// Side-view body geometry inside the band: the profile and the parts' outlines, subdivided at 0.5 mm.
fn dense_body(v: &Vehicle) -> Vec<(f64, f64)> {
    let mut pts = polyline_samples(&v.profile, 0.0005);
    for p in &v.parts {
        if p.y.1 >= -v.body_half_width() && p.y.0 <= v.body_half_width() {
            let outline = [
                (p.x.0, p.z.1),
                (p.x.0, p.z.0),
                (p.x.1, p.z.0),
                (p.x.1, p.z.1),
            ];
            pts.extend(polyline_samples(&outline, 0.0005));
        }
    }
    pts
}

/// Is `p` strictly below the line tangent to the circle (centre (xc, r), radius r) whose slope is
/// `theta` rising away from the wheel in direction `dir` (+1 forward, -1 backward)?
fn below_tangent(p: (f64, f64), xc: f64, r: f64, theta: f64, dir: f64) -> bool {
    // Tangent point and upward normal of the line.
    let (s, c) = theta.sin_cos();
    let t = (xc + dir * r * s, r - r * c);
    let n = (-dir * s, c);
    n.0 * (p.0 - t.0) + n.1 * (p.1 - t.1) < 0.0
}

/// Largest slope of a line tangent to the tyre that stays below every point of `pts` (bisection).
fn rotate_until_touch(pts: &[(f64, f64)], xc: f64, r: f64, dir: f64) -> Option<f64> {
    if pts.is_empty() {
        return None;
    }
    let (mut lo, mut hi) = (0.0f64, 89.0f64.to_radians());
    if !pts.iter().any(|&p| below_tangent(p, xc, r, hi, dir)) {
        return None;
    }
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if pts.iter().any(|&p| below_tangent(p, xc, r, mid, dir)) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    Some(lo)
}

/// The true angles, tyre zone (CFR) or axle zone (EU).
pub fn truth(v: &Vehicle, axle_zone: bool) -> Truth {
    let body = dense_body(v);
    let (xf, xr, r, big_r) = (v.front_x(), v.rear_x(), v.loaded_radius_m, v.free_radius_m);
    let zone = if axle_zone { 0.0 } else { big_r };
    let ahead: Vec<(f64, f64)> = body.iter().copied().filter(|p| p.0 > xf + zone).collect();
    let behind: Vec<(f64, f64)> = body.iter().copied().filter(|p| p.0 < xr - zone).collect();
    let approach_rad = rotate_until_touch(&ahead, xf, r, 1.0).unwrap_or(f64::NAN);
    let departure_rad = rotate_until_touch(&behind, xr, r, -1.0).unwrap_or(f64::NAN);
    let mut breakover_rad = f64::INFINITY;
    for &p in body.iter().filter(|p| p.0 > xr && p.0 < xf) {
        let f = rotate_until_touch(&[p], xf, r, -1.0);
        let b = rotate_until_touch(&[p], xr, r, 1.0);
        if let (Some(f), Some(b)) = (f, b) {
            breakover_rad = breakover_rad.min(f + b);
        }
    }
    Truth {
        approach_rad,
        departure_rad,
        breakover_rad,
    }
}
