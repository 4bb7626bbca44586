//! Property tests of the vehicle format: arbitrary text never panics the parser, arbitrary numbers
//! never panic validation, and every vehicle that validates can be ray cast and measured without
//! panicking, with angles inside their physical ranges.

use std::path::Path;

use hil_sim::geometry::{Normalized, Vec3};
use hil_sim::truth::{TruthOptions, true_angles};
use hil_sim::vehicle::{Axis, Part, Section, Tyre, Underside, Vehicle};
use hil_sim::world::Scene;
use proptest::prelude::*;

/// A number that is usually plausible for `lo..hi` and sometimes garbage.
fn num(lo: f64, hi: f64) -> impl Strategy<Value = f64> {
    prop_oneof![60 => lo..hi, 1 => any::<f64>(), 1 => Just(f64::NAN)]
}

/// Polyline points as (fraction along the section, height); placed by [`place`].
fn section() -> impl Strategy<Value = (f64, Vec<(f64, f64)>)> {
    (
        num(0.5, 1.5),
        prop::collection::vec((num(0.0, 1.0), num(0.15, 0.8)), 1..6),
    )
}

/// Put fractional points between `x_hi` and `x_lo`, front to rear.
fn place((width_m, pts): (f64, Vec<(f64, f64)>), x_hi: f64, x_lo: f64) -> Section {
    let mut points: Vec<[f64; 2]> = pts
        .into_iter()
        .map(|(u, z)| [x_hi + u * (x_lo - x_hi), z])
        .collect();
    points.sort_by(|a, b| b[0].total_cmp(&a[0]));
    Section { width_m, points }
}

fn part() -> impl Strategy<Value = Part> {
    prop_oneof![
        (
            num(-6.0, 2.0),
            num(-1.0, 1.0),
            num(0.0, 0.6),
            num(0.01, 1.0)
        )
            .prop_map(|(x, y, z, s)| Part::Box {
                name: "box".into(),
                min_m: [x, y, z],
                max_m: [x + s, y + s, z + s],
                rigid: true,
            }),
        (
            num(-6.0, 2.0),
            num(-1.0, 1.0),
            num(0.35, 0.8),
            num(0.01, 0.3),
            num(0.01, 0.6),
            0..3u8
        )
            .prop_map(|(x, y, z, r, l, a)| Part::Cylinder {
                name: "cyl".into(),
                axis: [Axis::X, Axis::Y, Axis::Z][usize::from(a)],
                centre_m: [x, y, z],
                radius_m: r,
                length_m: l,
                rigid: false,
            }),
    ]
}

fn vehicle() -> impl Strategy<Value = Vehicle> {
    (
        (
            num(2.0, 4.0),
            num(1.2, 2.0),
            num(1.5, 2.3),
            num(1.3, 2.5),
            num(0.0, 0.1),
        ),
        (num(0.3, 0.5), num(0.15, 0.35), num(0.15, 0.28)),
        (section(), section(), section()),
        prop::collection::vec(part(), 0..4),
    )
        .prop_map(
            |((wb, track, width, height, arch), (r, tw, rim), (front, between, rear), parts)| {
                Vehicle {
                    name: "random".into(),
                    wheelbase_m: wb,
                    track_m: track,
                    body_width_m: width,
                    body_height_m: height,
                    arch_clearance_m: arch,
                    tyre: Tyre {
                        radius_m: r,
                        width_m: tw,
                        rim_radius_m: rim,
                        tread_radius_m: None,
                        sidewall_bulge_m: 0.0,
                    },
                    underside: Some(Underside {
                        front: place(front, 1.6, 0.6),
                        between: place(between, -0.6, -wb + 0.6),
                        rear: place(rear, -wb - 0.6, -wb - 2.0),
                    }),
                    body_mesh: None,
                    parts,
                    published: None,
                }
            },
        )
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, max_global_rejects: 4096, ..ProptestConfig::default() })]

    #[test]
    fn arbitrary_text_never_panics_the_parser(text in "\\PC{0,400}") {
        let _ = Vehicle::from_toml_str(&text, Path::new("random.toml"));
    }

    #[test]
    fn valid_vehicles_can_be_cast_and_measured(v in vehicle()) {
        prop_assume!(v.validate().is_ok());
        let t = true_angles(&v, &TruthOptions { spacing_m: 0.05, ..TruthOptions::default() });
        for a in [t.approach.angle_rad, t.departure.angle_rad] {
            prop_assert!((0.0..=std::f64::consts::FRAC_PI_2).contains(&a), "{a}");
        }
        prop_assert!((0.0..=std::f64::consts::PI).contains(&t.breakover.angle_rad));
        let scene = Scene::from_vehicle(&v);
        for k in 0..64 {
            let a = f64::from(k) * 0.7;
            let d = Vec3::new(a.cos() * 0.8, a.sin() * 0.5, (a * 1.3).sin()).normalized();
            let o = Vec3::new(-v.wheelbase_m / 2.0, 0.0, 0.05);
            if let Some(hit) = scene.cast(o, d, 100.0) {
                prop_assert!(hit.range_m > 0.0 && hit.range_m < 100.0);
                prop_assert!(scene.distance_to_surface(hit.surface, o + d * hit.range_m) < 1e-6);
            }
        }
    }
}
