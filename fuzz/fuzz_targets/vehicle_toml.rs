//! Fuzz the simulator's vehicle format: any bytes must either be rejected with an error or give a
//! vehicle that can be measured (true angles) and ray cast without panicking.
#![no_main]

use std::path::Path;

use hil_sim::geometry::{Normalized, Vec3};
use hil_sim::truth::{TruthOptions, true_angles};
use hil_sim::vehicle::Vehicle;
use hil_sim::world::Scene;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(vehicle) = Vehicle::from_toml_str(text, Path::new("fuzz.toml")) else {
        return;
    };
    let _ = true_angles(
        &vehicle,
        &TruthOptions {
            spacing_m: 0.05,
            ..TruthOptions::default()
        },
    );
    let scene = Scene::from_vehicle(&vehicle);
    for k in 0..32 {
        let a = f64::from(k) * 0.9;
        let dir = Vec3::new(a.cos(), a.sin() * 0.4, (a * 1.7).sin()).normalized();
        let _ = scene.cast(Vec3::new(-vehicle.wheelbase_m / 2.0, 0.0, 0.1), dir, 100.0);
    }
});
