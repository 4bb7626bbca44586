//! Halls: the surroundings of a measurement, as a test hall or a workshop has them.
//!
//! A hall is built from a [`HallSpec`] (the scenario's `[hall]` table, or a world file holding
//! one), the measured vehicle and a seed:
//! - **Floor**: the vehicle frame's ground plane plus a gentle undulation, a sum of three plane
//!   waves (wavelengths `undulation_wavelength_m` x 1, 0.7 and 1.6, seeded directions and phases)
//!   whose peak is at most `undulation_m`, multiplied by a window that is exactly zero at the four
//!   tyre contact points (`1 - exp(-d^2 / 0.25 m^2)` per contact): the vehicle stands on the
//!   floor, so the plane through its contacts stays the ground of the true angles.
//! - **Tilt**: the floor is tilted by `tilt_deg` against gravity about a seeded horizontal axis.
//!   The vehicle and any other vehicle stand on the floor; walls, ceiling and pillars are
//!   plumb, so in the vehicle frame they lean by the tilt.
//! - **Walls and ceiling**: the inside of a box around the vehicle's centre (mid-wheelbase on the
//!   centre line), the front, rear, left and right walls `walls_m` away (each moved by a seeded
//!   uniform draw within `wall_jitter_m`), the ceiling `ceiling_m` high.
//! - **Pillar rows**: rows parallel to the vehicle at `y_m`, square (`round = false`) or round
//!   pillars of `size_m`, every `spacing_m` along x, with a seeded phase; the row runs between the
//!   front and rear walls.
//! - **Other vehicles**: vehicle files placed with their centre at (`x_m`, `y_m`) from the measured
//!   vehicle's centre and yawed by `yaw_deg`, each moved by seeded uniform draws within the
//!   jitters. They are cast with their own tyres, bodies and parts but without their ground.
//!
//! Surface ids: [`SurfaceKind::Structure`] with index 0-5 for the front, rear, left and right walls,
//! the ceiling and the box's bottom face, `10 + 1000 row + k` for pillar `k` of row `row`;
//! [`SurfaceKind::OtherVehicle`] with the other vehicle's number.
//!
//! [`OnFloor`] puts a robot trajectory on the floor: its height is the mean floor height under
//! its four wheels and its pitch and roll follow the floor's slope between them.

use std::path::{Path, PathBuf};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Deserialize;

use super::{Aabb, Scene, SurfaceId, SurfaceKind, hit_box, hit_cylinder};
use crate::geometry::{
    Isometry, Normalized, Pose, Rot3, Vec3, isometry_from_xyz_rpy, rot_from_rpy,
};
use crate::trajectory::Trajectory;
use crate::vehicle::{Axis, Vehicle};

/// Half the robot's wheelbase and track (firmware defaults lx, ly), metres: where [`OnFloor`]
/// samples the floor under the wheels.
const ROBOT_WHEEL_HALF_BASE_M: f64 = 0.12;
const ROBOT_WHEEL_HALF_TRACK_M: f64 = 0.115;

/// Radius of the undulation's window around each tyre contact, metres.
const CONTACT_WINDOW_M: f64 = 0.5;

/// First surface index of the pillars.
const PILLAR_INDEX_BASE: u16 = 10;

/// A hall as written (the scenario's `[hall]` table; see the module docs).
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct HallSpec {
    /// Distances from the vehicle's centre to the front (+x), rear, left (+y) and right walls, m.
    pub walls_m: [f64; 4],
    /// Each wall moves by a seeded uniform draw within +- this, metres.
    #[serde(default)]
    pub wall_jitter_m: f64,
    /// Ceiling height, metres.
    #[serde(default = "default_ceiling")]
    pub ceiling_m: f64,
    /// Rows of pillars.
    #[serde(default)]
    pub pillar_rows: Vec<PillarRow>,
    /// Other parked vehicles.
    #[serde(default)]
    pub other_vehicles: Vec<OtherVehicleSpec>,
    /// Tilt of the floor against gravity, degrees (seeded direction).
    #[serde(default)]
    pub tilt_deg: f64,
    /// Peak height of the floor's undulation, metres (0: a plane).
    #[serde(default)]
    pub undulation_m: f64,
    /// Main wavelength of the undulation, metres.
    #[serde(default = "default_wavelength")]
    pub undulation_wavelength_m: f64,
}

fn default_ceiling() -> f64 {
    5.0
}

fn default_wavelength() -> f64 {
    3.0
}

/// One row of pillars.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PillarRow {
    /// Lateral position of the row's axis from the vehicle's centre line (+y left), metres.
    pub y_m: f64,
    /// Distance between pillars along x, metres.
    pub spacing_m: f64,
    /// Side (square) or diameter (round), metres.
    pub size_m: f64,
    /// Round (concrete) instead of square (steel) pillars.
    #[serde(default)]
    pub round: bool,
}

/// Another parked vehicle.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct OtherVehicleSpec {
    /// Vehicle file, relative to the file holding the hall.
    pub file: PathBuf,
    /// Its centre's x from the measured vehicle's centre, metres.
    #[serde(default)]
    pub x_m: f64,
    /// Its centre's y from the measured vehicle's centre line, metres (+ left).
    pub y_m: f64,
    /// Its yaw, degrees.
    #[serde(default)]
    pub yaw_deg: f64,
    /// Seeded uniform jitter of `x_m`, metres.
    #[serde(default)]
    pub x_jitter_m: f64,
    /// Seeded uniform jitter of `y_m`, metres.
    #[serde(default)]
    pub y_jitter_m: f64,
    /// Seeded uniform jitter of `yaw_deg`, degrees.
    #[serde(default)]
    pub yaw_jitter_deg: f64,
}

impl HallSpec {
    /// The first invalid field and why (field names as in a scenario's `[hall]` table).
    pub fn validate(&self) -> Result<(), (String, String)> {
        let bad = |f: &str, r: String| Err((format!("hall.{f}"), r));
        if self.walls_m.iter().any(|w| !(2.0..=60.0).contains(w)) {
            return bad(
                "walls_m",
                "every wall must lie 2..=60 m from the vehicle".into(),
            );
        }
        if !(0.0..=1.0).contains(&self.wall_jitter_m) {
            return bad("wall_jitter_m", "must lie in 0..=1 m".into());
        }
        if !(2.5..=30.0).contains(&self.ceiling_m) {
            return bad("ceiling_m", "must lie in 2.5..=30 m".into());
        }
        if !(0.0..=5.0).contains(&self.tilt_deg) {
            return bad("tilt_deg", "must lie in 0..=5 degrees".into());
        }
        if !(0.0..=0.05).contains(&self.undulation_m) {
            return bad("undulation_m", "must lie in 0..=0.05 m".into());
        }
        if !(0.5..=50.0).contains(&self.undulation_wavelength_m) {
            return bad("undulation_wavelength_m", "must lie in 0.5..=50 m".into());
        }
        for (i, r) in self.pillar_rows.iter().enumerate() {
            if !(r.size_m > 0.05 && r.size_m <= 2.0) {
                return bad(
                    &format!("pillar_rows[{i}].size_m"),
                    "must lie in (0.05, 2] m".into(),
                );
            }
            if !(r.spacing_m >= r.size_m + 0.5 && r.spacing_m <= 100.0) {
                return bad(
                    &format!("pillar_rows[{i}].spacing_m"),
                    "must be at least size_m + 0.5 m and at most 100 m".into(),
                );
            }
            let inside = -self.walls_m[3] + r.size_m..=self.walls_m[2] - r.size_m;
            if !inside.contains(&r.y_m) || r.y_m.abs() < 1.5 {
                return bad(
                    &format!("pillar_rows[{i}].y_m"),
                    "must lie between the side walls and at least 1.5 m from the centre line"
                        .into(),
                );
            }
        }
        for (i, o) in self.other_vehicles.iter().enumerate() {
            let finite = [o.x_m, o.y_m, o.yaw_deg, o.x_jitter_m, o.y_jitter_m]
                .iter()
                .all(|v| v.is_finite());
            if !finite || o.y_m.abs() - o.y_jitter_m < 1.5 || o.yaw_jitter_deg.abs() > 45.0 {
                return bad(
                    &format!("other_vehicles[{i}]"),
                    "needs finite values, |y_m| - y_jitter_m >= 1.5 m and yaw_jitter_deg within 45"
                        .into(),
                );
            }
        }
        Ok(())
    }
}

/// The floor: the ground plane plus the windowed undulation (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct Floor {
    amplitude_m: f64,
    /// Per wave: (kx, ky, phase, weight), weights summing to 1.
    waves: [[f64; 4]; 3],
    contacts: [[f64; 2]; 4],
}

impl Floor {
    /// The flat ground z = 0.
    pub fn flat() -> Self {
        Self {
            amplitude_m: 0.0,
            waves: [[0.0; 4]; 3],
            contacts: [[0.0; 2]; 4],
        }
    }

    /// An undulating floor of peak `amplitude_m` that is exactly 0 at `contacts`.
    pub fn undulating(
        amplitude_m: f64,
        wavelength_m: f64,
        contacts: [[f64; 2]; 4],
        rng: &mut ChaCha8Rng,
    ) -> Self {
        let mut waves = [[0.0; 4]; 3];
        for (w, (factor, weight)) in waves.iter_mut().zip([(1.0, 0.5), (0.7, 0.3), (1.6, 0.2)]) {
            let dir: f64 = rng.random_range(0.0..std::f64::consts::TAU);
            let k = std::f64::consts::TAU / (wavelength_m * factor);
            *w = [
                k * dir.cos(),
                k * dir.sin(),
                rng.random_range(0.0..std::f64::consts::TAU),
                weight,
            ];
        }
        Self {
            amplitude_m,
            waves,
            contacts,
        }
    }

    /// Whether this is the plane z = 0.
    pub fn is_flat(&self) -> bool {
        self.amplitude_m == 0.0
    }

    /// Floor height at (x, y), metres.
    pub fn height(&self, x: f64, y: f64) -> f64 {
        self.height_and_gradient(x, y).0
    }

    /// The floor's slope (dz/dx, dz/dy) at (x, y).
    pub fn gradient(&self, x: f64, y: f64) -> (f64, f64) {
        let (_, gx, gy) = self.height_and_gradient(x, y);
        (gx, gy)
    }

    /// Height and slope together, analytically: h = A S W with S the waves' sum and W the
    /// product of the contact windows.
    fn height_and_gradient(&self, x: f64, y: f64) -> (f64, f64, f64) {
        if self.is_flat() {
            return (0.0, 0.0, 0.0);
        }
        let (mut s, mut sx, mut sy) = (0.0, 0.0, 0.0);
        for w in &self.waves {
            let (sin, cos) = (w[0] * x + w[1] * y + w[2]).sin_cos();
            s += w[3] * sin;
            sx += w[3] * cos * w[0];
            sy += w[3] * cos * w[1];
        }
        let rho2 = CONTACT_WINDOW_M * CONTACT_WINDOW_M;
        let factors = self.contacts.map(|c| {
            let (dx, dy) = (x - c[0], y - c[1]);
            let e = (-(dx * dx + dy * dy) / rho2).exp();
            // (1 - e) and its gradient.
            (1.0 - e, 2.0 * e * dx / rho2, 2.0 * e * dy / rho2)
        });
        let w: f64 = factors.iter().map(|f| f.0).product();
        let (mut wx, mut wy) = (0.0, 0.0);
        for (i, f) in factors.iter().enumerate() {
            let others: f64 = factors
                .iter()
                .enumerate()
                .filter(|(j, _)| *j != i)
                .map(|(_, g)| g.0)
                .product();
            wx += others * f.1;
            wy += others * f.2;
        }
        let a = self.amplitude_m;
        (a * s * w, a * (sx * w + s * wx), a * (sy * w + s * wy))
    }

    /// The ray's first crossing of the floor before `t_max`, with the floor's unit normal: from
    /// the crossing of z = 0, Newton steps on `z(t) - height(x(t), y(t))`. Rays that do not
    /// descend never reach it (the floor stays within centimetres of z = 0).
    pub fn cast(&self, o: Vec3, d: Vec3, t_max: f64) -> Option<(f64, Vec3)> {
        if d.z >= -1e-9 || o.z <= self.height(o.x, o.y) {
            return None;
        }
        let mut t = -o.z / d.z;
        let mut slope_xy = (0.0, 0.0);
        for _ in 0..8 {
            if !(t > 0.0 && t < t_max + 1.0) {
                return None;
            }
            let p = o + d * t;
            let (h, gx, gy) = self.height_and_gradient(p.x, p.y);
            slope_xy = (gx, gy);
            let f = p.z - h;
            if f.abs() < 1e-10 {
                break;
            }
            let slope = d.z - gx * d.x - gy * d.y;
            if slope >= -1e-12 {
                return None;
            }
            t -= f / slope;
        }
        if !(t > 0.0 && t < t_max) {
            return None;
        }
        let (gx, gy) = slope_xy;
        Some((t, Vec3::new(-gx, -gy, 1.0).normalized()))
    }

    /// Distance from `p` to the floor (vertical gap times the slope's cosine; exact for a plane,
    /// within the undulation's curvature otherwise).
    pub fn distance(&self, p: Vec3) -> f64 {
        let (h, gx, gy) = self.height_and_gradient(p.x, p.y);
        (p.z - h).abs() / (1.0 + gx * gx + gy * gy).sqrt()
    }
}

#[derive(Clone, Debug)]
struct Row {
    y: f64,
    half: f64,
    round: bool,
    xs: Vec<f64>,
}

#[derive(Clone, Debug)]
// The frames' names are the point of these fields.
#[allow(clippy::struct_field_names)]
struct Other {
    vehicle_from_other: Isometry,
    other_from_vehicle: Isometry,
    bounds: Aabb,
    scene: Scene,
}

/// A built hall (see the module docs).
#[derive(Clone, Debug)]
#[allow(clippy::struct_field_names)] // the frames' names are the point of two fields
pub struct Hall {
    spec: HallSpec,
    seed: u64,
    /// The floor (in the vehicle frame).
    pub floor: Floor,
    /// `hall_from_vehicle` rotation (the tilt) and the hall origin (the vehicle's centre) in
    /// the vehicle frame.
    hall_from_vehicle: Rot3,
    vehicle_from_hall: Rot3,
    origin: Vec3,
    room_min: Vec3,
    room_max: Vec3,
    rows: Vec<Row>,
    others: Vec<Other>,
}

impl PartialEq for Hall {
    fn eq(&self, other: &Self) -> bool {
        self.spec == other.spec && self.seed == other.seed && self.origin == other.origin
    }
}

impl Hall {
    /// Build `spec` around `vehicle` with the placement drawn from `seed`; other vehicles' files
    /// are read relative to `dir`. Errors are `(field, reason)` as in [`HallSpec::validate`].
    // One straight construction, in the order the seed's draws are taken.
    #[allow(clippy::too_many_lines)]
    pub fn build(
        spec: &HallSpec,
        vehicle: &Vehicle,
        dir: &Path,
        seed: u64,
    ) -> Result<Self, (String, String)> {
        spec.validate()?;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let origin = Vec3::new(-vehicle.wheelbase_m / 2.0, 0.0, 0.0);
        let jitter = |rng: &mut ChaCha8Rng, j: f64| {
            if j > 0.0 {
                rng.random_range(-j..=j)
            } else {
                0.0
            }
        };
        let walls: Vec<f64> = spec
            .walls_m
            .iter()
            .map(|w| w + jitter(&mut rng, spec.wall_jitter_m))
            .collect();
        let room_min = Vec3::new(-walls[1], -walls[3], -1.0);
        let room_max = Vec3::new(walls[0], walls[2], spec.ceiling_m);
        let tilt_dir: f64 = rng.random_range(0.0..std::f64::consts::TAU);
        let tilt = spec.tilt_deg.to_radians();
        let hall_from_vehicle = rot_from_rpy(tilt * tilt_dir.sin(), tilt * tilt_dir.cos(), 0.0);
        let rows = spec
            .pillar_rows
            .iter()
            .map(|r| {
                let phase = rng.random_range(0.0..r.spacing_m);
                let half = r.size_m / 2.0;
                let first = room_min.x + half + phase;
                // The spacing is at least 0.5 m (validated), so the count is bounded by the room.
                let count = ((room_max.x - half - first) / r.spacing_m)
                    .floor()
                    .max(-1.0)
                    + 1.0;
                let xs = (0..count as u32)
                    .map(|k| first + f64::from(k) * r.spacing_m)
                    .collect();
                Row {
                    y: r.y_m,
                    half,
                    round: r.round,
                    xs,
                }
            })
            .collect();
        let floor = if spec.undulation_m > 0.0 {
            let contacts = vehicle.tyre_centres().map(|[x, y, _]| [x, y]);
            Floor::undulating(
                spec.undulation_m,
                spec.undulation_wavelength_m,
                contacts,
                &mut rng,
            )
        } else {
            Floor::flat()
        };
        let mut others = Vec::new();
        for (i, o) in spec.other_vehicles.iter().enumerate() {
            let path = dir.join(&o.file);
            let v = Vehicle::load(&path).map_err(|e| {
                (
                    format!("hall.other_vehicles[{i}].file"),
                    format!("{}: {e}", path.display()),
                )
            })?;
            let yaw = (o.yaw_deg + jitter(&mut rng, o.yaw_jitter_deg)).to_radians();
            let centre = origin
                + Vec3::new(
                    o.x_m + jitter(&mut rng, o.x_jitter_m),
                    o.y_m + jitter(&mut rng, o.y_jitter_m),
                    0.0,
                );
            let (s, c) = yaw.sin_cos();
            let half_wb = v.wheelbase_m / 2.0;
            let vehicle_from_other = isometry_from_xyz_rpy(
                centre + Vec3::new(c * half_wb, s * half_wb, 0.0),
                0.0,
                0.0,
                yaw,
            );
            let w = v.body_width_m.max(v.track_m + v.tyre.width_m) / 2.0 + 0.1;
            let bounds = Aabb {
                min: Vec3::new(v.rear_x_m().min(-v.wheelbase_m) - 1.0, -w, -0.01),
                max: Vec3::new(v.front_x_m().max(0.0) + 1.0, w, v.body_height_m + 0.1),
            };
            others.push(Other {
                other_from_vehicle: vehicle_from_other.inverse(),
                vehicle_from_other,
                bounds,
                scene: Scene::from_vehicle(&v),
            });
        }
        Ok(Self {
            spec: spec.clone(),
            seed,
            floor,
            vehicle_from_hall: hall_from_vehicle.transpose(),
            hall_from_vehicle,
            origin,
            room_min,
            room_max,
            rows,
            others,
        })
    }

    /// The spec this hall was built from.
    pub fn spec(&self) -> &HallSpec {
        &self.spec
    }

    /// Where the other vehicles stand: `vehicle_from_other` of each.
    pub fn other_vehicle_poses(&self) -> Vec<Isometry> {
        self.others.iter().map(|o| o.vehicle_from_other).collect()
    }

    /// Pillar centres (x, y) in the hall frame, per row.
    pub fn pillar_positions(&self) -> Vec<Vec<[f64; 2]>> {
        self.rows
            .iter()
            .map(|r| r.xs.iter().map(|&x| [x, r.y]).collect())
            .collect()
    }

    /// Walls, ceiling, pillars and other vehicles: the nearest hit before `t_max` with its normal
    /// (vehicle frame), kind and index.
    pub(crate) fn cast(
        &self,
        o: Vec3,
        d: Vec3,
        t_max: f64,
    ) -> Option<(f64, Vec3, SurfaceKind, usize)> {
        let ho = self.hall_from_vehicle * (o - self.origin);
        let hd = self.hall_from_vehicle * d;
        let mut best: Option<(f64, Vec3, SurfaceKind, usize)> = None;
        let mut limit = t_max;
        if let Some((t, n, i)) = self.cast_room(ho, hd)
            && t < limit
        {
            limit = t;
            best = Some((t, self.vehicle_from_hall * n, SurfaceKind::Structure, i));
        }
        for (r, row) in self.rows.iter().enumerate() {
            if let Some((t, n, k)) = cast_row(row, ho, hd, limit, self.room_min.z, self.room_max.z)
            {
                limit = t;
                best = Some((
                    t,
                    self.vehicle_from_hall * n,
                    SurfaceKind::Structure,
                    usize::from(PILLAR_INDEX_BASE) + 1000 * r + k,
                ));
            }
        }
        for (i, other) in self.others.iter().enumerate() {
            let oo = other.other_from_vehicle.apply(o);
            let od = other.other_from_vehicle.apply_vector(d);
            let inv = Vec3::new(1.0 / od.x, 1.0 / od.y, 1.0 / od.z);
            if other.bounds.hit(oo, inv, limit)
                && let Some(h) = other.scene.cast_vehicle_only(oo, od, limit)
            {
                limit = h.range_m;
                best = Some((
                    h.range_m,
                    other.vehicle_from_other.apply_vector(h.normal),
                    SurfaceKind::OtherVehicle,
                    i,
                ));
            }
        }
        best
    }

    /// The room's walls and ceiling seen from inside: the face the ray leaves through.
    fn cast_room(&self, o: Vec3, d: Vec3) -> Option<(f64, Vec3, usize)> {
        let (lo, hi) = (self.room_min, self.room_max);
        if o.x <= lo.x || o.x >= hi.x || o.y <= lo.y || o.y >= hi.y || o.z >= hi.z {
            return None;
        }
        let mut best: Option<(f64, Vec3, usize)> = None;
        let axes = [
            (o.x, d.x, lo.x, hi.x, Vec3::new(1.0, 0.0, 0.0), [1, 0]),
            (o.y, d.y, lo.y, hi.y, Vec3::new(0.0, 1.0, 0.0), [3, 2]),
            (o.z, d.z, lo.z, hi.z, Vec3::new(0.0, 0.0, 1.0), [5, 4]),
        ];
        for (oc, dc, l, h, axis, [i_lo, i_hi]) in axes {
            let (t, n, i) = if dc > 1e-15 {
                ((h - oc) / dc, -axis, i_hi)
            } else if dc < -1e-15 {
                ((l - oc) / dc, axis, i_lo)
            } else {
                continue;
            };
            if t > 0.0 && best.is_none_or(|b| t < b.0) {
                best = Some((t, n, i));
            }
        }
        best
    }

    /// Distance from `p` (vehicle frame) to surface `id` of this hall.
    pub(crate) fn distance_to(&self, id: SurfaceId, p: Vec3) -> f64 {
        let i = usize::from(id.index);
        match id.kind {
            SurfaceKind::OtherVehicle => self.others.get(i).map_or(f64::INFINITY, |o| {
                o.scene
                    .distance_to_nearest_vehicle(o.other_from_vehicle.apply(p))
            }),
            SurfaceKind::Structure => {
                let h = self.hall_from_vehicle * (p - self.origin);
                let (lo, hi) = (self.room_min, self.room_max);
                match i {
                    0 => (h.x - hi.x).abs(),
                    1 => (h.x - lo.x).abs(),
                    2 => (h.y - hi.y).abs(),
                    3 => (h.y - lo.y).abs(),
                    4 => (h.z - hi.z).abs(),
                    5 => (h.z - lo.z).abs(),
                    _ => {
                        let j = i.saturating_sub(usize::from(PILLAR_INDEX_BASE));
                        let (r, k) = (j / 1000, j % 1000);
                        self.rows
                            .get(r)
                            .and_then(|row| row.xs.get(k).map(|&x| (row, x)))
                            .map_or(f64::INFINITY, |(row, x)| pillar_distance(row, x, h))
                    }
                }
            }
            _ => f64::INFINITY,
        }
    }

    /// Distance from `p` to the nearest wall, ceiling, pillar or other vehicle.
    pub fn distance_to_structures(&self, p: Vec3) -> f64 {
        let mut best = f64::INFINITY;
        for index in 0..6 {
            best = best.min(self.distance_to(
                SurfaceId {
                    kind: SurfaceKind::Structure,
                    index,
                },
                p,
            ));
        }
        let h = self.hall_from_vehicle * (p - self.origin);
        for row in &self.rows {
            for &x in &row.xs {
                best = best.min(pillar_distance(row, x, h));
            }
        }
        for o in &self.others {
            best = best.min(
                o.scene
                    .distance_to_nearest_vehicle(o.other_from_vehicle.apply(p)),
            );
        }
        best
    }
}

fn pillar_distance(row: &Row, x: f64, h: Vec3) -> f64 {
    let (dx, dy) = (h.x - x, h.y - row.y);
    if row.round {
        (dx.hypot(dy) - row.half).abs()
    } else {
        let (ex, ey) = (dx.abs() - row.half, dy.abs() - row.half);
        if ex <= 0.0 && ey <= 0.0 {
            -(ex.max(ey))
        } else {
            ex.max(0.0).hypot(ey.max(0.0))
        }
    }
}

/// The nearest pillar of `row` the ray hits before `t_max` (hall frame): only the pillars whose
/// x lies within the ray's x range while it crosses the row's y slab are tested.
fn cast_row(
    row: &Row,
    o: Vec3,
    d: Vec3,
    t_max: f64,
    z_lo: f64,
    z_hi: f64,
) -> Option<(f64, Vec3, usize)> {
    let (y0, y1) = (row.y - row.half, row.y + row.half);
    let (ta, tb) = if d.y.abs() < 1e-12 {
        if o.y < y0 || o.y > y1 {
            return None;
        }
        (0.0, t_max)
    } else {
        let (a, b) = ((y0 - o.y) / d.y, (y1 - o.y) / d.y);
        let (a, b) = if a < b { (a, b) } else { (b, a) };
        (a.max(0.0), b.min(t_max))
    };
    if ta > tb {
        return None;
    }
    let (xa, xb) = (o.x + d.x * ta, o.x + d.x * tb);
    let (x_lo, x_hi) = (xa.min(xb) - row.half, xa.max(xb) + row.half);
    let mut best: Option<(f64, Vec3, usize)> = None;
    let half_height = (z_hi - z_lo) / 2.0;
    for (k, &x) in row.xs.iter().enumerate() {
        if x < x_lo || x > x_hi {
            continue;
        }
        let hit = if row.round {
            hit_cylinder(
                Axis::Z,
                Vec3::new(x, row.y, z_lo + half_height),
                row.half,
                half_height,
                o,
                d,
            )
        } else {
            hit_box(
                Vec3::new(x - row.half, y0, z_lo),
                Vec3::new(x + row.half, y1, z_hi),
                o,
                d,
            )
        };
        if let Some((t, n)) = hit
            && t < best.map_or(t_max, |b| b.0)
        {
            let n = if n.dot(&d) > 0.0 { -n } else { n };
            best = Some((t, n, k));
        }
    }
    best
}

/// A trajectory put on a floor: the robot's height is the mean floor height under its four
/// wheels, and its pitch and roll follow the floor's slope between them (added to the inner
/// trajectory's vibration). With no floor, or a flat one, the inner trajectory unchanged.
pub struct OnFloor<'a, T: Trajectory> {
    /// The motion over a flat ground.
    pub inner: &'a T,
    /// The floor, if any.
    pub floor: Option<&'a Floor>,
}

impl<T: Trajectory> Trajectory for OnFloor<'_, T> {
    fn pose_at(&self, t_s: f64) -> Pose {
        let mut p = self.inner.pose_at(t_s);
        let Some(floor) = self.floor.filter(|f| !f.is_flat()) else {
            return p;
        };
        let (s, c) = p.yaw_rad.sin_cos();
        let at = |fx: f64, fy: f64| {
            let (lx, ly) = (fx * ROBOT_WHEEL_HALF_BASE_M, fy * ROBOT_WHEEL_HALF_TRACK_M);
            floor.height(
                p.position_m.x + c * lx - s * ly,
                p.position_m.y + s * lx + c * ly,
            )
        };
        let (fl, fr, rl, rr) = (at(1.0, 1.0), at(1.0, -1.0), at(-1.0, 1.0), at(-1.0, -1.0));
        p.position_m.z += (fl + fr + rl + rr) / 4.0;
        // Floor rising ahead lifts the nose (negative pitch); rising to the left lifts the left
        // side (positive roll).
        let rise_ahead = (fl + fr - rl - rr) / 2.0 / (2.0 * ROBOT_WHEEL_HALF_BASE_M);
        let rise_left = (fl + rl - fr - rr) / 2.0 / (2.0 * ROBOT_WHEEL_HALF_TRACK_M);
        p.pitch_rad -= rise_ahead.atan();
        p.roll_rad += rise_left.atan();
        p
    }

    fn wheel_distance_at(&self, t_s: f64) -> f64 {
        self.inner.wheel_distance_at(t_s)
    }
}
