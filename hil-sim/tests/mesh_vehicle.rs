//! Mesh parts end to end: the shipped mesh vehicle's true angles respond to its mesh parts, a mesh
//! box casts exactly like the analytic box, simulated hits on meshes lie on them, and bad mesh
//! parts are rejected with errors that name the vehicle file, the field and the mesh file.

mod common;

use std::fmt::Write as _;
use std::path::Path;

use common::{temp_dir, vehicles_dir};
use hil_sim::geometry::{Normalized, Vec3};
use hil_sim::truth::{TrueAngles, TruthOptions, closed_form_rad, true_angles};
use hil_sim::vehicle::{Part, Vehicle};
use hil_sim::world::{Candidates, Scene, SurfaceKind};
use rand::{Rng, SeedableRng};

const TOL: f64 = 1e-7;

fn hatchback() -> Vehicle {
    Vehicle::load(&vehicles_dir().join("hatchback_mesh.toml")).expect("shipped vehicle is valid")
}

fn angles(v: &Vehicle) -> TrueAngles {
    true_angles(
        v,
        &TruthOptions {
            spacing_m: 0.005,
            ..TruthOptions::default()
        },
    )
}

fn without(v: &Vehicle, name: &str) -> Vehicle {
    let mut v = v.clone();
    let before = v.parts.len();
    v.parts.retain(|p| p.name() != name);
    assert_eq!(v.parts.len() + 1, before, "{name} is a part");
    v
}

fn witness(a: &hil_sim::truth::TrueAngle) -> &str {
    a.witness.as_ref().map_or("", |w| w.source.as_str())
}

#[test]
fn mesh_parts_limit_the_departure_angle_in_order() {
    let v = hatchback();
    let r = v.tyre.radius_m;
    let full = angles(&v);
    // The spare wheel's rear lower vertex: x = -3.27 - 0.18, z = 0.30, 0.85 m behind the axle.
    assert_eq!(witness(&full.departure), "spare wheel");
    assert!(
        (full.departure.angle_rad - closed_form_rad(0.85, 0.30, r)).abs() < TOL,
        "{}",
        full.departure.angle_rad.to_degrees()
    );
    // Without the spare wheel the silencer limits it: the closed form over its vertices.
    let no_spare = without(&v, "spare wheel");
    let t = angles(&no_spare);
    assert_eq!(witness(&t.departure), "transverse silencer");
    let rear_x = -v.wheelbase_m;
    let silencer_min = no_spare
        .outline_vertices()
        .iter()
        .filter(|p| p.source == "transverse silencer")
        .map(|p| closed_form_rad(rear_x - p.x_m, p.z_m, r))
        .fold(f64::INFINITY, f64::min);
    assert!((t.departure.angle_rad - silencer_min).abs() < TOL);
    assert!(t.departure.angle_rad > full.departure.angle_rad + 0.5f64.to_radians());
    // Without both the body's rear overhang vertex (-3.35, 0.34) limits it.
    let body = angles(&without(&no_spare, "transverse silencer"));
    assert_eq!(witness(&body.departure), "rear overhang");
    assert!((body.departure.angle_rad - closed_form_rad(0.75, 0.34, r)).abs() < TOL);
    assert!(body.departure.angle_rad > t.departure.angle_rad + 0.5f64.to_radians());
    // The meshes sit behind the rear axle: approach and breakover do not change.
    assert_eq!(full.approach, body.approach);
    assert_eq!(full.breakover, body.breakover);
    println!(
        "departure: all parts {:.3} deg, silencer only {:.3} deg, body only {:.3} deg",
        full.departure.angle_rad.to_degrees(),
        t.departure.angle_rad.to_degrees(),
        body.departure.angle_rad.to_degrees()
    );
}

#[test]
fn flexible_mesh_parts_count_only_when_asked() {
    let mut v = hatchback();
    for part in &mut v.parts {
        if let Part::Mesh { name, rigid, .. } = part
            && name == "spare wheel"
        {
            *rigid = false;
        }
    }
    let all = angles(&v);
    let rigid_only = true_angles(
        &v,
        &TruthOptions {
            spacing_m: 0.005,
            include_flexible: false,
            ..TruthOptions::default()
        },
    );
    assert_eq!(witness(&all.departure), "spare wheel");
    assert_eq!(witness(&rigid_only.departure), "transverse silencer");
    assert!(rigid_only.departure.angle_rad > all.departure.angle_rad);
}

#[test]
fn a_mesh_crest_on_an_edge_between_vertices_limits_the_breakover() {
    // A flat-bottomed mesh plate between the axles whose lowest face spans mid-wheelbase with no
    // vertex there: the breakover crest touches the plate's bottom edge between its vertices.
    let dir = temp_dir("plate");
    std::fs::write(
        dir.join("plate.obj"),
        "v -0.6 -0.3 0\nv 0.6 -0.3 0\nv 0.6 0.3 0\nv -0.6 0.3 0\n\
         v -0.6 -0.3 0.02\nv 0.6 -0.3 0.02\nv 0.6 0.3 0.02\nv -0.6 0.3 0.02\n\
         f 1 2 3 4\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n",
    )
    .expect("write plate");
    let text =
        std::fs::read_to_string(vehicles_dir().join("hatchback_mesh.toml")).expect("vehicle text");
    let base = text.split("[[parts]]").next().expect("head");
    let with_plate = format!(
        "{base}[[parts]]\nkind = \"mesh\"\nname = \"plate\"\nfile = \"plate.obj\"\n\
         offset_m = [-1.3, 0.0, 0.13]\n"
    );
    let v =
        Vehicle::from_toml_str_in_dir(&with_plate, Path::new("plate.toml"), &dir).expect("valid");
    let t = true_angles(
        &v,
        &TruthOptions {
            spacing_m: 0.001,
            ..TruthOptions::default()
        },
    );
    let (r, wb) = (v.tyre.radius_m, v.wheelbase_m);
    assert_eq!(witness(&t.breakover), "plate");
    let expected = 2.0 * closed_form_rad(wb / 2.0, 0.13, r);
    assert!(
        (t.breakover.angle_rad - expected).abs() < 1e-5,
        "{} vs {}",
        t.breakover.angle_rad.to_degrees(),
        expected.to_degrees()
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_mesh_box_casts_like_the_analytic_box() {
    let (min, max) = ([-1.6, -0.35, 0.05], [-0.9, 0.45, 0.125]);
    let dir = temp_dir("box");
    let mut obj = String::new();
    for k in 0..8 {
        let c = |axis: usize| {
            if k & (1 << axis) == 0 {
                min[axis]
            } else {
                max[axis]
            }
        };
        writeln!(obj, "v {} {} {}", c(0), c(1), c(2)).expect("write to a String");
    }
    obj.push_str("f 1 3 4 2\nf 5 6 8 7\nf 1 2 6 5\nf 3 7 8 4\nf 1 5 7 3\nf 2 4 8 6\n");
    std::fs::write(dir.join("box.obj"), obj).expect("write box");
    let text =
        std::fs::read_to_string(vehicles_dir().join("hatchback_mesh.toml")).expect("vehicle text");
    let base = text.split("[[parts]]").next().expect("head");
    let analytic = format!(
        "{base}[[parts]]\nkind = \"box\"\nname = \"b\"\nmin_m = {min:?}\nmax_m = {max:?}\n"
    );
    let mesh = format!("{base}[[parts]]\nkind = \"mesh\"\nname = \"b\"\nfile = \"box.obj\"\n");
    let a = Scene::from_vehicle(
        &Vehicle::from_toml_str(&analytic, Path::new("a.toml")).expect("analytic valid"),
    );
    let m = Scene::from_vehicle(
        &Vehicle::from_toml_str_in_dir(&mesh, Path::new("m.toml"), &dir).expect("mesh valid"),
    );
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(30);
    let (mut part_hits, mut worst) = (0usize, 0.0f64);
    for _ in 0..50_000 {
        let o = Vec3::new(
            rng.random_range(-2.6..0.1),
            rng.random_range(-0.8..0.8),
            rng.random_range(0.01..0.15),
        );
        let inside = (0..3).all(|k| {
            let c = [o.x, o.y, o.z][k];
            c >= min[k] && c <= max[k]
        });
        if inside {
            continue;
        }
        let target = Vec3::new(
            rng.random_range(min[0] - 0.1..max[0] + 0.1),
            rng.random_range(min[1] - 0.1..max[1] + 0.1),
            rng.random_range(min[2] - 0.05..max[2] + 0.05),
        );
        let d = (target - o).normalized();
        match (a.cast(o, d, 100.0), m.cast(o, d, 100.0)) {
            (None, None) => {}
            (Some(ha), Some(hm)) => {
                assert_eq!(ha.surface, hm.surface, "ray {o:?} {d:?}");
                let diff = (ha.range_m - hm.range_m).abs();
                assert!(diff < 1e-9, "ray {o:?} {d:?}: {diff}");
                worst = worst.max(diff);
                part_hits += usize::from(ha.surface.kind == SurfaceKind::Part);
            }
            (ha, hm) => panic!("ray {o:?} {d:?}: analytic {ha:?}, mesh {hm:?}"),
        }
    }
    assert!(part_hits > 10_000, "only {part_hits} rays hit the box");
    println!("{part_hits} box hits, largest range difference {worst:e} m");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn hits_on_mesh_parts_lie_on_them_and_wedge_culling_keeps_them() {
    let v = hatchback();
    let s = Scene::from_vehicle(&v);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(31);
    let mut mesh_hits = 0usize;
    for _ in 0..30_000 {
        let o = Vec3::new(
            rng.random_range(-3.4..-2.2),
            rng.random_range(-0.6..0.6),
            rng.random_range(0.02..0.13),
        );
        let heading: f64 = rng.random_range(-3.2..3.2);
        let half: f64 = rng.random_range(0.01..0.2);
        let az = heading + rng.random_range(-half..half);
        let el: f64 = rng.random_range(-0.2..0.6);
        let d = Vec3::new(az.cos() * el.cos(), az.sin() * el.cos(), el.sin());
        let hit = s.cast(o, d, 100.0);
        assert_eq!(
            s.cast_among(o, d, 100.0, s.candidates_in_wedge(o, heading, half)),
            hit
        );
        assert_eq!(s.cast_among(o, d, 100.0, Candidates::ALL), hit);
        if let Some(h) = hit {
            let p = o + d * h.range_m;
            let dist = s.distance_to_surface(h.surface, p);
            assert!(dist < 1e-9, "{:?} at {p:?}: {dist}", h.surface);
            assert!(h.normal.dot(&d) <= 0.0);
            mesh_hits += usize::from(h.surface.kind == SurfaceKind::Part);
        }
    }
    assert!(mesh_hits > 1000, "only {mesh_hits} hits on the mesh parts");
    println!("{mesh_hits} hits on the mesh parts");
}

#[test]
fn bad_mesh_parts_are_rejected_naming_file_field_and_place() {
    let path = vehicles_dir().join("hatchback_mesh.toml");
    let text = std::fs::read_to_string(&path).expect("vehicle text");
    let e = Vehicle::from_toml_str(&text, &path)
        .expect_err("no directory")
        .to_string();
    assert!(
        e.contains("hatchback_mesh.toml") && e.contains("parts[0].file") && e.contains("directory"),
        "{e}"
    );
    let dir = temp_dir("bad");
    let e = Vehicle::from_toml_str_in_dir(&text, Path::new("v.toml"), &dir)
        .expect_err("missing file")
        .to_string();
    assert!(
        e.contains("parts[0].file") && e.contains("silencer.obj"),
        "{e}"
    );
    std::fs::create_dir_all(dir.join("meshes")).expect("mkdir");
    std::fs::write(
        dir.join("meshes/silencer.obj"),
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n",
    )
    .expect("write");
    let e = Vehicle::from_toml_str_in_dir(&text, Path::new("v.toml"), &dir)
        .expect_err("bad index")
        .to_string();
    assert!(
        e.contains("v.toml")
            && e.contains("parts[0].file")
            && e.contains("silencer.obj")
            && e.contains("line 4")
            && e.contains("out of range"),
        "{e}"
    );
    let low = text.replace(
        "offset_m = [-3.10, 0.0, 0.24]",
        "offset_m = [-3.10, 0.0, 0.05]",
    );
    let e = Vehicle::from_toml_str_in_dir(&low, Path::new("v.toml"), &vehicles_dir())
        .expect_err("below ground")
        .to_string();
    assert!(
        e.contains("parts[0].file") && e.contains("below the ground"),
        "{e}"
    );
    let scaled = text.replace("scale = 0.001", "scale = -1.0");
    let e = Vehicle::from_toml_str_in_dir(&scaled, Path::new("v.toml"), &vehicles_dir())
        .expect_err("negative scale")
        .to_string();
    assert!(e.contains("parts[1].scale"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The sedan's body prisms written as one OBJ mesh (each prism a closed extruded polygon: the
/// underside polyline with a top vertex above each of its points, so every cap is a strip of quads).
fn prisms_as_obj(v: &Vehicle) -> String {
    let top = v.body_height_m;
    let mut obj = String::new();
    let mut base = 0;
    for (_, poly, width) in v.body_prisms() {
        let bottom = &poly[..poly.len() - 2];
        let n = bottom.len();
        let hw = width / 2.0;
        // Vertex layout per side y: bottom 0..n, then top n..2n; side -hw first, then +hw.
        for y in [-hw, hw] {
            for &[x, z] in bottom {
                writeln!(obj, "v {x} {y} {z}").expect("write");
            }
            for &[x, _] in bottom {
                writeln!(obj, "v {x} {y} {top}").expect("write");
            }
        }
        let id = |side: usize, k: usize| base + side * 2 * n + k + 1;
        for side in 0..2 {
            for i in 0..n - 1 {
                let (b0, b1, t1, t0) = (i, i + 1, n + i + 1, n + i);
                writeln!(
                    obj,
                    "f {} {} {} {}",
                    id(side, b0),
                    id(side, b1),
                    id(side, t1),
                    id(side, t0)
                )
                .expect("write");
            }
        }
        // The boundary loop: bottom front to rear, rear face, top rear to front, front face.
        let mut ring: Vec<usize> = (0..n).collect();
        ring.extend((n..2 * n).rev());
        for k in 0..ring.len() {
            let (a, b) = (ring[k], ring[(k + 1) % ring.len()]);
            writeln!(obj, "f {} {} {} {}", id(0, a), id(0, b), id(1, b), id(1, a)).expect("write");
        }
        base += 4 * n;
    }
    obj
}

#[test]
fn a_mesh_body_matches_the_prism_body_in_truth_and_casting() {
    let sedan_path = vehicles_dir().join("sedan.toml");
    let prisms = Vehicle::load(&sedan_path).expect("sedan");
    let dir = temp_dir("body");
    std::fs::write(dir.join("body.obj"), prisms_as_obj(&prisms)).expect("write body");
    let text = std::fs::read_to_string(&sedan_path).expect("sedan text");
    let (head, rest) = text.split_once("[underside.front]").expect("underside");
    let (_, parts) = rest.split_once("[[parts]]").expect("parts");
    let mesh_text = format!("{head}[body_mesh]\nfile = \"body.obj\"\n\n[[parts]]{parts}");
    let mesh = Vehicle::from_toml_str_in_dir(&mesh_text, Path::new("m.toml"), &dir)
        .expect("mesh body is valid");
    assert!(mesh.body_prisms().is_empty());
    assert!((mesh.front_x_m() - prisms.front_x_m()).abs() < 1e-12);
    assert!((mesh.rear_x_m() - prisms.rear_x_m()).abs() < 1e-12);
    let (a, b) = (angles(&prisms), angles(&mesh));
    let worst_breakover = (a.breakover.angle_rad - b.breakover.angle_rad).abs();
    println!(
        "prism vs mesh body: approach {:.4} / {:.4}, breakover {:.4} / {:.4}, departure {:.4} / {:.4} deg",
        a.approach.angle_rad.to_degrees(),
        b.approach.angle_rad.to_degrees(),
        a.breakover.angle_rad.to_degrees(),
        b.breakover.angle_rad.to_degrees(),
        a.departure.angle_rad.to_degrees(),
        b.departure.angle_rad.to_degrees()
    );
    assert!((a.approach.angle_rad - b.approach.angle_rad).abs() < TOL);
    assert!((a.departure.angle_rad - b.departure.angle_rad).abs() < TOL);
    // Both sample the breakover crest's edges every 5 mm, at different places.
    assert!(worst_breakover < 1e-4, "{worst_breakover}");
    assert_eq!(witness(&b.approach), "body");

    let (sp, sm) = (Scene::from_vehicle(&prisms), Scene::from_vehicle(&mesh));
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(32);
    let (mut body_hits, mut worst) = (0usize, 0.0f64);
    for _ in 0..30_000 {
        let o = Vec3::new(
            rng.random_range(-4.5..1.5),
            rng.random_range(-0.6..0.6),
            rng.random_range(0.02..0.15),
        );
        let d = Vec3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-0.3..1.0),
        )
        .normalized();
        match (sp.cast(o, d, 100.0), sm.cast(o, d, 100.0)) {
            (None, None) => {}
            (Some(hp), Some(hm)) => {
                assert_eq!(hp.surface.kind, hm.surface.kind, "ray {o:?} {d:?}");
                let diff = (hp.range_m - hm.range_m).abs();
                assert!(diff < 1e-9, "ray {o:?} {d:?}: {diff}");
                worst = worst.max(diff);
                if hm.surface.kind == SurfaceKind::Body {
                    body_hits += 1;
                    let p = o + d * hm.range_m;
                    assert!(sm.distance_to_surface(hm.surface, p) < 1e-9);
                }
            }
            (hp, hm) => panic!("ray {o:?} {d:?}: prisms {hp:?}, mesh {hm:?}"),
        }
    }
    assert!(body_hits > 5000, "only {body_hits} body hits");
    println!("{body_hits} body hits, largest range difference {worst:e} m");

    let both = format!("{text}\n[body_mesh]\nfile = \"body.obj\"\n");
    let e = Vehicle::from_toml_str_in_dir(&both, Path::new("m.toml"), &dir)
        .expect_err("both")
        .to_string();
    assert!(e.contains("body_mesh") && e.contains("not both"), "{e}");
    let neither = mesh_text.replace("[body_mesh]\nfile = \"body.obj\"\n", "");
    let e = Vehicle::from_toml_str_in_dir(&neither, Path::new("m.toml"), &dir)
        .expect_err("neither")
        .to_string();
    assert!(e.contains("underside") && e.contains("body_mesh"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}
