//! Vehicles: the TOML format (parametric prisms, boxes and cylinders, and triangle-mesh parts or
//! body), its validation, and the side-view outline used for the true angles.
//!
//! # Frame
//! The vehicle frame is right-handed, z up, x toward the vehicle's front, y to its left, metres
//! (docs/architecture.md section 8). Its origin is **on the ground, under the centre of the front axle**: the
//! front wheel centres are at `(0, ±track/2, r)` and the rear ones at `(-wheelbase, ±track/2, r)`.
//! The ground is the plane z = 0.
//!
//! # Shape
//! The body is a set of prisms. Each underside section (front overhang, between the axles, rear
//! overhang) is a side-view polyline of `(x_m, z_m)` points, ordered from front to rear (x strictly
//! decreasing); the section's prism is the area between that polyline and `body_height_m`, extruded
//! over `width_m` centred on y = 0. The first point of the front section is the lower edge of the
//! front bumper, so the body's front face rises vertically from it to the roof line; likewise the rear
//! face at the last point of the rear section. Over each axle a wheel-arch prism joins the sections,
//! from `2 r + arch_clearance_m` up to the roof line. Tyres are cylinders (tread of radius `radius_m`,
//! width `width_m`, flat sidewalls, a rim disc recessed by [`RIM_INSET_M`]). Optional parts (exhaust,
//! differential, skid plate, tow hitch, mud flaps, ...) are axis-aligned boxes or cylinders.
//!
//! # Example
//! ```toml
//! name = "example sedan"
//! wheelbase_m = 2.8
//! track_m = 1.58
//! body_width_m = 1.84
//! body_height_m = 1.45
//! arch_clearance_m = 0.05      # optional, default 0.05
//!
//! [tyre]
//! radius_m = 0.33
//! width_m = 0.225
//! rim_radius_m = 0.23
//!
//! [underside.front]            # ahead of the front axle: every x > 0
//! width_m = 1.70
//! points = [[0.98, 0.32], [0.80, 0.18], [0.45, 0.15]]
//! [underside.between]          # between the axles: -wheelbase < x < 0
//! width_m = 1.50
//! points = [[-0.45, 0.15], [-2.35, 0.15]]
//! [underside.rear]             # behind the rear axle: every x < -wheelbase
//! width_m = 1.70
//! points = [[-3.25, 0.18], [-3.85, 0.38]]
//!
//! [[parts]]
//! kind = "cylinder"            # or "box" with min_m / max_m corners
//! name = "exhaust"
//! axis = "x"                   # x, y or z
//! centre_m = [-3.0, 0.5, 0.22]
//! radius_m = 0.04
//! length_m = 0.6
//! rigid = true                 # optional, default true; false for mud flaps, air dams
//!
//! [[parts]]
//! kind = "mesh"                # a triangle mesh read from OBJ, STL or PLY (docs/simulator.md, "Triangle-mesh vehicles")
//! name = "silencer"
//! file = "meshes/silencer.obj" # relative to this vehicle file's directory
//! scale = 1.0                  # optional, default 1: file units to metres
//! offset_m = [-3.1, 0.0, 0.24] # optional, default 0: added after scaling
//! rigid = true
//! ```
//! Unknown keys are rejected; every validation error names the file and the field. Mesh parts are
//! read by [`Vehicle::load`] (or [`Vehicle::from_toml_str_in_dir`]); [`Vehicle::from_toml_str`]
//! has no directory to read them from and rejects them.
//!
//! # Mesh body
//! Instead of `[underside]`, a vehicle may give its whole body as one triangle mesh:
//! ```toml
//! [body_mesh]
//! file = "meshes/body.obj"     # relative to this vehicle file's directory
//! scale = 1.0                  # optional
//! offset_m = [0.0, 0.0, 0.0]   # optional
//! ```
//! It replaces the prisms and the wheel arches (so it must leave room for the tyres itself; the
//! prisms' tyre-gap check does not apply), and its points appear in witness reports as `body`.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::Deserialize;

use crate::geometry::Vec3;
use crate::mesh::{Mesh, MeshError};

/// How far the rim disc sits inside the tyre's sidewall plane, metres.
pub const RIM_INSET_M: f64 = 0.03;

/// Most edge samples one mesh adds to the outline (bounds the true-angle work on huge meshes).
pub const MAX_MESH_EDGE_SAMPLES: f64 = 4.0e6;

/// The outline source name of a mesh body's points.
pub const BODY_MESH_SOURCE: &str = "body";

/// Default gap between the top of the tyre and the wheel arch, metres.
pub const DEFAULT_ARCH_CLEARANCE_M: f64 = 0.05;

/// Minimum side-view clearance between the underside polylines and a tyre circle, metres.
pub const MIN_TYRE_GAP_M: f64 = 0.01;

/// Largest length, and largest coordinate magnitude, a vehicle file may use, metres (keeps every
/// derived computation finite and small).
pub const MAX_DIMENSION_M: f64 = 50.0;

/// Smallest outline sampling step, metres; smaller requests are raised to it.
pub const MIN_SPACING_M: f64 = 1e-4;

/// A vehicle as written in its TOML file (see the module docs for the format).
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Vehicle {
    /// Human-readable name.
    pub name: String,
    /// Distance between the axles, metres.
    pub wheelbase_m: f64,
    /// Distance between the left and right tyre centre planes, metres.
    pub track_m: f64,
    /// Overall body width, metres (the wheel arches span it).
    pub body_width_m: f64,
    /// Height of the roof line above the ground, metres.
    pub body_height_m: f64,
    /// Gap between the tyre top and the wheel arch, metres.
    #[serde(default = "default_arch_clearance")]
    pub arch_clearance_m: f64,
    /// The tyres (all four alike).
    pub tyre: Tyre,
    /// The underside profile of a prism body (exactly one of `underside` and `body_mesh`).
    #[serde(default)]
    pub underside: Option<Underside>,
    /// The whole body as a triangle mesh instead of prisms.
    #[serde(default)]
    pub body_mesh: Option<BodyMesh>,
    /// Optional parts.
    #[serde(default)]
    pub parts: Vec<Part>,
    /// Published angles of the real vehicle this one resembles, for documentation only.
    #[serde(default)]
    pub published: Option<PublishedAngles>,
}

fn default_arch_clearance() -> f64 {
    DEFAULT_ARCH_CLEARANCE_M
}

fn default_true() -> bool {
    true
}

fn default_one() -> f64 {
    1.0
}

/// A mesh part's triangles in the vehicle frame (scaled and offset), shared by clones. Empty until
/// the vehicle file's loader reads the mesh file.
#[derive(Clone, Default, PartialEq)]
pub struct LoadedMesh(pub Arc<Mesh>);

impl std::fmt::Debug for LoadedMesh {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "LoadedMesh({} vertices, {} triangles)",
            self.0.vertices().len(),
            self.0.triangles().len()
        )
    }
}

/// Tyre dimensions (static loaded radius).
#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Tyre {
    /// Static loaded radius, metres: the wheel centre is this high above the ground.
    pub radius_m: f64,
    /// Tread width, metres.
    pub width_m: f64,
    /// Rim radius, metres (inside the sidewall annulus).
    pub rim_radius_m: f64,
    /// Free (unloaded) tread radius, metres; absent: `radius_m`, a rigid cylinder. When larger
    /// than `radius_m` the tyre is loaded: the tread is a circle of this radius about the wheel
    /// centre, flattened where it would pass below the ground (the contact patch), and the
    /// scene casts it as a mesh ([`crate::world`]). The true angles still use `radius_m` (the
    /// standards' static loaded radius arc).
    #[serde(default)]
    pub tread_radius_m: Option<f64>,
    /// Outward bulge of each sidewall at the contact patch, metres (0: flat sidewalls). It
    /// fades to nothing at the top of the tyre.
    #[serde(default)]
    pub sidewall_bulge_m: f64,
}

impl Tyre {
    /// The free tread radius (`tread_radius_m`, else the static loaded radius).
    pub fn tread_radius(&self) -> f64 {
        self.tread_radius_m.unwrap_or(self.radius_m)
    }

    /// Whether the tyre is modelled as loaded (flattened or bulging) rather than a cylinder.
    pub fn is_loaded(&self) -> bool {
        self.tread_radius() > self.radius_m || self.sidewall_bulge_m > 0.0
    }
}

/// A body given as a triangle mesh (see docs/simulator.md, "Triangle-mesh vehicles"): it replaces the prisms and the wheel
/// arches, so the mesh must leave room for the tyres itself.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct BodyMesh {
    /// The mesh file, relative to the vehicle file's directory.
    pub file: PathBuf,
    /// Factor from the file's units to metres.
    #[serde(default = "default_one")]
    pub scale: f64,
    /// Added to every scaled vertex, metres.
    #[serde(default)]
    pub offset_m: [f64; 3],
    /// The triangles in the vehicle frame, filled in by the loader.
    #[serde(skip)]
    pub mesh: LoadedMesh,
}

/// The three underside sections.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Underside {
    /// Front overhang: from the bumper's lower edge back toward the front tyre.
    pub front: Section,
    /// Between the axles.
    pub between: Section,
    /// Rear overhang: from behind the rear tyre to the rear bumper's lower edge.
    pub rear: Section,
}

/// One side-view polyline with its lateral extent.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Section {
    /// Lateral extent, metres, centred on y = 0.
    pub width_m: f64,
    /// `(x_m, z_m)` points, front to rear (x strictly decreasing).
    pub points: Vec<[f64; 2]>,
}

/// Axis of a cylindrical part.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum Axis {
    /// Along the vehicle (exhaust pipe).
    X,
    /// Across the vehicle (differential housing, axle tube, tow bar).
    Y,
    /// Vertical.
    Z,
}

/// An optional part under the body.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
pub enum Part {
    /// An axis-aligned box.
    Box {
        /// Name, used in witness reports.
        name: String,
        /// Minimum corner, metres.
        min_m: [f64; 3],
        /// Maximum corner, metres.
        max_m: [f64; 3],
        /// Rigid (counts for EU-style rigid-only angles) or flexible (mud flap, air dam).
        #[serde(default = "default_true")]
        rigid: bool,
    },
    /// A finite cylinder with flat caps along one axis.
    Cylinder {
        /// Name, used in witness reports.
        name: String,
        /// Axis direction.
        axis: Axis,
        /// Centre, metres.
        centre_m: [f64; 3],
        /// Radius, metres.
        radius_m: f64,
        /// Length along the axis, metres.
        length_m: f64,
        /// Rigid or flexible, as for boxes.
        #[serde(default = "default_true")]
        rigid: bool,
    },
    /// A triangle mesh read from an OBJ, STL or PLY file.
    Mesh {
        /// Name, used in witness reports.
        name: String,
        /// The mesh file, relative to the vehicle file's directory.
        file: PathBuf,
        /// Factor from the file's units to metres.
        #[serde(default = "default_one")]
        scale: f64,
        /// Added to every scaled vertex, metres.
        #[serde(default)]
        offset_m: [f64; 3],
        /// Rigid or flexible, as for boxes.
        #[serde(default = "default_true")]
        rigid: bool,
        /// The triangles in the vehicle frame, filled in by the loader.
        #[serde(skip)]
        mesh: LoadedMesh,
    },
}

impl Part {
    /// The part's name.
    pub fn name(&self) -> &str {
        match self {
            Part::Box { name, .. } | Part::Cylinder { name, .. } | Part::Mesh { name, .. } => name,
        }
    }

    /// Whether the part is rigid.
    pub fn rigid(&self) -> bool {
        match self {
            Part::Box { rigid, .. } | Part::Cylinder { rigid, .. } | Part::Mesh { rigid, .. } => {
                *rigid
            }
        }
    }
}

/// Published angles, degrees (documentation and plausibility checks only).
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PublishedAngles {
    /// Approach angle, degrees.
    pub approach_deg: f64,
    /// Ramp breakover angle, degrees.
    pub breakover_deg: f64,
    /// Departure angle, degrees.
    pub departure_deg: f64,
    /// Where the figures come from.
    pub source: String,
}

/// Why a vehicle file was rejected.
#[derive(Debug, thiserror::Error)]
pub enum VehicleError {
    /// The file could not be read.
    #[error("cannot read vehicle file {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The IO error.
        source: std::io::Error,
    },
    /// The TOML did not parse or did not match the format (the message names line and key).
    #[error("vehicle file {path}: {message}")]
    Toml {
        /// The file.
        path: PathBuf,
        /// toml's message, with line and column.
        message: String,
    },
    /// A field has an impossible value.
    #[error("vehicle file {path}: field `{field}`: {reason}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// Dotted field name, e.g. `underside.front.points[2]`.
        field: String,
        /// What is wrong.
        reason: String,
    },
    /// A mesh part's file could not be read or is malformed.
    #[error("vehicle file {path}: field `{field}`: {source}")]
    Mesh {
        /// The vehicle file.
        path: PathBuf,
        /// Dotted field name, e.g. `parts[2].file`.
        field: String,
        /// What is wrong with the mesh file (boxed: it is large and rare).
        source: Box<MeshError>,
    },
}

impl Vehicle {
    /// Read and validate a vehicle file.
    pub fn load(path: &Path) -> Result<Self, VehicleError> {
        let text = std::fs::read_to_string(path).map_err(|source| VehicleError::Io {
            path: path.to_owned(),
            source,
        })?;
        let dir = path.parent().unwrap_or(Path::new("."));
        Self::parse(&text, path, Some(dir))
    }

    /// Parse and validate vehicle TOML without mesh parts; `path` is only used in error messages.
    /// A mesh part is an error here (there is no directory to read its file from).
    pub fn from_toml_str(text: &str, path: &Path) -> Result<Self, VehicleError> {
        Self::parse(text, path, None)
    }

    /// Parse and validate vehicle TOML, reading mesh parts' files relative to `dir`; `path` is only
    /// used in error messages.
    pub fn from_toml_str_in_dir(text: &str, path: &Path, dir: &Path) -> Result<Self, VehicleError> {
        Self::parse(text, path, Some(dir))
    }

    fn parse(text: &str, path: &Path, dir: Option<&Path>) -> Result<Self, VehicleError> {
        let mut vehicle: Vehicle = toml::from_str(text).map_err(|e| VehicleError::Toml {
            path: path.to_owned(),
            message: e.to_string(),
        })?;
        vehicle
            .validate()
            .map_err(|(field, reason)| VehicleError::Invalid {
                path: path.to_owned(),
                field,
                reason,
            })?;
        if let Some(body) = &mut vehicle.body_mesh {
            let placed = load_mesh_file(
                path,
                dir,
                "body_mesh.file",
                &body.file,
                body.scale,
                body.offset_m,
            )?;
            body.mesh = LoadedMesh(Arc::new(placed));
        }
        for (i, part) in vehicle.parts.iter_mut().enumerate() {
            if let Part::Mesh {
                file,
                scale,
                offset_m,
                mesh,
                ..
            } = part
            {
                let placed = load_mesh_file(
                    path,
                    dir,
                    &format!("parts[{i}].file"),
                    file,
                    *scale,
                    *offset_m,
                )?;
                *mesh = LoadedMesh(Arc::new(placed));
            }
        }
        Ok(vehicle)
    }

    /// Check every field; on failure return `(field, reason)`.
    pub fn validate(&self) -> Result<(), (String, String)> {
        positive("wheelbase_m", self.wheelbase_m)?;
        positive("track_m", self.track_m)?;
        positive("body_width_m", self.body_width_m)?;
        positive("body_height_m", self.body_height_m)?;
        non_negative("arch_clearance_m", self.arch_clearance_m)?;
        positive("tyre.radius_m", self.tyre.radius_m)?;
        positive("tyre.width_m", self.tyre.width_m)?;
        positive("tyre.rim_radius_m", self.tyre.rim_radius_m)?;
        let r = self.tyre.radius_m;
        if self.tyre.rim_radius_m >= r {
            return fail("tyre.rim_radius_m", "must be smaller than tyre.radius_m");
        }
        if let Some(tr) = self.tyre.tread_radius_m
            && !(tr >= r && tr <= 1.2 * r)
        {
            return fail(
                "tyre.tread_radius_m",
                "must lie between tyre.radius_m and 1.2 x tyre.radius_m",
            );
        }
        if !(0.0..=0.05).contains(&self.tyre.sidewall_bulge_m) {
            return fail("tyre.sidewall_bulge_m", "must lie in 0..=0.05 m");
        }
        if self.tyre.width_m <= 2.0 * RIM_INSET_M {
            return fail(
                "tyre.width_m",
                format!("must exceed twice the rim inset ({RIM_INSET_M} m)"),
            );
        }
        if self.track_m <= self.tyre.width_m {
            return fail(
                "track_m",
                "must exceed tyre.width_m (the tyres would overlap)",
            );
        }
        if self.wheelbase_m <= 2.0 * r {
            return fail(
                "wheelbase_m",
                "must exceed the tyre diameter (the tyres would overlap)",
            );
        }
        if self.body_height_m <= r + self.tyre.tread_radius() + self.arch_clearance_m {
            return fail(
                "body_height_m",
                "must exceed the tyre's height (radius_m + tread radius) plus arch_clearance_m",
            );
        }
        match (&self.underside, &self.body_mesh) {
            (Some(u), None) => self.validate_underside(u)?,
            (None, Some(b)) => {
                if b.file.as_os_str().is_empty() {
                    return fail("body_mesh.file", "must name a mesh file");
                }
                positive("body_mesh.scale", b.scale)?;
                coordinates("body_mesh.offset_m", &b.offset_m)?;
            }
            (Some(_), Some(_)) => {
                return fail(
                    "body_mesh",
                    "give either [underside] or [body_mesh], not both",
                );
            }
            (None, None) => {
                return fail("underside", "missing: give [underside] or [body_mesh]");
            }
        }
        for (i, part) in self.parts.iter().enumerate() {
            validate_part(&format!("parts[{i}]"), part)?;
        }
        Ok(())
    }

    fn validate_underside(&self, u: &Underside) -> Result<(), (String, String)> {
        let wb = self.wheelbase_m;
        let sections = [
            ("underside.front", &u.front, 0.0, f64::INFINITY),
            ("underside.between", &u.between, -wb, 0.0),
            ("underside.rear", &u.rear, f64::NEG_INFINITY, -wb),
        ];
        for (name, section, x_min, x_max) in sections {
            self.validate_section(name, section, x_min, x_max)?;
        }
        Ok(())
    }

    fn validate_section(
        &self,
        name: &str,
        section: &Section,
        x_min: f64,
        x_max: f64,
    ) -> Result<(), (String, String)> {
        positive(&format!("{name}.width_m"), section.width_m)?;
        if section.width_m > self.body_width_m {
            return fail(&format!("{name}.width_m"), "must not exceed body_width_m");
        }
        if section.points.len() < 2 {
            return fail(
                &format!("{name}.points"),
                "needs at least two (x_m, z_m) points",
            );
        }
        for (i, &[x, z]) in section.points.iter().enumerate() {
            let field = format!("{name}.points[{i}]");
            coordinates(&field, &[x, z])?;
            if x <= x_min || x >= x_max {
                return fail(
                    &field,
                    format!("x = {x} m must lie strictly between {x_min} and {x_max} m"),
                );
            }
            if z <= 0.0 || z >= self.body_height_m - 0.05 {
                return fail(
                    &field,
                    format!("z = {z} m must be above the ground and 5 cm below body_height_m"),
                );
            }
            if i > 0 && x >= section.points[i - 1][0] {
                return fail(&field, "x must strictly decrease from front to rear");
            }
        }
        for (i, w) in section.points.windows(2).enumerate() {
            for axle_x in [0.0, -self.wheelbase_m] {
                let gap = segment_point_distance(w[0], w[1], [axle_x, self.tyre.radius_m])
                    - self.tyre.tread_radius();
                if gap < MIN_TYRE_GAP_M {
                    return fail(
                        &format!("{name}.points[{i}..={}]", i + 1),
                        format!(
                            "passes within {MIN_TYRE_GAP_M} m of the tyre at x = {axle_x} m (side view)"
                        ),
                    );
                }
            }
        }
        Ok(())
    }

    /// Centres of the four tyres in the vehicle frame: front-left, front-right, rear-left, rear-right.
    pub fn tyre_centres(&self) -> [[f64; 3]; 4] {
        let (r, h, wb) = (self.tyre.radius_m, self.track_m / 2.0, self.wheelbase_m);
        [[0.0, h, r], [0.0, -h, r], [-wb, h, r], [-wb, -h, r]]
    }

    /// The x of the front bumper's lower edge (the vehicle's front end; a mesh body's largest x).
    pub fn front_x_m(&self) -> f64 {
        match (&self.underside, &self.body_mesh) {
            (Some(u), _) => u.front.points.first().map_or(0.0, |p| p[0]),
            (None, Some(b)) => b.mesh.0.vertex_bounds().map_or(0.0, |e| e.max.x),
            (None, None) => 0.0,
        }
    }

    /// The x of the rear bumper's lower edge (the vehicle's rear end; a mesh body's smallest x).
    pub fn rear_x_m(&self) -> f64 {
        match (&self.underside, &self.body_mesh) {
            (Some(u), _) => u.rear.points.last().map_or(-self.wheelbase_m, |p| p[0]),
            (None, Some(b)) => b
                .mesh
                .0
                .vertex_bounds()
                .map_or(-self.wheelbase_m, |e| e.min.x),
            (None, None) => -self.wheelbase_m,
        }
    }

    /// The body's side-view polygons, one per prism, each with its lateral width: the three sections
    /// and the two wheel arches. Polygons are closed implicitly (last vertex joins the first).
    /// Empty for a mesh body.
    pub fn body_prisms(&self) -> Vec<(String, Vec<[f64; 2]>, f64)> {
        let top = self.body_height_m;
        let Some(u) = &self.underside else {
            return Vec::new();
        };
        let mut out = Vec::new();
        for (name, s) in [
            ("front overhang", &u.front),
            ("between axles", &u.between),
            ("rear overhang", &u.rear),
        ] {
            let mut poly = s.points.clone();
            let (first, last) = (s.points[0][0], s.points[s.points.len() - 1][0]);
            poly.push([last, top]);
            poly.push([first, top]);
            out.push((name.to_owned(), poly, s.width_m));
        }
        let arch_z = self.tyre.radius_m + self.tyre.tread_radius() + self.arch_clearance_m;
        let arches = [
            (
                "front arch",
                u.front.points[u.front.points.len() - 1][0],
                u.between.points[0][0],
            ),
            (
                "rear arch",
                u.between.points[u.between.points.len() - 1][0],
                u.rear.points[0][0],
            ),
        ];
        for (name, x_front, x_rear) in arches {
            let poly = vec![
                [x_front, arch_z],
                [x_rear, arch_z],
                [x_rear, top],
                [x_front, top],
            ];
            out.push((name.to_owned(), poly, self.body_width_m));
        }
        out
    }

    /// The vehicle's side-view outline as points, every polyline vertex plus samples at most
    /// `spacing_m` apart along every edge (underside, bumper faces, arches, parts). This is what the
    /// true-angle routine searches; the vertices alone are returned by [`Vehicle::outline_vertices`].
    /// Steps below [`MIN_SPACING_M`] (or NaN) are raised to it.
    pub fn outline_points(&self, spacing_m: f64) -> Vec<OutlinePoint> {
        let spacing_m = if spacing_m >= MIN_SPACING_M {
            spacing_m
        } else {
            MIN_SPACING_M
        };
        let mut out = Vec::new();
        for edge in self.outline_edges() {
            let n = ((distance2(edge.a, edge.b) / spacing_m).ceil() as usize).max(1);
            for k in 0..=n {
                let t = k as f64 / n as f64;
                out.push(OutlinePoint {
                    x_m: edge.a[0] + t * (edge.b[0] - edge.a[0]),
                    z_m: edge.a[1] + t * (edge.b[1] - edge.a[1]),
                    rigid: edge.rigid,
                    source: edge.source.clone(),
                });
            }
        }
        if let Some(body) = &self.body_mesh {
            out.extend(
                mesh_side_view(&body.mesh.0, spacing_m)
                    .into_iter()
                    .map(|[x_m, z_m]| OutlinePoint {
                        x_m,
                        z_m,
                        rigid: true,
                        source: BODY_MESH_SOURCE.to_owned(),
                    }),
            );
        }
        for part in &self.parts {
            if let Part::Mesh { mesh, .. } = part {
                out.extend(
                    mesh_side_view(&mesh.0, spacing_m)
                        .into_iter()
                        .map(|[x_m, z_m]| OutlinePoint {
                            x_m,
                            z_m,
                            rigid: part.rigid(),
                            source: part.name().to_owned(),
                        }),
                );
            }
        }
        out
    }

    /// The outline's vertices only (no samples along edges), mesh parts' vertices included.
    pub fn outline_vertices(&self) -> Vec<OutlinePoint> {
        let mut out = Vec::new();
        for edge in self.outline_edges() {
            for p in [edge.a, edge.b] {
                out.push(OutlinePoint {
                    x_m: p[0],
                    z_m: p[1],
                    rigid: edge.rigid,
                    source: edge.source.clone(),
                });
            }
        }
        if let Some(body) = &self.body_mesh {
            out.extend(body.mesh.0.vertices().iter().map(|v| OutlinePoint {
                x_m: v.x,
                z_m: v.z,
                rigid: true,
                source: BODY_MESH_SOURCE.to_owned(),
            }));
        }
        for part in &self.parts {
            if let Part::Mesh { mesh, .. } = part {
                out.extend(mesh.0.vertices().iter().map(|v| OutlinePoint {
                    x_m: v.x,
                    z_m: v.z,
                    rigid: part.rigid(),
                    source: part.name().to_owned(),
                }));
            }
        }
        out
    }

    /// Side-view edges of everything that can touch a ramp: body prisms and box and cylinder parts
    /// (mesh parts contribute points, see `mesh_side_view`). Cylinders whose axis is y appear as
    /// 64-gons (documented approximation, error below 0.12 % of the radius).
    fn outline_edges(&self) -> Vec<OutlineEdge> {
        let mut edges = Vec::new();
        for (name, poly, _) in self.body_prisms() {
            for i in 0..poly.len() {
                let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
                edges.push(OutlineEdge {
                    a,
                    b,
                    rigid: true,
                    source: name.clone(),
                });
            }
        }
        for part in &self.parts {
            let Some(poly) = part_side_view(part) else {
                continue;
            };
            for i in 0..poly.len() {
                let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
                edges.push(OutlineEdge {
                    a,
                    b,
                    rigid: part.rigid(),
                    source: part.name().to_owned(),
                });
            }
        }
        edges
    }
}

/// One point of the side-view outline.
#[derive(Clone, Debug, PartialEq)]
pub struct OutlinePoint {
    /// x in the vehicle frame, metres.
    pub x_m: f64,
    /// Height above the ground, metres.
    pub z_m: f64,
    /// False for flexible parts.
    pub rigid: bool,
    /// Which body section or part this point belongs to.
    pub source: String,
}

struct OutlineEdge {
    a: [f64; 2],
    b: [f64; 2],
    rigid: bool,
    source: String,
}

/// A box's or cylinder's side-view (x, z) outline polygon (`None` for a mesh).
fn part_side_view(part: &Part) -> Option<Vec<[f64; 2]>> {
    Some(match part {
        Part::Mesh { .. } => return None,
        Part::Box { min_m, max_m, .. } => rectangle(min_m[0], max_m[0], min_m[2], max_m[2]),
        Part::Cylinder {
            axis,
            centre_m: c,
            radius_m: r,
            length_m: l,
            ..
        } => match axis {
            Axis::X => rectangle(c[0] - l / 2.0, c[0] + l / 2.0, c[2] - r, c[2] + r),
            Axis::Z => rectangle(c[0] - r, c[0] + r, c[2] - l / 2.0, c[2] + l / 2.0),
            Axis::Y => (0..64)
                .map(|k| {
                    let a = std::f64::consts::TAU * f64::from(k) / 64.0;
                    [c[0] + r * a.cos(), c[2] + r * a.sin()]
                })
                .collect(),
        },
    })
}

fn rectangle(x0: f64, x1: f64, z0: f64, z1: f64) -> Vec<[f64; 2]> {
    vec![[x0, z0], [x1, z0], [x1, z1], [x0, z1]]
}

fn validate_part(field: &str, part: &Part) -> Result<(), (String, String)> {
    match part {
        Part::Box { min_m, max_m, .. } => {
            coordinates(&format!("{field}.min_m"), min_m)?;
            coordinates(&format!("{field}.max_m"), max_m)?;
            for k in 0..3 {
                if min_m[k] >= max_m[k] {
                    return fail(
                        &format!("{field}.max_m[{k}]"),
                        "must exceed min_m in every coordinate",
                    );
                }
            }
            if min_m[2] < 0.0 {
                return fail(
                    &format!("{field}.min_m[2]"),
                    "must not be below the ground (z >= 0)",
                );
            }
        }
        Part::Cylinder {
            axis,
            centre_m,
            radius_m,
            length_m,
            ..
        } => {
            coordinates(&format!("{field}.centre_m"), centre_m)?;
            positive(&format!("{field}.radius_m"), *radius_m)?;
            positive(&format!("{field}.length_m"), *length_m)?;
            let half_height = if *axis == Axis::Z {
                length_m / 2.0
            } else {
                *radius_m
            };
            if centre_m[2] - half_height < 0.0 {
                return fail(
                    &format!("{field}.centre_m[2]"),
                    "the cylinder reaches below the ground",
                );
            }
        }
        Part::Mesh {
            file,
            scale,
            offset_m,
            ..
        } => {
            if file.as_os_str().is_empty() {
                return fail(&format!("{field}.file"), "must name a mesh file");
            }
            positive(&format!("{field}.scale"), *scale)?;
            coordinates(&format!("{field}.offset_m"), offset_m)?;
        }
    }
    Ok(())
}

/// Read a mesh file named in vehicle file `path` (field `field`) relative to `dir`, scale and
/// offset it, and check where it lies.
fn load_mesh_file(
    path: &Path,
    dir: Option<&Path>,
    field: &str,
    file: &Path,
    scale: f64,
    offset_m: [f64; 3],
) -> Result<Mesh, VehicleError> {
    let Some(dir) = dir else {
        return Err(VehicleError::Invalid {
            path: path.to_owned(),
            field: field.to_owned(),
            reason: "meshes need the vehicle file's directory: load the vehicle from its file"
                .to_owned(),
        });
    };
    let raw = crate::mesh::load(&dir.join(file)).map_err(|source| VehicleError::Mesh {
        path: path.to_owned(),
        field: field.to_owned(),
        source: Box::new(source),
    })?;
    let placed = raw.transformed(scale, v3(offset_m));
    check_mesh_placement(&placed).map_err(|reason| VehicleError::Invalid {
        path: path.to_owned(),
        field: field.to_owned(),
        reason,
    })?;
    Ok(placed)
}

/// A placed mesh must stay within +-[`MAX_DIMENSION_M`] and above the ground.
fn check_mesh_placement(mesh: &Mesh) -> Result<(), String> {
    let Some(b) = mesh.vertex_bounds() else {
        return Err("the mesh has no vertices".to_owned());
    };
    let coords = [b.min.x, b.min.y, b.min.z, b.max.x, b.max.y, b.max.z];
    if !coords.iter().all(|c| c.abs() <= MAX_DIMENSION_M) {
        return Err(format!(
            "the scaled and offset mesh reaches beyond +-{MAX_DIMENSION_M} m"
        ));
    }
    // Scaling and offsetting round: a mesh resting on the ground may end a nanometre below it.
    if b.min.z < -1e-9 {
        return Err(format!(
            "the scaled and offset mesh reaches below the ground (lowest z = {} m)",
            b.min.z
        ));
    }
    Ok(())
}

fn v3(a: [f64; 3]) -> Vec3 {
    Vec3::new(a[0], a[1], a[2])
}

/// The side-view points of a mesh part that can first touch a ramp line or crest.
///
/// Every vertex, projected to (x, z): a tangent line in the side view first touches a polyhedron
/// at a vertex (the extreme point of a polytope in any direction is a vertex), so vertices suffice
/// for approach and departure. A breakover crest can instead touch the outline on an edge between
/// vertices, so edges are also sampled every `spacing_m`, keeping per x-bin of that width only the
/// lowest sample: a lower point at the same x is below every ramp line and crest the higher one is.
fn mesh_side_view(mesh: &Mesh, spacing_m: f64) -> Vec<[f64; 2]> {
    let mut out: Vec<[f64; 2]> = mesh.vertices().iter().map(|v| [v.x, v.z]).collect();
    out.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    out.dedup();
    let Some(x_min) = out.first().map(|p| p[0]) else {
        return out;
    };
    let x_max = out.last().map_or(x_min, |p| p[0]);
    let vertices = mesh.vertices();
    let edge = |tri: &[u32; 3], k: usize| {
        (
            vertices[tri[k] as usize],
            vertices[tri[(k + 1) % 3] as usize],
        )
    };
    // A huge mesh is sampled more coarsely rather than without bound (only its breakover samples
    // are affected; its vertices stay exact).
    let total_m: f64 = mesh
        .triangles()
        .iter()
        .flat_map(|tri| (0..3).map(move |k| (tri, k)))
        .map(|(tri, k)| {
            let (a, b) = edge(tri, k);
            (b.x - a.x).hypot(b.z - a.z)
        })
        .sum();
    let spacing_m = spacing_m.max(total_m / MAX_MESH_EDGE_SAMPLES);
    let bins = ((x_max - x_min) / spacing_m).ceil() as usize + 1;
    let mut lowest: Vec<Option<[f64; 2]>> = vec![None; bins];
    for tri in mesh.triangles() {
        for k in 0..3 {
            let (a, b) = edge(tri, k);
            let n = (((b.x - a.x).hypot(b.z - a.z) / spacing_m).ceil() as usize).max(1);
            for s in 1..n {
                let t = s as f64 / n as f64;
                let p = [a.x + t * (b.x - a.x), a.z + t * (b.z - a.z)];
                let bin = (((p[0] - x_min) / spacing_m) as usize).min(bins - 1);
                if lowest[bin].is_none_or(|q| p[1] < q[1]) {
                    lowest[bin] = Some(p);
                }
            }
        }
    }
    out.extend(lowest.into_iter().flatten());
    out
}

fn positive(field: &str, v: f64) -> Result<(), (String, String)> {
    if v.is_finite() && v > 0.0 && v <= MAX_DIMENSION_M {
        Ok(())
    } else {
        fail(
            field,
            format!("must be a positive number up to {MAX_DIMENSION_M}, got {v}"),
        )
    }
}

fn non_negative(field: &str, v: f64) -> Result<(), (String, String)> {
    if v.is_finite() && (0.0..=MAX_DIMENSION_M).contains(&v) {
        Ok(())
    } else {
        fail(field, format!("must lie in 0..={MAX_DIMENSION_M}, got {v}"))
    }
}

/// Every coordinate finite and within +-[`MAX_DIMENSION_M`].
fn coordinates(field: &str, values: &[f64]) -> Result<(), (String, String)> {
    if values
        .iter()
        .all(|v| v.is_finite() && v.abs() <= MAX_DIMENSION_M)
    {
        Ok(())
    } else {
        fail(
            field,
            format!("coordinates must be finite numbers within +-{MAX_DIMENSION_M} m"),
        )
    }
}

fn fail<T>(field: &str, reason: impl Into<String>) -> Result<T, (String, String)> {
    Err((field.to_owned(), reason.into()))
}

fn distance2(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// Distance from point `p` to the segment `a`-`b` in the plane.
pub fn segment_point_distance(a: [f64; 2], b: [f64; 2], p: [f64; 2]) -> f64 {
    let (dx, dz) = (b[0] - a[0], b[1] - a[1]);
    let len2 = dx * dx + dz * dz;
    let t = if len2 > 0.0 {
        (((p[0] - a[0]) * dx + (p[1] - a[1]) * dz) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    distance2([a[0] + t * dx, a[1] + t * dz], p)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A small valid vehicle used by tests across the crate.
    pub(crate) const TEST_SEDAN: &str = r#"
name = "test sedan"
wheelbase_m = 2.8
track_m = 1.58
body_width_m = 1.84
body_height_m = 1.45
[tyre]
radius_m = 0.33
width_m = 0.225
rim_radius_m = 0.23
[underside.front]
width_m = 1.7
points = [[0.98, 0.32], [0.80, 0.18], [0.45, 0.15]]
[underside.between]
width_m = 1.5
points = [[-0.45, 0.15], [-1.4, 0.14], [-2.35, 0.15]]
[underside.rear]
width_m = 1.7
points = [[-3.25, 0.18], [-3.85, 0.38]]
[[parts]]
kind = "cylinder"
name = "exhaust"
axis = "x"
centre_m = [-3.4, 0.5, 0.24]
radius_m = 0.04
length_m = 0.4
"#;

    pub(crate) fn test_sedan() -> Vehicle {
        Vehicle::from_toml_str(TEST_SEDAN, Path::new("test.toml")).expect("test vehicle is valid")
    }

    fn err_of(text: &str) -> String {
        Vehicle::from_toml_str(text, Path::new("v.toml"))
            .expect_err("must be rejected")
            .to_string()
    }

    #[test]
    fn test_vehicle_parses() {
        let v = test_sedan();
        assert_eq!(v.parts.len(), 1);
        assert!((v.front_x_m() - 0.98).abs() < 1e-12);
        assert_eq!(v.body_prisms().len(), 5);
    }

    #[test]
    fn unknown_key_is_rejected_with_line() {
        let e = err_of(&TEST_SEDAN.replace("track_m = 1.58", "track_m = 1.58\ncolour = \"red\""));
        assert!(e.contains("v.toml") && e.contains("colour"), "{e}");
        assert!(e.contains("line"), "{e}");
    }

    #[test]
    fn bad_values_name_their_field() {
        let e = err_of(&TEST_SEDAN.replace("rim_radius_m = 0.23", "rim_radius_m = 0.4"));
        assert!(e.contains("tyre.rim_radius_m"), "{e}");
        let e = err_of(&TEST_SEDAN.replace("[-1.4, 0.14]", "[-0.3, 0.14]"));
        assert!(e.contains("underside.between.points[1]"), "{e}");
        let e = err_of(&TEST_SEDAN.replace("[0.45, 0.15]", "[0.25, 0.15]"));
        assert!(
            e.contains("underside.front.points[1..=2]") && e.contains("tyre"),
            "{e}"
        );
        let e = err_of(&TEST_SEDAN.replace("wheelbase_m = 2.8", "wheelbase_m = -2.8"));
        assert!(e.contains("wheelbase_m"), "{e}");
        let e = err_of(&TEST_SEDAN.replace("radius_m = 0.04", "radius_m = 0.3"));
        assert!(e.contains("parts[0].centre_m[2]"), "{e}");
    }

    #[test]
    fn outline_samples_include_vertices_and_respect_spacing() {
        let v = test_sedan();
        let pts = v.outline_points(0.01);
        let verts = v.outline_vertices();
        for q in &verts {
            assert!(
                pts.iter()
                    .any(|p| (p.x_m - q.x_m).abs() < 1e-12 && (p.z_m - q.z_m).abs() < 1e-12)
            );
        }
        assert!(pts.len() > 10 * verts.len());
    }
}
