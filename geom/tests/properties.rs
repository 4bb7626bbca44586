//! Property tests of the geometry's invariants over random inputs (proptest, seeded by its own
//! persistence; failures print the minimal case).

use passangle_geom::{M3, Pose, V3, VoxelIndex, symmetric_eigen3, voxel_of};
use proptest::prelude::*;

fn v3(range: f64) -> impl Strategy<Value = V3> {
    [-range..range, -range..range, -range..range].prop_map(V3::from)
}

fn pose() -> impl Strategy<Value = Pose> {
    (v3(20.0), v3(3.0)).prop_map(|(xyz, rpy)| Pose::from_xyz_rpy(xyz, rpy))
}

fn close(a: V3, b: V3, tol: f64) -> bool {
    (a - b).norm() <= tol
}

proptest! {
    #[test]
    fn a_pose_composed_with_its_inverse_is_the_identity(p in pose(), x in v3(50.0)) {
        let back = p.inverse().compose(&p).apply(x);
        prop_assert!(close(back, x, 1e-9), "{back:?} vs {x:?}");
        let forth = p.compose(&p.inverse()).apply(x);
        prop_assert!(close(forth, x, 1e-9), "{forth:?} vs {x:?}");
    }

    #[test]
    fn composing_poses_applies_them_in_turn(a in pose(), b in pose(), x in v3(50.0)) {
        let composed = a.compose(&b).apply(x);
        let in_turn = a.apply(b.apply(x));
        prop_assert!(close(composed, in_turn, 1e-9), "{composed:?} vs {in_turn:?}");
    }

    #[test]
    fn rotations_stay_orthonormal_and_keep_lengths(a in pose(), b in pose(), v in v3(10.0)) {
        let r = a.compose(&b).rotation;
        let rtr = r.transpose() * r;
        for i in 0..3 {
            for j in 0..3 {
                let want = if i == j { 1.0 } else { 0.0 };
                prop_assert!((rtr[(i, j)] - want).abs() < 1e-12, "R^T R = {rtr:?}");
            }
        }
        prop_assert!(((r * v).norm() - v.norm()).abs() < 1e-9);
    }

    #[test]
    fn an_increment_survives_the_round_trip_through_a_pose(
        r in v3(3.0).prop_filter("rotation below pi", |r| r.norm() < 3.1),
        t in v3(5.0),
    ) {
        let d = [r[0], r[1], r[2], t[0], t[1], t[2]];
        let back = Pose::from_increment(d).to_increment();
        for k in 0..6 {
            prop_assert!((back[k] - d[k]).abs() < 1e-8, "{d:?} -> {back:?}");
        }
    }

    #[test]
    fn the_closed_form_eigen_solver_reconstructs_its_matrix(
        diag in v3(5.0),
        off in v3(5.0),
    ) {
        let m = M3::new(
            diag[0], off[0], off[1],
            off[0], diag[1], off[2],
            off[1], off[2], diag[2],
        );
        let (values, vectors) = symmetric_eigen3(&m).expect("finite input");
        // Eigenvectors are the columns: m v = lambda v for each, and they are orthonormal.
        let scale = m.iter().fold(1.0_f64, |a, &v| a.max(v.abs()));
        for k in 0..3 {
            let v: V3 = vectors.column(k).into_owned();
            prop_assert!((v.norm() - 1.0).abs() < 1e-9, "|v{k}| = {}", v.norm());
            let mv = m * v;
            let lv = v.map(|c| c * values[k]);
            prop_assert!(close(mv, lv, 1e-7 * scale), "m v != lambda v for {m:?}: {values:?}");
        }
        let trace = diag[0] + diag[1] + diag[2];
        prop_assert!((values.iter().sum::<f64>() - trace).abs() < 1e-9 * scale);
    }

    #[test]
    fn a_point_lies_in_the_voxel_it_is_given(p in v3(1000.0), size in 0.001..2.0_f64) {
        let v = voxel_of(p, size);
        for k in 0..3 {
            let lo = f64::from(v[k]) * size;
            prop_assert!(lo <= p[k] + 1e-9 * p[k].abs().max(1.0), "{p:?} {size} {v:?}");
            prop_assert!(p[k] < lo + size + 1e-9 * p[k].abs().max(1.0), "{p:?} {size} {v:?}");
        }
    }

    #[test]
    fn voxel_index_queries_equal_a_brute_force_scan(
        points in prop::collection::vec(v3(1.0), 1..300),
        q in v3(1.2),
        voxel_m in 0.05..0.8_f64,
        radius_m in 0.0..1.5_f64,
    ) {
        let index = VoxelIndex::new(points.clone(), voxel_m);
        let mut got = [(0.0, 0u32); 8];
        let n = index.nearest(q, radius_m, &mut got);
        let mut want: Vec<(f64, u32)> = points
            .iter()
            .enumerate()
            .map(|(i, &p)| ((p - q).norm_squared(), i as u32))
            .filter(|&(d2, _)| d2 <= radius_m * radius_m)
            .collect();
        want.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        want.truncate(8);
        prop_assert_eq!(&got[..n], &want[..]);
    }
}
