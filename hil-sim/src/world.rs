//! The simulated world and its ray caster: a flat ground, four tyres, the body prisms and the parts of
//! one [`Vehicle`], all in the vehicle frame (see [`crate::vehicle`]).
//!
//! Parametric primitives are intersected analytically: the ground is the plane z = 0, a tyre is a
//! y-axis cylinder with flat sidewall annuli and a recessed rim disc, a body prism is a side-view
//! polygon extruded along y (the ray is clipped to the y slab, then crossed with the polygon's edges
//! in the x-z plane), box and cylinder parts are axis-aligned boxes and finite cylinders. Mesh parts
//! are triangle meshes cast through their own BVH ([`crate::mesh`]). Each primitive carries a
//! bounding box that rejects most rays cheaply; a scene has ~10 primitives, so no hierarchy over
//! them is needed. Sensors that fire many rays in a narrow horizontal wedge (a VLP-16 packet
//! sweeps under 10 degrees) first ask [`Scene::candidates_in_wedge`] which primitives the wedge can
//! reach and cast with [`Scene::cast_among`]; tests check that this never changes a hit.
//! [`Scene::cast`] returns the nearest hit with its surface normal and which surface it was;
//! [`Scene::distance_to_surface`] is an independent distance function used by tests to check that
//! simulated points lie on the surface they were cast on.
//!
//! Known approximation: the rim disc spans the full tyre radius in its recessed plane instead of
//! having an inner lip, so a ray entering the rim opening obliquely stops on the disc slightly
//! outside the rim radius.

use std::sync::Arc;

use crate::geometry::{Normalized, Vec3};
// The primitives' bounding boxes are the meshes' (one slab test for both).
use crate::mesh::{Bounds as Aabb, Mesh};
use crate::vehicle::{Axis, Part, RIM_INSET_M, Tyre, Vehicle};

pub mod hall;
pub use hall::{Floor, Hall, HallSpec, OnFloor};

/// What kind of surface a ray hit.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SurfaceKind {
    /// The ground plane.
    Ground,
    /// A tyre (index: front-left, front-right, rear-left, rear-right).
    Tyre,
    /// A body prism (index into [`Vehicle::body_prisms`]); a mesh body has the index after the
    /// last prism (0, as a mesh body has no prisms).
    Body,
    /// An optional part (index into `Vehicle::parts`).
    Part,
    /// A hall's wall, ceiling or pillar (index: see [`hall::Hall`]).
    Structure,
    /// Another parked vehicle in a hall (index: which one).
    OtherVehicle,
}

/// Which surface a ray hit.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct SurfaceId {
    /// The kind of surface.
    pub kind: SurfaceKind,
    /// Index within that kind.
    pub index: u16,
}

/// A ray hit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Distance along the (unit) ray direction, metres.
    pub range_m: f64,
    /// Unit surface normal, facing the ray's origin.
    pub normal: Vec3,
    /// The surface.
    pub surface: SurfaceId,
}

#[derive(Clone, Debug)]
struct TyrePrim {
    centre: Vec3,
    radius: f64,
    half_width: f64,
    rim_radius: f64,
    bounds: Aabb,
    /// A loaded tyre's surface (flattened contact patch, bulging sidewalls), cast instead of
    /// the cylinder.
    mesh: Option<Arc<Mesh>>,
}

#[derive(Clone, Debug)]
struct Prism {
    /// Side-view polygon (x, z), closed implicitly.
    poly: Vec<[f64; 2]>,
    half_width: f64,
    bounds: Aabb,
}

#[derive(Clone, Debug)]
enum PartPrim {
    Box {
        min: Vec3,
        max: Vec3,
    },
    Cylinder {
        axis: Axis,
        centre: Vec3,
        radius: f64,
        half_length: f64,
        bounds: Aabb,
    },
    Mesh {
        mesh: Arc<Mesh>,
        bounds: Aabb,
    },
}

impl PartPrim {
    fn bounds(&self) -> Aabb {
        match self {
            PartPrim::Box { min, max } => Aabb {
                min: *min,
                max: *max,
            },
            PartPrim::Cylinder { bounds, .. } | PartPrim::Mesh { bounds, .. } => *bounds,
        }
    }
}

/// A scene ready for ray casting. Build it once per vehicle with [`Scene::from_vehicle`].
#[derive(Clone, Debug)]
pub struct Scene {
    tyres: Vec<TyrePrim>,
    prisms: Vec<Prism>,
    /// A mesh body with its bounds, cast as the body surface after the prisms.
    body_mesh: Option<(Arc<Mesh>, Aabb)>,
    parts: Vec<PartPrim>,
    /// The hall around the vehicle (floor, walls, pillars, other vehicles); `None`: an empty,
    /// flat world.
    hall: Option<Arc<Hall>>,
}

/// Base diffuse reflectivity of each kind of surface on the VLP-16's 0..100 calibrated scale
/// (assumed typical values: dark rubber, dusty concrete, painted or coated steel, bare metal).
pub fn base_reflectivity(kind: SurfaceKind) -> f64 {
    match kind {
        SurfaceKind::Ground => 25.0,
        SurfaceKind::Tyre => 6.0,
        SurfaceKind::Body => 40.0,
        SurfaceKind::Part => 60.0,
        SurfaceKind::Structure => 50.0,
        SurfaceKind::OtherVehicle => 35.0,
    }
}

impl Scene {
    /// Build the scene of a (validated) vehicle.
    pub fn from_vehicle(vehicle: &Vehicle) -> Self {
        let t = &vehicle.tyre;
        let tyres = vehicle
            .tyre_centres()
            .iter()
            .map(|&[x, y, z]| {
                let hw = t.width_m / 2.0;
                let centre = Vec3::new(x, y, z);
                if t.is_loaded() {
                    let mesh = loaded_tyre_mesh(t, centre);
                    let b = mesh.bounds();
                    return TyrePrim {
                        centre,
                        radius: t.radius_m,
                        half_width: hw,
                        rim_radius: t.rim_radius_m,
                        bounds: Aabb {
                            min: b.min,
                            max: b.max,
                        },
                        mesh: Some(Arc::new(mesh)),
                    };
                }
                TyrePrim {
                    centre,
                    radius: t.radius_m,
                    half_width: hw,
                    rim_radius: t.rim_radius_m,
                    bounds: Aabb {
                        min: Vec3::new(x - t.radius_m, y - hw, z - t.radius_m),
                        max: Vec3::new(x + t.radius_m, y + hw, z + t.radius_m),
                    },
                    mesh: None,
                }
            })
            .collect();
        let prisms = vehicle
            .body_prisms()
            .into_iter()
            .map(|(_, poly, width)| {
                let hw = width / 2.0;
                let (mut min, mut max) = (
                    Vec3::new(f64::INFINITY, -hw, f64::INFINITY),
                    Vec3::new(f64::NEG_INFINITY, hw, f64::NEG_INFINITY),
                );
                for &[x, z] in &poly {
                    min.x = min.x.min(x);
                    min.z = min.z.min(z);
                    max.x = max.x.max(x);
                    max.z = max.z.max(z);
                }
                Prism {
                    poly,
                    half_width: hw,
                    bounds: Aabb { min, max },
                }
            })
            .collect();
        let parts = vehicle.parts.iter().map(part_prim).collect();
        let body_mesh = vehicle.body_mesh.as_ref().map(|b| {
            let bounds = b.mesh.0.bounds();
            (
                Arc::clone(&b.mesh.0),
                Aabb {
                    min: bounds.min,
                    max: bounds.max,
                },
            )
        });
        Self {
            tyres,
            prisms,
            body_mesh,
            parts,
            hall: None,
        }
    }

    /// This scene inside `hall` (its floor replaces the flat ground; its walls, pillars and other
    /// vehicles are cast after the vehicle's primitives and never culled by wedges).
    #[must_use]
    pub fn with_hall(mut self, hall: Option<Arc<Hall>>) -> Self {
        self.hall = hall;
        self
    }

    /// The hall, if any.
    pub fn hall(&self) -> Option<&Hall> {
        self.hall.as_deref()
    }

    /// Distance from `p` to the nearest surface of any kind: ground or floor, the vehicle and
    /// the hall (for tests and cloud checks).
    pub fn distance_to_nearest(&self, p: Vec3) -> f64 {
        let ground = self.distance_to_surface(
            SurfaceId {
                kind: SurfaceKind::Ground,
                index: 0,
            },
            p,
        );
        let hall = self
            .hall
            .as_ref()
            .map_or(f64::INFINITY, |h| h.distance_to_structures(p));
        ground.min(hall).min(self.distance_to_nearest_vehicle(p))
    }

    /// Distance from `p` to the nearest tyre, body surface or part.
    pub fn distance_to_nearest_vehicle(&self, p: Vec3) -> f64 {
        let mut best = f64::INFINITY;
        for (kind, n) in [
            (SurfaceKind::Tyre, self.tyres.len()),
            (
                SurfaceKind::Body,
                self.prisms.len() + usize::from(self.body_mesh.is_some()),
            ),
            (SurfaceKind::Part, self.parts.len()),
        ] {
            for index in 0..n {
                let id = SurfaceId {
                    kind,
                    index: index as u16,
                };
                best = best.min(self.distance_to_surface(id, p));
            }
        }
        best
    }

    /// Cast a ray from `origin` along the unit vector `dir`; the nearest hit closer than `max_range_m`.
    pub fn cast(&self, origin: Vec3, dir: Vec3, max_range_m: f64) -> Option<Hit> {
        self.cast_among(origin, dir, max_range_m, Candidates::ALL)
    }

    /// [`Scene::cast`] testing only the primitives in `candidates` (and the ground). Callers must
    /// make sure no other primitive can be hit, e.g. with [`Scene::candidates_in_wedge`].
    pub fn cast_among(
        &self,
        origin: Vec3,
        dir: Vec3,
        max_range_m: f64,
        candidates: Candidates,
    ) -> Option<Hit> {
        self.cast_inner(origin, dir, max_range_m, candidates, true)
    }

    /// The vehicle's primitives only (no ground, no hall): how another vehicle standing in a hall
    /// is cast.
    pub(crate) fn cast_vehicle_only(
        &self,
        origin: Vec3,
        dir: Vec3,
        max_range_m: f64,
    ) -> Option<Hit> {
        self.cast_inner(origin, dir, max_range_m, Candidates::ALL, false)
    }

    // One nearest-hit loop over every kind of primitive.
    #[allow(clippy::too_many_lines)]
    fn cast_inner(
        &self,
        origin: Vec3,
        dir: Vec3,
        max_range_m: f64,
        candidates: Candidates,
        surroundings: bool,
    ) -> Option<Hit> {
        let inv = Vec3::new(1.0 / dir.x, 1.0 / dir.y, 1.0 / dir.z);
        let mut best: Option<Hit> = None;
        let mut t_max = max_range_m;
        let mut keep = |t: f64, normal: Vec3, kind: SurfaceKind, index: usize, t_max: &mut f64| {
            if t > 0.0 && t < *t_max {
                *t_max = t;
                let normal = if normal.dot(&dir) > 0.0 {
                    -normal
                } else {
                    normal
                };
                best = Some(Hit {
                    range_m: t,
                    normal,
                    surface: SurfaceId {
                        kind,
                        index: index as u16,
                    },
                });
            }
        };
        match &self.hall {
            _ if !surroundings => {}
            Some(h) if !h.floor.is_flat() => {
                if let Some((t, n)) = h.floor.cast(origin, dir, t_max) {
                    keep(t, n, SurfaceKind::Ground, 0, &mut t_max);
                }
            }
            _ => {
                if dir.z < 0.0 && origin.z > 0.0 {
                    keep(
                        -origin.z / dir.z,
                        Vec3::new(0.0, 0.0, 1.0),
                        SurfaceKind::Ground,
                        0,
                        &mut t_max,
                    );
                }
            }
        }
        for (i, ty) in self.tyres.iter().enumerate() {
            if candidates.has_tyre(i)
                && ty.bounds.hit(origin, inv, t_max)
                && let Some((t, n)) = match &ty.mesh {
                    Some(m) => m.cast(origin, dir, t_max),
                    None => hit_tyre(ty, origin, dir, t_max),
                }
            {
                keep(t, n, SurfaceKind::Tyre, i, &mut t_max);
            }
        }
        for (i, pr) in self.prisms.iter().enumerate() {
            if candidates.has_prism(i)
                && pr.bounds.hit(origin, inv, t_max)
                && let Some((t, n)) = hit_prism(pr, origin, dir, t_max)
            {
                keep(t, n, SurfaceKind::Body, i, &mut t_max);
            }
        }
        let body_index = self.prisms.len();
        if let Some((mesh, bounds)) = &self.body_mesh
            && candidates.has_prism(body_index)
            && bounds.hit(origin, inv, t_max)
            && let Some((t, n)) = mesh.cast(origin, dir, t_max)
        {
            keep(t, n, SurfaceKind::Body, body_index, &mut t_max);
        }
        for (i, part) in self.parts.iter().enumerate() {
            if !candidates.has_part(i) {
                continue;
            }
            let found = match part {
                PartPrim::Box { min, max } => {
                    if (Aabb {
                        min: *min,
                        max: *max,
                    })
                    .hit(origin, inv, t_max)
                    {
                        hit_box(*min, *max, origin, dir)
                    } else {
                        None
                    }
                }
                PartPrim::Cylinder {
                    axis,
                    centre,
                    radius,
                    half_length,
                    bounds,
                } => {
                    if bounds.hit(origin, inv, t_max) {
                        hit_cylinder(*axis, *centre, *radius, *half_length, origin, dir)
                    } else {
                        None
                    }
                }
                PartPrim::Mesh { mesh, bounds } => {
                    if bounds.hit(origin, inv, t_max) {
                        mesh.cast(origin, dir, t_max)
                    } else {
                        None
                    }
                }
            };
            if let Some((t, n)) = found {
                keep(t, n, SurfaceKind::Part, i, &mut t_max);
            }
        }
        if surroundings
            && let Some(h) = &self.hall
            && let Some((t, n, kind, index)) = h.cast(origin, dir, t_max)
        {
            keep(t, n, kind, index, &mut t_max);
        }
        best
    }

    /// The primitives a ray from `origin` can hit when its horizontal direction lies within
    /// `half_width_rad` of the world angle `mid_rad` (counter-clockwise from +x): every primitive
    /// whose bounding box, grown by 1 cm, overlaps that wedge seen from above, or contains the
    /// origin's x-y position. Conservative: widen the wedge for any doubt.
    pub fn candidates_in_wedge(
        &self,
        origin: Vec3,
        mid_rad: f64,
        half_width_rad: f64,
    ) -> Candidates {
        let mut c = Candidates {
            tyres: 0,
            prisms: 0,
            parts: 0,
        };
        let visible = |b: &Aabb| aabb_in_wedge(b, origin, mid_rad, half_width_rad);
        for (i, t) in self.tyres.iter().enumerate().take(64) {
            c.tyres |= u64::from(visible(&t.bounds)) << i;
        }
        for (i, p) in self.prisms.iter().enumerate().take(64) {
            c.prisms |= u64::from(visible(&p.bounds)) << i;
        }
        let body_index = self.prisms.len();
        if let Some((_, bounds)) = &self.body_mesh
            && body_index < 64
        {
            c.prisms |= u64::from(visible(bounds)) << body_index;
        }
        for (i, part) in self.parts.iter().enumerate().take(64) {
            c.parts |= u64::from(visible(&part.bounds())) << i;
        }
        c
    }

    /// Distance from `p` to the surface `id` (independent of the ray caster; for tests and checks).
    pub fn distance_to_surface(&self, id: SurfaceId, p: Vec3) -> f64 {
        let i = usize::from(id.index);
        match id.kind {
            SurfaceKind::Ground => match &self.hall {
                Some(h) => h.floor.distance(p),
                None => p.z.abs(),
            },
            SurfaceKind::Tyre => self.tyres.get(i).map_or(f64::INFINITY, |t| match &t.mesh {
                Some(m) => m.distance(p),
                None => tyre_distance(t, p),
            }),
            SurfaceKind::Structure | SurfaceKind::OtherVehicle => self
                .hall
                .as_ref()
                .map_or(f64::INFINITY, |h| h.distance_to(id, p)),
            SurfaceKind::Body => match (self.prisms.get(i), &self.body_mesh) {
                (Some(pr), _) => prism_distance(pr, p),
                (None, Some((mesh, _))) if i == self.prisms.len() => mesh.distance(p),
                (None, _) => f64::INFINITY,
            },
            SurfaceKind::Part => self
                .parts
                .get(i)
                .map_or(f64::INFINITY, |pa| part_distance(pa, p)),
        }
    }
}

/// Which primitives [`Scene::cast_among`] tests: one bit per tyre, body prism and part (primitives
/// past the 64th are always tested).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Candidates {
    tyres: u64,
    prisms: u64,
    parts: u64,
}

impl Candidates {
    /// Every primitive.
    pub const ALL: Self = Self {
        tyres: u64::MAX,
        prisms: u64::MAX,
        parts: u64::MAX,
    };

    fn bit(mask: u64, i: usize) -> bool {
        i >= 64 || mask & (1 << i) != 0
    }

    fn has_tyre(self, i: usize) -> bool {
        Self::bit(self.tyres, i)
    }

    fn has_prism(self, i: usize) -> bool {
        Self::bit(self.prisms, i)
    }

    fn has_part(self, i: usize) -> bool {
        Self::bit(self.parts, i)
    }
}

/// Wrap an angle to (-pi, pi].
fn wrap_pi(a: f64) -> f64 {
    let w = (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
    if w <= -std::f64::consts::PI {
        w + std::f64::consts::TAU
    } else {
        w
    }
}

/// Whether the box (grown by 1 cm), seen from above from `o`, overlaps the wedge `mid +- half`.
fn aabb_in_wedge(b: &Aabb, o: Vec3, mid_rad: f64, half_rad: f64) -> bool {
    const GROW_M: f64 = 0.01;
    let (x0, x1, y0, y1) = (
        b.min.x - GROW_M,
        b.max.x + GROW_M,
        b.min.y - GROW_M,
        b.max.y + GROW_M,
    );
    if (x0..=x1).contains(&o.x) && (y0..=y1).contains(&o.y) {
        return true;
    }
    // Outside the rectangle, it subtends less than pi: measure its corners from its centre's bearing.
    let centre = (f64::midpoint(y0, y1) - o.y).atan2(f64::midpoint(x0, x1) - o.x);
    let (mut lo, mut hi) = (0.0f64, 0.0f64);
    for (x, y) in [(x0, y0), (x0, y1), (x1, y0), (x1, y1)] {
        let dev = wrap_pi((y - o.y).atan2(x - o.x) - centre);
        lo = lo.min(dev);
        hi = hi.max(dev);
    }
    let (rect_mid, rect_half) = (centre + f64::midpoint(lo, hi), (hi - lo) / 2.0);
    wrap_pi(rect_mid - mid_rad).abs() <= rect_half + half_rad
}

fn part_prim(part: &Part) -> PartPrim {
    match part {
        Part::Mesh { mesh, .. } => {
            let b = mesh.0.bounds();
            PartPrim::Mesh {
                mesh: Arc::clone(&mesh.0),
                bounds: Aabb {
                    min: b.min,
                    max: b.max,
                },
            }
        }
        Part::Box { min_m, max_m, .. } => PartPrim::Box {
            min: v3(*min_m),
            max: v3(*max_m),
        },
        Part::Cylinder {
            axis,
            centre_m,
            radius_m,
            length_m,
            ..
        } => {
            let c = v3(*centre_m);
            let (r, h) = (*radius_m, length_m / 2.0);
            let half = match axis {
                Axis::X => Vec3::new(h, r, r),
                Axis::Y => Vec3::new(r, h, r),
                Axis::Z => Vec3::new(r, r, h),
            };
            PartPrim::Cylinder {
                axis: *axis,
                centre: c,
                radius: r,
                half_length: h,
                bounds: Aabb {
                    min: c - half,
                    max: c + half,
                },
            }
        }
    }
}

/// Angular segments of a loaded tyre's mesh around its axle.
const LOADED_TYRE_SEGMENTS: usize = 96;

/// The surface of a loaded tyre centred at `centre` (axle along y) as a triangle mesh.
///
/// Around the axle, at angle `th` from straight down, the tread's radius is the free radius `R`
/// except where that would pass below the ground: there it is `h / cos th` (h = the static
/// loaded radius, the centre's height), a flat contact patch on z = 0 from `-acos(h/R)` to
/// `+acos(h/R)` (angles sampled exactly at both ends). Across the tread, the profile runs from
/// the rim edge (rim radius, at the sidewall plane) up the sidewall to a 1.5 cm shoulder and
/// over the flat tread to the other side; each sidewall bulges outward by
/// `bulge * cos(th)^4 * sin(pi s)` (s = 0 at the rim, 1 at the shoulder; none above the axle).
/// Each rim disc sits [`RIM_INSET_M`] inside its sidewall plane, joined to the sidewall's rim
/// edge by a short cylinder (the rim's lip).
pub fn loaded_tyre_mesh(t: &Tyre, centre: Vec3) -> Mesh {
    let (h, big_r, rim, hw, bulge) = (
        t.radius_m,
        t.tread_radius(),
        t.rim_radius_m,
        t.width_m / 2.0,
        t.sidewall_bulge_m,
    );
    let mut angles: Vec<f64> = (0..LOADED_TYRE_SEGMENTS)
        .map(|k| std::f64::consts::TAU * k as f64 / LOADED_TYRE_SEGMENTS as f64)
        .collect();
    if big_r > h {
        let edge = (h / big_r).acos();
        angles.push(edge);
        angles.push(std::f64::consts::TAU - edge);
        angles.sort_by(f64::total_cmp);
        angles.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
    }
    // Profile across the tyre at one angle: (radius, y) from the +y rim disc to the -y one.
    let profile = |th: f64| -> Vec<(f64, f64)> {
        let c = th.cos();
        let tread = if c > 0.0 { big_r.min(h / c) } else { big_r };
        let shoulder = 0.015_f64.min(0.25 * (tread - rim));
        let b = bulge * c.max(0.0).powi(4);
        let wall = |s: f64| {
            (
                rim + s * (tread - shoulder - rim),
                b * (std::f64::consts::PI * s).sin(),
            )
        };
        let mut side: Vec<(f64, f64)> = vec![(rim, hw - RIM_INSET_M), (rim, hw)];
        for s in [0.25, 0.5, 0.75] {
            let (r, dy) = wall(s);
            side.push((r, hw + dy));
        }
        side.push((tread - shoulder, hw));
        side.push((tread, hw - shoulder));
        let mut out = side.clone();
        out.extend(side.iter().rev().map(|&(r, y)| (r, -y)));
        out
    };
    let per_ring = profile(0.0).len();
    let mut vertices = Vec::with_capacity(angles.len() * per_ring + 2);
    for &th in &angles {
        let (s, c) = th.sin_cos();
        for (r, y) in profile(th) {
            vertices.push(Vec3::new(centre.x + r * s, centre.y + y, centre.z - r * c));
        }
    }
    let hub = [
        Vec3::new(centre.x, centre.y + hw - RIM_INSET_M, centre.z),
        Vec3::new(centre.x, centre.y - hw + RIM_INSET_M, centre.z),
    ];
    let hub_index = vertices.len() as u32;
    vertices.extend(hub);
    let n = angles.len();
    let mut triangles = Vec::with_capacity(n * (2 * per_ring));
    for k in 0..n {
        let (a, b) = ((k * per_ring) as u32, (((k + 1) % n) * per_ring) as u32);
        for j in 0..per_ring as u32 - 1 {
            triangles.push([a + j, b + j, b + j + 1]);
            triangles.push([a + j, b + j + 1, a + j + 1]);
        }
        // Rim discs: fans from the hub centres to the first and last profile points.
        triangles.push([hub_index, a, b]);
        let last = per_ring as u32 - 1;
        triangles.push([hub_index + 1, a + last, b + last]);
    }
    // Every vertex is finite and every index in range by construction.
    Mesh::new(vertices, triangles).unwrap_or_default()
}

fn v3(a: [f64; 3]) -> Vec3 {
    Vec3::new(a[0], a[1], a[2])
}

/// Smallest positive root of the ray against a circle of radius `r` in a 2-D projection
/// (`o`, `d` the projected origin relative to the centre and the projected direction).
fn circle_entry(ox: f64, oz: f64, dx: f64, dz: f64, r: f64) -> Option<f64> {
    let a = dx * dx + dz * dz;
    if a < 1e-18 {
        return None;
    }
    let b = ox * dx + oz * dz;
    let c = ox * ox + oz * oz - r * r;
    let disc = b * b - a * c;
    if disc < 0.0 || c < 0.0 {
        return None; // missed, or the origin is inside the circle (we only model outside hits)
    }
    let t = (-b - disc.sqrt()) / a;
    (t > 0.0).then_some(t)
}

fn hit_tyre(ty: &TyrePrim, o: Vec3, d: Vec3, t_max: f64) -> Option<(f64, Vec3)> {
    let c = ty.centre;
    let mut best: Option<(f64, Vec3)> = None;
    let mut consider = |t: f64, n: Vec3| {
        if t > 0.0 && t < best.map_or(t_max, |b| b.0) {
            best = Some((t, n));
        }
    };
    if let Some(t) = circle_entry(o.x - c.x, o.z - c.z, d.x, d.z, ty.radius) {
        let p = o + d * t;
        if (p.y - c.y).abs() <= ty.half_width {
            consider(t, Vec3::new(p.x - c.x, 0.0, p.z - c.z) * (1.0 / ty.radius));
        }
    }
    if d.y.abs() > 1e-12 {
        let (r2, rim2) = (ty.radius * ty.radius, ty.rim_radius * ty.rim_radius);
        for side in [-1.0, 1.0] {
            for (offset, lo2) in [(ty.half_width, rim2), (ty.half_width - RIM_INSET_M, 0.0)] {
                let t = (c.y + side * offset - o.y) / d.y;
                let p = o + d * t;
                let rho2 = (p.x - c.x).powi(2) + (p.z - c.z).powi(2);
                if rho2 >= lo2 && rho2 <= r2 {
                    consider(t, Vec3::new(0.0, side, 0.0));
                }
            }
        }
    }
    best
}

/// Point-in-polygon (even-odd rule) in the x-z plane.
fn inside_polygon(poly: &[[f64; 2]], x: f64, z: f64) -> bool {
    let mut inside = false;
    let mut j = poly.len() - 1;
    for i in 0..poly.len() {
        let ([xi, zi], [xj, zj]) = (poly[i], poly[j]);
        if (zi > z) != (zj > z) && x < (xj - xi) * (z - zi) / (zj - zi) + xi {
            inside = !inside;
        }
        j = i;
    }
    inside
}

fn hit_prism(pr: &Prism, o: Vec3, d: Vec3, t_max: f64) -> Option<(f64, Vec3)> {
    let hw = pr.half_width;
    // Clip the ray to the slab |y| <= hw.
    let (mut t0, mut t1, mut from_side) = (0.0f64, t_max, false);
    if d.y.abs() < 1e-12 {
        if o.y.abs() > hw {
            return None;
        }
    } else {
        let (a, b) = ((-hw - o.y) / d.y, (hw - o.y) / d.y);
        let (a, b) = if a < b { (a, b) } else { (b, a) };
        if a > t0 {
            t0 = a;
            from_side = true;
        }
        t1 = t1.min(b);
    }
    if t0 >= t1 {
        return None;
    }
    if from_side {
        let p = o + d * t0;
        if inside_polygon(&pr.poly, p.x, p.z) {
            return Some((t0, Vec3::new(0.0, -d.y.signum(), 0.0)));
        }
    }
    // First crossing of a polygon edge within (t0, t1).
    let mut best: Option<(f64, Vec3)> = None;
    let n = pr.poly.len();
    for i in 0..n {
        let ([ax, az], [bx, bz]) = (pr.poly[i], pr.poly[(i + 1) % n]);
        let (ex, ez) = (bx - ax, bz - az);
        let denom = d.x * ez - d.z * ex;
        if denom.abs() < 1e-15 {
            continue;
        }
        let (wx, wz) = (ax - o.x, az - o.z);
        let t = (wx * ez - wz * ex) / denom;
        let s = (wx * d.z - wz * d.x) / denom;
        if (0.0..=1.0).contains(&s) && t > t0 && t < t1 && t < best.map_or(f64::INFINITY, |b| b.0) {
            best = Some((t, Vec3::new(ez, 0.0, -ex).normalized()));
        }
    }
    best
}

fn hit_box(min: Vec3, max: Vec3, o: Vec3, d: Vec3) -> Option<(f64, Vec3)> {
    let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
    let mut normal = Vec3::zeros();
    let axes = [
        (o.x, d.x, min.x, max.x, Vec3::new(1.0, 0.0, 0.0)),
        (o.y, d.y, min.y, max.y, Vec3::new(0.0, 1.0, 0.0)),
        (o.z, d.z, min.z, max.z, Vec3::new(0.0, 0.0, 1.0)),
    ];
    for (o, d, lo, hi, axis) in axes {
        if d.abs() < 1e-15 {
            if o < lo || o > hi {
                return None;
            }
            continue;
        }
        let (a, b) = ((lo - o) / d, (hi - o) / d);
        let (a, b) = if a < b { (a, b) } else { (b, a) };
        if a > t0 {
            t0 = a;
            normal = axis;
        }
        t1 = t1.min(b);
    }
    (t0 > 0.0 && t0 <= t1).then_some((t0, normal))
}

/// Split `v` into (along the axis, first cross coordinate, second cross coordinate).
fn axis_split(axis: Axis, v: Vec3) -> (f64, f64, f64) {
    match axis {
        Axis::X => (v.x, v.y, v.z),
        Axis::Y => (v.y, v.x, v.z),
        Axis::Z => (v.z, v.x, v.y),
    }
}

fn axis_join(axis: Axis, a: f64, u: f64, v: f64) -> Vec3 {
    match axis {
        Axis::X => Vec3::new(a, u, v),
        Axis::Y => Vec3::new(u, a, v),
        Axis::Z => Vec3::new(u, v, a),
    }
}

fn hit_cylinder(axis: Axis, c: Vec3, r: f64, h: f64, o: Vec3, d: Vec3) -> Option<(f64, Vec3)> {
    let (oa, ou, ov) = axis_split(axis, o - c);
    let (da, du, dv) = axis_split(axis, d);
    let mut best: Option<(f64, Vec3)> = None;
    if let Some(t) = circle_entry(ou, ov, du, dv, r)
        && (oa + da * t).abs() <= h
    {
        best = Some((
            t,
            axis_join(axis, 0.0, ou + du * t, ov + dv * t) * (1.0 / r),
        ));
    }
    if da.abs() > 1e-15 {
        for side in [-1.0, 1.0] {
            let t = (side * h - oa) / da;
            let (u, v) = (ou + du * t, ov + dv * t);
            if t > 0.0 && u * u + v * v <= r * r && t < best.map_or(f64::INFINITY, |b| b.0) {
                best = Some((t, axis_join(axis, side, 0.0, 0.0)));
            }
        }
    }
    best
}

/// Distance from a point to a solid's surface given its signed "excess" along two independent
/// directions (`da`, `dr` <= 0 inside): inside, the nearer face; outside, the Euclidean corner distance.
fn two_way_distance(da: f64, dr: f64) -> f64 {
    if da <= 0.0 && dr <= 0.0 {
        (-da).min(-dr)
    } else {
        da.max(0.0).hypot(dr.max(0.0))
    }
}

fn tyre_distance(t: &TyrePrim, p: Vec3) -> f64 {
    let q = p - t.centre;
    let rho = q.x.hypot(q.z);
    let tread = (q.y.abs() - t.half_width).max(0.0).hypot(rho - t.radius);
    let wall = (q.y.abs() - t.half_width)
        .abs()
        .hypot((t.rim_radius - rho).max(rho - t.radius).max(0.0));
    let rim = (q.y.abs() - (t.half_width - RIM_INSET_M))
        .abs()
        .hypot((rho - t.radius).max(0.0));
    tread.min(wall).min(rim)
}

fn prism_distance(pr: &Prism, p: Vec3) -> f64 {
    let n = pr.poly.len();
    let edge = (0..n)
        .map(|i| {
            crate::vehicle::segment_point_distance(pr.poly[i], pr.poly[(i + 1) % n], [p.x, p.z])
        })
        .fold(f64::INFINITY, f64::min);
    let inside = inside_polygon(&pr.poly, p.x, p.z);
    two_way_distance(p.y.abs() - pr.half_width, if inside { -edge } else { edge })
}

fn part_distance(part: &PartPrim, p: Vec3) -> f64 {
    match part {
        PartPrim::Box { min, max } => {
            let c = (*min + *max) * 0.5;
            let h = (*max - *min) * 0.5;
            let q = p - c;
            let e = Vec3::new(q.x.abs() - h.x, q.y.abs() - h.y, q.z.abs() - h.z);
            if e.x <= 0.0 && e.y <= 0.0 && e.z <= 0.0 {
                -(e.x.max(e.y).max(e.z))
            } else {
                Vec3::new(e.x.max(0.0), e.y.max(0.0), e.z.max(0.0)).norm()
            }
        }
        PartPrim::Cylinder {
            axis,
            centre,
            radius,
            half_length,
            ..
        } => {
            let (a, u, v) = axis_split(*axis, p - *centre);
            two_way_distance(a.abs() - half_length, u.hypot(v) - radius)
        }
        PartPrim::Mesh { mesh, .. } => mesh.distance(p),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vehicle::tests::test_sedan;
    use rand::{Rng, SeedableRng};

    fn scene() -> Scene {
        Scene::from_vehicle(&test_sedan())
    }

    #[test]
    fn straight_down_hits_ground_and_straight_up_hits_underside() {
        let s = scene();
        let o = Vec3::new(-1.4, 0.0, 0.1);
        let down = s.cast(o, Vec3::new(0.0, 0.0, -1.0), 100.0).expect("ground");
        assert_eq!(down.surface.kind, SurfaceKind::Ground);
        assert!((down.range_m - 0.1).abs() < 1e-12);
        let up = s
            .cast(o, Vec3::new(0.0, 0.0, 1.0), 100.0)
            .expect("underside");
        assert_eq!(
            up.surface,
            SurfaceId {
                kind: SurfaceKind::Body,
                index: 1
            }
        );
        assert!(
            (up.range_m - 0.04).abs() < 1e-12,
            "floor at 0.14 m: {}",
            up.range_m
        );
        assert!((up.normal.z + 1.0).abs() < 1e-3);
    }

    #[test]
    fn sideways_ray_hits_the_inner_sidewall_or_tread_of_the_left_front_tyre() {
        let s = scene();
        let hit = s
            .cast(Vec3::new(0.0, 0.0, 0.33), Vec3::new(0.0, 1.0, 0.0), 100.0)
            .expect("tyre");
        assert_eq!(
            hit.surface,
            SurfaceId {
                kind: SurfaceKind::Tyre,
                index: 0
            }
        );
        // Through the rim opening onto the recessed rim disc: y = track/2 - width/2 + inset.
        assert!(
            (hit.range_m - (0.79 - 0.1125 + RIM_INSET_M)).abs() < 1e-12,
            "{}",
            hit.range_m
        );
        let hit = s
            .cast(Vec3::new(0.0, 0.0, 0.05), Vec3::new(0.0, 1.0, 0.0), 100.0)
            .expect("tyre");
        assert!(
            (hit.range_m - (0.79 - 0.1125)).abs() < 1e-12,
            "sidewall: {}",
            hit.range_m
        );
    }

    #[test]
    fn wedge_culling_never_changes_a_hit() {
        let s = scene();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(12);
        let mut culled = 0usize;
        for _ in 0..20_000 {
            let o = Vec3::new(
                rng.random_range(-4.5..2.0),
                rng.random_range(-0.6..0.6),
                rng.random_range(0.05..0.13),
            );
            let heading: f64 = rng.random_range(-3.2..3.2);
            let half: f64 = rng.random_range(0.01..0.3);
            let a = heading + rng.random_range(-half..half);
            let elevation: f64 = rng.random_range(-0.3..0.3);
            let d = Vec3::new(
                a.cos() * elevation.cos(),
                a.sin() * elevation.cos(),
                elevation.sin(),
            );
            let c = s.candidates_in_wedge(o, heading, half);
            culled += usize::from(c.tyres.count_ones() < 4);
            assert_eq!(s.cast_among(o, d, 100.0, c), s.cast(o, d, 100.0));
        }
        assert!(
            culled > 10_000,
            "the wedges culled tyres only {culled} times"
        );
    }

    #[test]
    fn rays_into_the_sky_return_nothing() {
        let s = scene();
        assert!(
            s.cast(Vec3::new(5.0, 0.0, 0.1), Vec3::new(0.0, 0.0, 1.0), 100.0)
                .is_none()
        );
    }

    #[test]
    fn every_hit_lies_on_the_surface_it_reports() {
        let s = scene();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut kinds = std::collections::HashSet::new();
        for _ in 0..20_000 {
            let o = Vec3::new(
                rng.random_range(-4.5..2.0),
                rng.random_range(-0.6..0.6),
                rng.random_range(0.05..0.13),
            );
            let d = Vec3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            )
            .normalized();
            if let Some(hit) = s.cast(o, d, 100.0) {
                let p = o + d * hit.range_m;
                let dist = s.distance_to_surface(hit.surface, p);
                assert!(dist < 1e-9, "{:?} at {p:?}: {dist}", hit.surface);
                assert!(hit.normal.dot(&d) <= 0.0);
                kinds.insert(hit.surface.kind);
            }
        }
        assert_eq!(kinds.len(), 4, "all surface kinds were hit: {kinds:?}");
    }
}
