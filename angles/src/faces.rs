//! The lowest edges of faces across the path, as envelope samples.
//!
//! The envelope's modes leave out the points of faces across the path in the overhangs
//! ([`super::envelope::across_path`]): smeared along the rays, a part's end cap lifts the lowest
//! modes of its last bins. But a face across the path can be the part itself: a mud flap, a
//! towing eye's plate, a bumper's rear face hanging below the body. Left out, its lowest edge is
//! lost, and the witness moves to whatever lies behind it (on the simulated city car, its rear
//! bumper 8 cm further back and 8 cm higher than the flaps' edge: departure 3 degrees too large).
//!
//! Each face gives one sample at its lowest edge instead:
//! 1. **Faces**: the marked points, grouped into connected sets of [`CELL_M`] cells (26
//!    neighbours). A set with fewer than [`MIN_FACE_POINTS`] points gives nothing.
//! 2. **Lowest edge** by counting, as [`super::edge`] counts along x: the face's points are sorted
//!    by height; `z0` is the height of its `min_support`-th lowest point (a lone low return does
//!    not place it); the reference stretch starts `3 sigma` above `z0` (past the edge's blur) and
//!    is [`REFERENCE_M`] tall, doubled up to [`MAX_REFERENCE_M`] while it holds fewer than
//!    [`MIN_FACE_POINTS`] points; `rho` is its density per metre of height. With `N` the points
//!    below the stretch, the edge lies at `z_ref - N / rho`. Noise moves as many points down
//!    across the edge as up, so the count does not depend on the blur, where the lowest mode of
//!    a face would sit `w` above its edge (the mode's window holds the face above it). A face
//!    seen by rays that are nearly horizontal (a low sensor) has little noise in height, so the
//!    edge is sharp; the count needs no estimate of it.
//! 3. **Position**: the median x and mean y of the points between the edge and `z_ref`.
//! 4. **A free edge only**: the sample is kept unless the envelope continues inboard of it at
//!    its height: a sample of the modes within `3 sigma` above the edge or below it, between
//!    `3 sigma` plus a bin and that plus [`INBOARD_M`] inboard (towards the axles) of the face.
//!    An end cap's lowest edge is the end of a part's underside, which the modes already hold,
//!    and there the face's points mix with the underside's denser layer, which the count takes
//!    for the face's (on the simulated pickup's frame rails: edges 1 cm low and 2 cm outward). A
//!    flap's lowest edge is free: inboard of it lies the tyre, or nothing at its height. (The
//!    flap's own unmarked points form modes within its smear, `w` above its edge.)
//!
//! A face gives nothing when the count reaches more than `3 sigma` below its lowest points (it
//! counted more than a uniformly covered face holds: a face that widens towards its bottom,
//! whose density the stretch above understates). A face that narrows towards its bottom (a round
//! end cap) gets an edge above its lowest point: its sample lies above the surface, and the
//! envelope's own samples of the part keep the witness.

use passangle_geom::{VoxelMap, voxel_of};

use super::envelope::EnvelopeSample;
use super::geom::{V3, median};

/// Cell edge for grouping marked points into faces (metres): two marked points belong to one
/// face when their cells touch, so gaps of up to two cells (the point spacing of a face seen from
/// 2-3 m) do not split a face.
const CELL_M: f64 = 0.02;
/// Fewest points of a face, and of its reference stretch (as [`super::edge`]'s reference).
const MIN_FACE_POINTS: usize = super::edge::MIN_REFERENCE_POINTS;
/// Height of the reference stretch above a face's edge (metres), before it is extended.
const REFERENCE_M: f64 = 0.02;
/// Tallest reference stretch (metres): [`super::envelope`]'s marked points reach 8 cm above the
/// lowest point of their column.
const MAX_REFERENCE_M: f64 = 0.06;
/// Length of the stretch inboard of a face where an underside at its edge's height makes the
/// edge an end cap's (metres): the reference stretch of [`super::edge`].
const INBOARD_M: f64 = 0.03;

/// One sample per face across the path at its free lowest edge: `points` are the band's points,
/// `marked` which of them [`super::envelope::across_path`] marked, `envelope` the samples of the
/// modes, `inner_x_m` the axles' x (rear, front), `noise_m`, `bin_m` and `min_support` the
/// envelope's.
pub(crate) fn face_bottoms(
    points: &[V3],
    marked: &[bool],
    envelope: &[EnvelopeSample],
    inner_x_m: (f64, f64),
    noise_m: f64,
    bin_m: f64,
    min_support: usize,
) -> Vec<EnvelopeSample> {
    let face_points: Vec<V3> = points
        .iter()
        .zip(marked)
        .filter(|&(_, &m)| m)
        .map(|(p, _)| *p)
        .collect();
    let reach_m = 3.0 * noise_m + bin_m;
    let continues_inboard = |s: &EnvelopeSample| {
        let inboard = if s.x_m > inner_x_m.1 { -1.0 } else { 1.0 };
        envelope.iter().any(|e| {
            let u = (e.x_m - s.x_m) * inboard;
            u >= reach_m && u <= reach_m + INBOARD_M && e.z_m <= s.z_m + 3.0 * noise_m
        })
    };
    faces(&face_points)
        .into_iter()
        .filter_map(|mut face| lowest_edge(&mut face, noise_m, min_support))
        .filter(|s| !continues_inboard(s))
        .collect()
}

/// `points` grouped into connected sets of [`CELL_M`] cells; sets with fewer than
/// [`MIN_FACE_POINTS`] points are dropped.
fn faces(points: &[V3]) -> Vec<Vec<V3>> {
    let mut cell_ids: VoxelMap<usize> = VoxelMap::default();
    let mut cells: Vec<[i32; 3]> = Vec::new();
    let cell_of_point: Vec<usize> = points
        .iter()
        .map(|&p| {
            let key = voxel_of(p, CELL_M);
            *cell_ids.entry(key).or_insert_with(|| {
                cells.push(key);
                cells.len() - 1
            })
        })
        .collect();
    let mut parent: Vec<usize> = (0..cells.len()).collect();
    for (id, key) in cells.iter().enumerate() {
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let neighbour = [
                        key[0].wrapping_add(dx),
                        key[1].wrapping_add(dy),
                        key[2].wrapping_add(dz),
                    ];
                    if let Some(&other) = cell_ids.get(&neighbour) {
                        union(&mut parent, id, other);
                    }
                }
            }
        }
    }
    // Indexed by each set's root cell: the sets come out in the order of their first points.
    let mut sets: Vec<Vec<V3>> = vec![Vec::new(); cells.len()];
    for (p, &cell) in points.iter().zip(&cell_of_point) {
        let root = find(&mut parent, cell);
        sets[root].push(*p);
    }
    sets.into_iter()
        .filter(|s| s.len() >= MIN_FACE_POINTS)
        .collect()
}

fn find(parent: &mut [usize], mut i: usize) -> usize {
    while parent[i] != i {
        parent[i] = parent[parent[i]];
        i = parent[i];
    }
    i
}

fn union(parent: &mut [usize], a: usize, b: usize) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    if ra != rb {
        parent[ra.max(rb)] = ra.min(rb);
    }
}

/// The face's lowest edge by counting (the module's step 2), `None` where the count does not
/// hold.
fn lowest_edge(face: &mut [V3], noise_m: f64, min_support: usize) -> Option<EnvelopeSample> {
    face.sort_by(|a, b| a[2].total_cmp(&b[2]));
    let z0 = face.get(min_support.max(1) - 1)?[2];
    let z_ref = z0 + 3.0 * noise_m;
    let below = face.partition_point(|p| p[2] < z_ref);
    let mut length_m = REFERENCE_M;
    let inside = loop {
        let n = face.partition_point(|p| p[2] < z_ref + length_m) - below;
        if n >= MIN_FACE_POINTS {
            break n;
        }
        if length_m >= MAX_REFERENCE_M {
            return None;
        }
        length_m = (2.0 * length_m).min(MAX_REFERENCE_M);
    };
    let rho = inside as f64 / length_m;
    let z_edge = z_ref - below as f64 / rho;
    if z_edge < face[0][2] - 3.0 * noise_m {
        return None;
    }
    let lo = face.partition_point(|p| p[2] < z_edge);
    let band = &face[lo..below.max(lo + 1).min(face.len())];
    let mut xs: Vec<f64> = band.iter().map(|p| p[0]).collect();
    let x_m = median(&mut xs)?;
    let y_m = band.iter().map(|p| p[1]).sum::<f64>() / band.len() as f64;
    Some(EnvelopeSample {
        x_m,
        z_m: z_edge,
        y_m,
        support: below,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A plate across the path at `x`, from `z_bottom` up 8 cm, 20 cm wide, sampled every
    /// `step` with heights offset by `phase`.
    fn plate(x: f64, z_bottom: f64, step: f64, phase: f64) -> Vec<V3> {
        let mut out = Vec::new();
        let mut z = z_bottom + phase;
        while z < z_bottom + 0.08 {
            let mut y = -0.1;
            while y < 0.1 {
                out.push(V3::new(x, y, z));
                y += step;
            }
            z += step;
        }
        out
    }

    fn jitter(points: &mut [V3], sigma: f64, seed: u64) {
        // A small deterministic generator: the crate takes no random-number dependency.
        let mut s = seed;
        let mut next = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        for p in points {
            // Sum of uniforms: close enough to normal for a blurred edge.
            let n: f64 = (0..12).map(|_| next()).sum::<f64>() - 6.0;
            p[0] += sigma * n;
            let m: f64 = (0..12).map(|_| next()).sum::<f64>() - 6.0;
            p[2] += 0.2 * sigma * m;
        }
    }

    #[test]
    fn a_plates_lowest_edge_is_found_to_a_millimetre_with_noise() {
        let mut points = plate(-2.735, 0.170, 0.004, 0.001);
        jitter(&mut points, 0.01, 7);
        let marked = vec![true; points.len()];
        let samples = face_bottoms(&points, &marked, &[], (-1.2, 1.2), 0.01, 0.005, 5);
        assert_eq!(samples.len(), 1, "{samples:?}");
        let s = samples[0];
        assert!((s.z_m - 0.170).abs() < 0.001, "{s:?}");
        assert!((s.x_m + 2.735).abs() < 0.003, "{s:?}");
    }

    #[test]
    fn a_noiseless_plates_edge_is_exact_to_its_point_spacing() {
        let points = plate(1.9, 0.25, 0.002, 0.0);
        let marked = vec![true; points.len()];
        let s = face_bottoms(&points, &marked, &[], (-1.2, 1.2), 0.001, 0.005, 5)[0];
        assert!((s.z_m - 0.25).abs() < 0.002, "{s:?}");
        assert!((s.x_m - 1.9).abs() < 1e-12, "{s:?}");
    }

    #[test]
    fn two_plates_apart_are_two_faces_and_unmarked_points_are_none() {
        let mut points = plate(-2.7, 0.17, 0.004, 0.0);
        points.extend(plate(-2.9, 0.22, 0.004, 0.0));
        let mut marked = vec![true; points.len()];
        let mut samples = face_bottoms(&points, &marked, &[], (-1.2, 1.2), 0.002, 0.005, 5);
        samples.sort_by(|a, b| a.x_m.total_cmp(&b.x_m));
        assert_eq!(samples.len(), 2, "{samples:?}");
        assert!((samples[0].z_m - 0.22).abs() < 0.004 && (samples[1].z_m - 0.17).abs() < 0.004);
        marked.fill(false);
        assert!(face_bottoms(&points, &marked, &[], (-1.2, 1.2), 0.002, 0.005, 5).is_empty());
    }

    #[test]
    fn an_edge_where_the_underside_continues_inboard_gives_no_sample() {
        // A frame rail's end cap at x 1.9 (front overhang, inboard is -x) whose underside the
        // modes hold 2-5 cm inboard, and a flap at -1.535 whose own modes lie within its smear.
        let points = plate(1.9, 0.34, 0.004, 0.0);
        let marked = vec![true; points.len()];
        let underside = |x_m, z_m| EnvelopeSample {
            x_m,
            z_m,
            y_m: 0.0,
            support: 50,
        };
        let axles = (-1.2, 1.2);
        let rail = [underside(1.87, 0.341), underside(1.86, 0.340)];
        assert!(face_bottoms(&points, &marked, &rail, axles, 0.004, 0.005, 5).is_empty());
        let higher = [underside(1.87, 0.40)];
        assert_eq!(
            face_bottoms(&points, &marked, &higher, axles, 0.004, 0.005, 5).len(),
            1
        );
        let flap_points = plate(-1.535, 0.17, 0.004, 0.0);
        let marked = vec![true; flap_points.len()];
        let own_modes = [underside(-1.528, 0.178), underside(-1.523, 0.178)];
        let s = face_bottoms(&flap_points, &marked, &own_modes, axles, 0.004, 0.005, 5);
        assert_eq!(s.len(), 1, "{s:?}");
    }

    #[test]
    fn a_face_wider_at_its_bottom_gives_no_sample_below_its_points() {
        // A dense strip 1 cm tall under a sparse face: counted at the sparse density, the strip
        // would reach far below its own points.
        let mut points = plate(0.0, 0.20, 0.01, 0.0);
        for i in 0..400_u32 {
            points.push(V3::new(
                0.0,
                -0.1 + 0.0005 * f64::from(i),
                0.19 + 0.000_025 * f64::from(i),
            ));
        }
        let marked = vec![true; points.len()];
        for s in face_bottoms(&points, &marked, &[], (-1.2, 1.2), 0.001, 0.005, 5) {
            assert!(s.z_m >= 0.19 - 0.003, "{s:?}");
        }
    }
}
