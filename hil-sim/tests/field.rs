//! The field-realistic simulator: the mesh fleet with loaded tyres, halls, and the protocol's
//! template scenario. Sensor-effect tests live beside their models (`vlp16.rs`, `d435.rs`,
//! `wheel_odometry.rs`).

mod common;

use std::path::Path;

use common::{crate_dir, shipped_vehicle, temp_dir};
use hil_sim::geometry::Vec3;
use hil_sim::scenario::Scenario;
use hil_sim::trajectory::Trajectory;
use hil_sim::truth::{TruthOptions, true_angles};
use hil_sim::world::{Scene, SurfaceKind};

const FLEET: [&str; 8] = [
    "city_car",
    "sports_car",
    "pickup_bof",
    "suv_unibody",
    "long_van",
    "offroader_skid",
    "minibus",
    "estate_towbar",
];

/// The closed form of the tangent angle to a point at distance d ahead of the tyre, height z.
fn closed_form(d: f64, z: f64, r: f64) -> f64 {
    (r / d.hypot(r - z)).asin() - (r - z).atan2(d)
}

#[test]
fn the_sports_cars_approach_is_the_hand_computed_angle_to_its_splitter() {
    // By hand: the splitter's front lower edge is at x = 1.10 m, z = 0.172 m; the static loaded
    // radius is 0.322 m. hypot(1.10, 0.150) = 1.110180, asin(0.322 / 1.110180) = 16.8597 deg,
    // atan2(0.150, 1.10) = 7.7652 deg: approach = 9.0946 deg.
    let v = shipped_vehicle("sports_car");
    let t = true_angles(&v, &TruthOptions::default());
    let w = t.approach.witness.as_ref().expect("a witness");
    assert_eq!(w.source, "front splitter");
    assert!(
        (w.x_m - 1.10).abs() < 1e-9 && (w.z_m - 0.172).abs() < 1e-9,
        "{w:?}"
    );
    assert!(
        (t.approach.angle_rad.to_degrees() - 9.0946).abs() < 1e-3,
        "{}",
        t.approach.angle_rad.to_degrees()
    );
    assert!((t.approach.angle_rad - closed_form(1.10, 0.172, 0.322)).abs() < 1e-7);
}

#[test]
fn every_fleet_vehicle_loads_has_its_truth_and_small_meshes() {
    for name in FLEET {
        let v = shipped_vehicle(name);
        assert!(v.tyre.is_loaded(), "{name}: loaded tyres");
        assert!(v.tyre.tread_radius() > v.tyre.radius_m, "{name}");
        let t = true_angles(&v, &TruthOptions::default());
        for (angle, what) in [
            (&t.approach, "approach"),
            (&t.breakover, "breakover"),
            (&t.departure, "departure"),
        ] {
            let deg = angle.angle_rad.to_degrees();
            assert!((5.0..50.0).contains(&deg), "{name} {what}: {deg}");
            let w = angle.witness.as_ref().expect("witness");
            // The truth's stepping search agrees with the closed form at its own witness.
            if what != "breakover" {
                let d = if what == "approach" {
                    w.x_m
                } else {
                    -v.wheelbase_m - w.x_m
                };
                let r = v.tyre.radius_m;
                assert!(
                    (angle.angle_rad - closed_form(d, w.z_m, r)).abs() < 1e-7,
                    "{name} {what}"
                );
            }
        }
        let dir = crate_dir().join("vehicles/meshes/fleet").join(name);
        for f in std::fs::read_dir(&dir).expect("mesh directory") {
            let len = f.expect("entry").metadata().expect("metadata").len();
            assert!(len < 300_000, "{name}: a mesh of {len} bytes");
        }
    }
}

#[test]
fn a_loaded_tyre_is_flat_on_the_ground_and_wider_than_its_loaded_radius() {
    let v = shipped_vehicle("offroader_skid");
    let s = Scene::from_vehicle(&v);
    let (r, big_r) = (v.tyre.radius_m, v.tyre.tread_radius());
    let [_, y, _] = v.tyre_centres()[0];
    // Ahead of the front tyre at its centre's height, a ray toward it meets the tread at the free
    // radius, not at the static loaded radius.
    let hit = s
        .cast(Vec3::new(1.5, y, r), Vec3::new(-1.0, 0.0, 0.0), 10.0)
        .expect("tread");
    assert_eq!(hit.surface.kind, SurfaceKind::Tyre);
    assert!(
        (1.5 - hit.range_m - big_r).abs() < 2e-3,
        "tread at x = {}, free radius {big_r}",
        1.5 - hit.range_m
    );
    // The contact patch: the mesh's lowest vertices lie on the ground, from -sqrt(R^2 - r^2) to
    // +sqrt(R^2 - r^2) around the axle, and none below it.
    let [x0, y0, z0] = v.tyre_centres()[0];
    let mesh = hil_sim::world::loaded_tyre_mesh(&v.tyre, Vec3::new(x0, y0, z0));
    let lowest = mesh.vertices().iter().fold(f64::MAX, |m, p| m.min(p.z));
    assert!(lowest.abs() < 1e-12, "{lowest}");
    let patch: Vec<f64> = mesh
        .vertices()
        .iter()
        .filter(|p| p.z.abs() < 1e-9)
        .map(|p| p.x)
        .collect();
    let half = (big_r * big_r - r * r).sqrt();
    let (lo, hi) = patch
        .iter()
        .fold((f64::MAX, f64::MIN), |(l, h), x| (l.min(*x), h.max(*x)));
    assert!(
        (hi - half).abs() < 1e-9 && (lo + half).abs() < 1e-9,
        "{lo} {hi} {half}"
    );
    // From the vehicle's centre line toward the tyre at 5 cm height: the sidewall bulges inward
    // (toward the ray) beyond the tread's edge plane.
    let inner_plane = y - v.tyre.width_m / 2.0;
    let side = s
        .cast(Vec3::new(0.0, 0.0, 0.06), Vec3::new(0.0, 1.0, 0.0), 3.0)
        .expect("sidewall");
    assert_eq!(side.surface.kind, SurfaceKind::Tyre);
    assert!(
        side.range_m < inner_plane - 0.005,
        "sidewall at y = {} vs plane {inner_plane}",
        side.range_m
    );
    // Toward the front of the tyre (cos 0.3 from straight down, radial 0.3 m) the bulge has
    // faded to a fraction of a millimetre: the sidewall is in its plane.
    let top = s
        .cast(
            Vec3::new(0.3 * 0.954, 0.0, r - 0.3 * 0.3),
            Vec3::new(0.0, 1.0, 0.0),
            3.0,
        )
        .expect("sidewall");
    assert_eq!(top.surface.kind, SurfaceKind::Tyre);
    assert!((top.range_m - inner_plane).abs() < 2e-3, "{top:?}");
}

fn field_scenario(vehicle: &str, world: Option<&str>, seed: u64) -> Scenario {
    let template_path = crate_dir().join("scenarios/field/city-car-hall-a.toml");
    let template = Scenario::load(&template_path).expect("template");
    let v = shipped_vehicle(vehicle);
    let mut file = template.file.clone();
    file.vehicle = crate_dir().join("vehicles").join(format!("{vehicle}.toml"));
    file.world = world.map(|w| {
        crate_dir()
            .join("scenarios/worlds")
            .join(format!("{w}.toml"))
    });
    file.seed = seed;
    file.robot.start_x_m = v.front_x_m() + 1.0;
    file.robot.distance_m = v.front_x_m() - v.rear_x_m() + 2.0;
    Scenario::from_parts(&template_path, file, v).expect("valid scenario")
}

#[test]
fn every_fleet_vehicle_in_every_hall_is_a_valid_pass_for_the_robot() {
    // The placement (yaw up to 3 degrees, 10 cm off the path) never puts a part lower than the
    // robot over its path, for every vehicle, hall and the protocol's seeds.
    for name in FLEET {
        for world in [None, Some("hall-a"), Some("hall-b"), Some("hall-c")] {
            for seed in [1, 2, 101, 102] {
                let s = field_scenario(name, world, seed);
                assert_eq!(s.hall.is_some(), world.is_some());
            }
        }
    }
}

#[test]
fn the_hall_surrounds_the_vehicle_with_walls_pillars_a_second_vehicle_and_a_floor() {
    let s = field_scenario("city_car", Some("hall-a"), 1);
    let scene = s.scene();
    let hall = s.hall.as_deref().expect("a hall");
    let centre = Vec3::new(-s.vehicle.wheelbase_m / 2.0, 0.0, 0.6);
    // Rays along the hall's axes from above the vehicle's centre reach walls 6-10 m away
    // (hall A: 7, 8, 6 and 9 m, each within 0.5 m), leaning by at most the 0.5 degree tilt.
    let mut kinds = std::collections::HashSet::new();
    for (dir, nominal) in [
        (Vec3::new(1.0, 0.0, 0.0), 7.0),
        (Vec3::new(-1.0, 0.0, 0.0), 8.0),
        (Vec3::new(0.0, 1.0, 0.0), 6.0),
        (Vec3::new(0.0, -1.0, 0.0), 9.0),
    ] {
        let start = centre + Vec3::new(0.0, 0.0, 1.5);
        let hit = scene.cast(start, dir, 50.0).expect("a wall");
        kinds.insert(hit.surface.kind);
        assert!(
            (hit.range_m - nominal).abs() <= 0.5 + 0.1,
            "{dir:?}: {} m ({:?})",
            hit.range_m,
            hit.surface
        );
    }
    assert!(kinds.contains(&SurfaceKind::Structure), "{kinds:?}");
    // Sweep a horizontal fan at 0.5 m height: it meets pillars (left row) and the other vehicle
    // (right), and every hit lies on the surface it reports.
    let (mut pillars, mut other) = (0, 0);
    for k in 0..3600 {
        let a = f64::from(k) * std::f64::consts::TAU / 3600.0;
        let o = Vec3::new(2.0, 0.0, 0.5);
        let d = Vec3::new(a.cos(), a.sin(), 0.0);
        if let Some(h) = scene.cast(o, d, 50.0) {
            let p = o + d * h.range_m;
            assert!(
                scene.distance_to_surface(h.surface, p) < 1e-6,
                "{:?} at {p:?}",
                h.surface
            );
            match h.surface.kind {
                SurfaceKind::Structure if h.surface.index >= 10 => pillars += 1,
                SurfaceKind::OtherVehicle => other += 1,
                _ => {}
            }
        }
    }
    assert!(pillars > 20, "pillar hits {pillars}");
    assert!(other > 100, "other vehicle hits {other}");
    // The floor is 0 at the tyre contacts (the vehicle stands on it) and undulates by
    // millimetres elsewhere; the robot rides on it.
    for [x, y, _] in s.vehicle.tyre_centres() {
        assert!(hall.floor.height(x, y).abs() < 1e-12);
    }
    let heights: Vec<f64> = (0..200)
        .map(|k| hall.floor.height(2.0 - 0.05 * f64::from(k), 0.3))
        .collect();
    let span = heights.iter().fold(f64::MIN, |m, h| m.max(*h))
        - heights.iter().fold(f64::MAX, |m, h| m.min(*h));
    assert!(span > 0.001 && span <= 0.006, "floor span {span}");
    // The analytic slope matches central differences.
    for (x, y) in [(0.7, 0.2), (-1.3, -0.4), (3.0, 1.0)] {
        let (gx, gy) = hall.floor.gradient(x, y);
        let h = 1e-5;
        let fx = (hall.floor.height(x + h, y) - hall.floor.height(x - h, y)) / (2.0 * h);
        let fy = (hall.floor.height(x, y + h) - hall.floor.height(x, y - h)) / (2.0 * h);
        assert!(
            (gx - fx).abs() < 1e-8 && (gy - fy).abs() < 1e-8,
            "{gx} {fx} {gy} {fy}"
        );
    }
    let pose = s.motion().pose_at(5.0);
    let flat = s.run.pose_at(5.0);
    assert!((pose.position_m.z - flat.position_m.z).abs() > 1e-5);
    assert!((pose.position_m.z - flat.position_m.z).abs() < 0.006);
    // Straight down from the robot's lidar the ray meets the floor, at the floor's height.
    let o = pose.position_m + Vec3::new(0.0, 0.0, 0.12);
    let down = scene
        .cast(o, Vec3::new(0.0, 0.0, -1.0), 1.0)
        .expect("floor");
    assert_eq!(down.surface.kind, SurfaceKind::Ground);
    let z = o.z - down.range_m;
    assert!((z - hall.floor.height(o.x, o.y)).abs() < 1e-9);
}

#[test]
fn seeds_move_the_hall_and_the_placement_and_repeat_exactly() {
    let a = field_scenario("suv_unibody", Some("hall-b"), 1);
    let b = field_scenario("suv_unibody", Some("hall-b"), 2);
    let a2 = field_scenario("suv_unibody", Some("hall-b"), 1);
    let (ha, hb) = (a.hall.as_deref().unwrap(), b.hall.as_deref().unwrap());
    assert_ne!(ha.pillar_positions(), hb.pillar_positions());
    assert_ne!(ha.other_vehicle_poses(), hb.other_vehicle_poses());
    assert_ne!(a.run.start_m, b.run.start_m);
    assert_eq!(a.run, a2.run);
    assert_eq!(
        ha.pillar_positions(),
        a2.hall.as_deref().unwrap().pillar_positions()
    );
    // The placement stays within its bounds: heading within 3 degrees of 180, and the path
    // within 10 cm (plus the yaw's lever) of the centre line at the vehicle's centre.
    for seed in 1..=30 {
        let s = field_scenario("suv_unibody", None, seed);
        let yaw = (s.run.heading_rad - std::f64::consts::PI).to_degrees();
        assert!(yaw.abs() <= 3.0 + 1e-9, "{yaw}");
        let p = s.run.pose_at(0.0).position_m;
        let centre_x = -s.vehicle.wheelbase_m / 2.0;
        let y_at_centre = p.y + (centre_x - p.x) * s.run.heading_rad.tan();
        assert!(y_at_centre.abs() <= 0.1 + 1e-9, "{y_at_centre}");
    }
}

#[test]
fn the_field_scenarios_packets_repeat_bit_for_bit() {
    let s = field_scenario("estate_towbar", Some("hall-c"), 7);
    let scene = s.scene();
    let motion = s.motion();
    let sim = hil_sim::vlp16::Vlp16Sim::new(&scene, &motion, s.lidar_config(), s.lidar_seed());
    let again = hil_sim::vlp16::Vlp16Sim::new(&scene, &motion, s.lidar_config(), s.lidar_seed());
    for k in [0, 500, 3000] {
        assert_eq!(
            sim.data_packet(k).to_bytes(),
            again.data_packet(k).to_bytes()
        );
    }
}

#[test]
fn world_files_are_validated_with_the_field_named() {
    let dir = temp_dir("world");
    let world = dir.join("bad.toml");
    std::fs::write(&world, "walls_m = [1.0, 8.0, 6.0, 9.0]\n").expect("write");
    let template_path = crate_dir().join("scenarios/field/city-car-hall-a.toml");
    let template = Scenario::load(&template_path).expect("template");
    let mut file = template.file.clone();
    file.vehicle = crate_dir().join("vehicles/city_car.toml");
    file.world = Some(world);
    let e = Scenario::from_parts(&template_path, file, shipped_vehicle("city_car"))
        .expect_err("a wall 1 m away")
        .to_string();
    assert!(e.contains("hall.walls_m"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
    assert!(Path::new(&crate_dir().join("evaluation.toml")).exists());
}
