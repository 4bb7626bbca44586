//! Tyres: find them from their contact with the ground, fit each as a circle in the side view.
//!
//! 1. Seeds: points a few centimetres above the ground (between `seed_low_m` and `seed_high_m`) are
//!    almost only tyre: cluster them on a 5 cm grid; keep compact clusters (a vehicle body part that
//!    low is wide, a tyre's footprint is not). The four largest are the tyres.
//! 2. Side-view circle per tyre: points in the tyre's lateral slab, projected onto the x-z plane.
//!    The silhouette (outermost point per 3-degree sector, walking outward from the centre and
//!    stopping at the first radial gap wider than `tyre_gap_m`, or 4 x the median radial step in
//!    sparse clouds, so the wheel arch and sills are not taken) is fitted with a geometric least-squares circle, trimmed at 3 sigma, iterated from a
//!    chord-based first guess. Silhouette points lower than 30 % of the centre height are not used:
//!    a loaded tyre is flattened and bulges near the road.
//! 3. The static loaded radius is the centre's height above the ground; the fitted radius is the
//!    free tread radius. The lateral faces are the 1 % / 99 % quantiles of y of the points in the disc.

use std::collections::HashMap;

use super::geom::{Circle, V3, fit_circle, median};

/// Grid cell for seed clustering (metres).
const SEED_CELL_M: f64 = 0.05;

/// A cluster of low points that may be a tyre footprint.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Seed {
    pub x: f64,
    pub y: f64,
    pub x_min: f64,
    pub x_max: f64,
    pub y_min: f64,
    pub y_max: f64,
    pub count: usize,
    /// Half chord at the top of the seed slice, for the first radius guess.
    pub half_chord_m: f64,
}

/// Find footprint clusters among points (x, y, h) with `h_lo < h < h_hi`; largest first.
pub(crate) fn find_seeds(points: &[V3], h_lo: f64, h_hi: f64) -> (Vec<Seed>, usize) {
    let mut cells: HashMap<(i64, i64), Vec<usize>> = HashMap::new();
    for (i, p) in points.iter().enumerate() {
        if p[2] > h_lo && p[2] < h_hi {
            let key = (
                (p[0] / SEED_CELL_M).floor() as i64,
                (p[1] / SEED_CELL_M).floor() as i64,
            );
            cells.entry(key).or_default().push(i);
        }
    }
    let mut keys: Vec<(i64, i64)> = cells.keys().copied().collect();
    keys.sort_unstable();
    let mut seen: HashMap<(i64, i64), bool> = HashMap::new();
    let mut seeds = Vec::new();
    for start in keys {
        if seen.contains_key(&start) {
            continue;
        }
        seen.insert(start, true);
        let mut stack = vec![start];
        let mut members: Vec<usize> = Vec::new();
        while let Some((cx, cy)) = stack.pop() {
            members.extend(&cells[&(cx, cy)]);
            for dx in -1..=1 {
                for dy in -1..=1 {
                    let k = (cx + dx, cy + dy);
                    if cells.contains_key(&k) && !seen.contains_key(&k) {
                        seen.insert(k, true);
                        stack.push(k);
                    }
                }
            }
        }
        if let Some(seed) = seed_from(points, &members, h_hi) {
            seeds.push(seed);
        }
    }
    let compact = seeds.len();
    seeds.sort_by(|a, b| b.count.cmp(&a.count).then(a.x.total_cmp(&b.x)));
    (seeds, compact)
}

fn seed_from(points: &[V3], members: &[usize], h_hi: f64) -> Option<Seed> {
    if members.len() < 8 {
        return None;
    }
    let (mut x_min, mut x_max, mut y_min, mut y_max) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    let (mut sx, mut sy) = (0.0, 0.0);
    let (mut top_min, mut top_max) = (f64::MAX, f64::MIN);
    for &i in members {
        let p = points[i];
        x_min = x_min.min(p[0]);
        x_max = x_max.max(p[0]);
        y_min = y_min.min(p[1]);
        y_max = y_max.max(p[1]);
        sx += p[0];
        sy += p[1];
        if p[2] > h_hi - 0.015 {
            top_min = top_min.min(p[0]);
            top_max = top_max.max(p[0]);
        }
    }
    let n = members.len() as f64;
    let compact = (x_max - x_min) < 1.3 && (y_max - y_min) < 0.7 && (x_max - x_min) > 0.02;
    compact.then(|| Seed {
        x: sx / n,
        y: sy / n,
        x_min,
        x_max,
        y_min,
        y_max,
        count: members.len(),
        half_chord_m: if top_max > top_min {
            0.5 * (top_max - top_min)
        } else {
            0.5 * (x_max - x_min)
        },
    })
}

/// A tyre fitted in some ground-aligned frame (x, y, h).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct TyreFit {
    pub centre_x: f64,
    pub centre_y: f64,
    /// Centre height above the ground = static loaded radius.
    pub loaded_radius_m: f64,
    /// Fitted tread (free) radius.
    pub free_radius_m: f64,
    pub inner_y: f64,
    pub outer_y: f64,
    pub residual_rms_m: f64,
    pub silhouette_points: usize,
}

/// Parameters for [`fit_tyre`].
#[derive(Debug, Clone, Copy)]
pub(crate) struct TyreParams {
    pub h_lo: f64,
    pub h_hi: f64,
    pub gap_m: f64,
    pub noise_m: f64,
    /// Which side the vehicle centreline lies on: +1 if the centreline has larger y than this tyre.
    pub inward_sign: f64,
}

/// Fit one tyre around its seed; `None` if no consistent circle is found.
pub(crate) fn fit_tyre(points: &[V3], seed: &Seed, params: TyreParams) -> Option<TyreFit> {
    // The slab reaches 1 cm inboard of the footprint (body parts hug the inner face) and 3 cm outboard.
    let (slab_lo, slab_hi) = if params.inward_sign > 0.0 {
        (seed.y_min - 0.03, seed.y_max + 0.01)
    } else {
        (seed.y_min - 0.01, seed.y_max + 0.03)
    };
    let cand: Vec<[f64; 2]> = points
        .iter()
        .filter(|p| {
            p[1] > slab_lo
                && p[1] < slab_hi
                && (p[0] - seed.x).abs() < 1.2
                && p[2] > params.h_lo
                && p[2] < 2.0
        })
        .map(|p| [p[0], p[2]])
        .collect();
    let h = params.h_hi;
    let r0 = ((seed.half_chord_m.powi(2) + h * h) / (2.0 * h)).clamp(0.15, 1.0);
    let mut circle = Circle {
        u: 0.5 * (seed.x_min + seed.x_max),
        v: r0,
        r: r0,
    };
    let mut used = 0;
    let mut rms = f64::NAN;
    for _ in 0..5 {
        let sil = silhouette(&cand, circle, params.gap_m);
        let sil: Vec<[f64; 2]> = sil
            .into_iter()
            .filter(|p| p[1] > 0.3 * circle.v.max(0.1))
            .collect();
        let (c, n, e) = trimmed_circle(&sil, params.noise_m)?;
        let moved = (c.u - circle.u).abs() + (c.v - circle.v).abs() + (c.r - circle.r).abs();
        circle = c;
        used = n;
        rms = e;
        if moved < 1e-9 {
            break;
        }
    }
    if !(0.1..=1.2).contains(&circle.r) || circle.v <= 0.05 || used < 10 {
        return None;
    }
    let (inner_y, outer_y) = lateral_faces(points, seed, circle, params);
    Some(TyreFit {
        centre_x: circle.u,
        centre_y: 0.5 * (inner_y + outer_y),
        loaded_radius_m: circle.v,
        free_radius_m: circle.r,
        inner_y,
        outer_y,
        residual_rms_m: rms,
        silhouette_points: used,
    })
}

/// Outermost connected point per 3-degree sector around `c`.
fn silhouette(cand: &[[f64; 2]], c: Circle, gap_m: f64) -> Vec<[f64; 2]> {
    const SECTORS: usize = 120;
    let mut sectors: Vec<Vec<(f64, usize)>> = vec![Vec::new(); SECTORS];
    for (i, p) in cand.iter().enumerate() {
        let (du, dv) = (p[0] - c.u, p[1] - c.v);
        let rho = du.hypot(dv);
        if rho > 1.6 * c.r {
            continue;
        }
        let t = (dv.atan2(du) + std::f64::consts::PI) / std::f64::consts::TAU;
        let k = ((t * SECTORS as f64) as usize).min(SECTORS - 1);
        sectors[k].push((rho, i));
    }
    for s in &mut sectors {
        s.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    }
    // Sparse clouds have wide radial steps inside the tyre too: the gap that ends the tyre is at
    // least 4 x the median step between consecutive points of a sector (inside 0.5 .. 1 radius).
    let mut steps: Vec<f64> = sectors
        .iter()
        .flat_map(|s| {
            s.windows(2)
                .filter(|w| w[0].0 >= 0.5 * c.r && w[1].0 <= c.r)
                .map(|w| w[1].0 - w[0].0)
        })
        .collect();
    let gap_m = gap_m.max(4.0 * median(&mut steps).unwrap_or(0.0));
    let mut out = Vec::with_capacity(SECTORS);
    for s in sectors {
        let mut last: Option<(f64, usize)> = None;
        for &(rho, i) in &s {
            if let Some((prev, _)) = last
                && rho - prev > gap_m
                && prev >= 0.5 * c.r
            {
                break;
            }
            last = Some((rho, i));
        }
        if let Some((rho, i)) = last
            && rho >= 0.5 * c.r
        {
            out.push(cand[i]);
        }
    }
    out
}

/// Circle fit, then refit without residuals beyond 3 sigma (robust MAD), twice.
/// Returns the circle, points used and their RMS residual.
fn trimmed_circle(points: &[[f64; 2]], noise_m: f64) -> Option<(Circle, usize, f64)> {
    let mut pts = points.to_vec();
    let mut c = fit_circle(&pts)?;
    for _ in 0..3 {
        let res = |p: &[f64; 2]| (p[0] - c.u).hypot(p[1] - c.v) - c.r;
        let mut abs: Vec<f64> = pts.iter().map(|p| res(p).abs()).collect();
        let sigma = 1.4826 * median(&mut abs)?;
        let limit = (3.0 * sigma).max(3.0 * noise_m).max(0.002);
        let kept: Vec<[f64; 2]> = pts
            .iter()
            .copied()
            .filter(|p| res(p).abs() <= limit)
            .collect();
        if kept.len() == pts.len() || kept.len() < 8 {
            break;
        }
        pts = kept;
        c = fit_circle(&pts)?;
    }
    let rms = (pts
        .iter()
        .map(|p| ((p[0] - c.u).hypot(p[1] - c.v) - c.r).powi(2))
        .sum::<f64>()
        / pts.len() as f64)
        .sqrt();
    Some((c, pts.len(), rms))
}

/// Inner and outer face (y) of the tyre: 1 % / 99 % quantiles of y of points inside the disc.
fn lateral_faces(points: &[V3], seed: &Seed, c: Circle, params: TyreParams) -> (f64, f64) {
    let tol = (3.0 * params.noise_m).max(0.01);
    // As for the slab: 1 cm inboard of the footprint, 5 cm outboard.
    let (lo, hi) = if params.inward_sign > 0.0 {
        (seed.y_min - 0.05, seed.y_max + 0.01)
    } else {
        (seed.y_min - 0.01, seed.y_max + 0.05)
    };
    let mut ys: Vec<f64> = points
        .iter()
        .filter(|p| {
            p[1] > lo
                && p[1] < hi
                && p[2] > params.h_hi
                && (p[0] - c.u).hypot(p[2] - c.v) < c.r + tol
        })
        .map(|p| p[1])
        .collect();
    if ys.len() < 10 {
        return if params.inward_sign > 0.0 {
            (seed.y_max, seed.y_min)
        } else {
            (seed.y_min, seed.y_max)
        };
    }
    ys.sort_unstable_by(f64::total_cmp);
    let q = |f: f64| ys[((ys.len() - 1) as f64 * f).round() as usize];
    let (lo, hi) = (q(0.01), q(0.99));
    if params.inward_sign > 0.0 {
        (hi, lo)
    } else {
        (lo, hi)
    }
}
