//! Robust lower envelope of the body in the side view.
//!
//! Body points inside the lateral band are binned along x (`bin_m`). In each bin the lowest *mode*
//! of the heights is found: the lowest window of height `2 w` that holds at least `min_support`
//! points, then re-centred on the mean of the points within `w` of it until it stops moving (a
//! flat-kernel mean shift that climbs from the noise tail to the surface; a peak with more than
//! twice its points in the next `2 w` above it, counted at its own lateral positions, is a tail
//! fluctuation, and the climb goes on; a narrow part under a wide surface is not a tail of it).
//! `w` is 2.5 x the noise sigma (at least 1 mm), so on a noisy flat surface the mode is the
//! surface itself, not its low noise tail; a lone low outlier (fewer than `min_support` points
//! within `2 w`) never forms a mode and is counted in `outliers_below`.
//!
//! The mode's points get a least-squares line `z = a + b (x - x_mean)`; the bin contributes two
//! envelope samples, the line's values at the mode's lowest and highest x, each pulled 2 noise sigma
//! toward the mean x (noise spreads points outward; with no noise the extremes are exact), heights
//! clamped to the mode's height range. On noiseless piecewise-flat surfaces both samples lie exactly on the surface, so
//! corners are kept to the point spacing; on noisy ones each sample averages the whole mode.
//! Known bias (measured in the tests and the README section "Passing angles"): at a convex corner the mode mixes both
//! faces within `w`, which lifts the envelope there by up to about `w / 2`.

/// One envelope sample in the side view (vehicle frame x forward, z up).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EnvelopeSample {
    /// Position along the vehicle (metres).
    pub x_m: f64,
    /// Height above the ground (metres).
    pub z_m: f64,
    /// Mean lateral position of the supporting points (metres).
    pub y_m: f64,
    /// Points in the bin's lowest mode (the support of this sample).
    pub support: usize,
}

/// Envelope parameters.
#[derive(Debug, Clone, Copy)]
pub(crate) struct EnvelopeParams {
    pub bin_m: f64,
    pub half_window_m: f64,
    pub min_support: usize,
    /// Noise sigma: the mode's extreme x are pulled in by 2 sigma (noise spreads them outward).
    pub noise_m: f64,
}

/// Result of the envelope pass.
#[derive(Debug, Clone, Default)]
pub(crate) struct Envelope {
    pub samples: Vec<EnvelopeSample>,
    /// Points that lay below their bin's mode (rejected as outliers).
    pub outliers_below: usize,
    /// Bins with points but no mode of sufficient support.
    pub unsupported_bins: usize,
    /// Sparse bins at the noise fringe of a dense surface, not used (see [`fringe_bins`]).
    pub fringe_bins: usize,
}

/// Noise sigma normal to the underside, from the points themselves: the points are split into
/// 3 cm x 3 cm columns (x, y); each column with at least 12 points gets a least-squares plane
/// `z = a x + b y + c`; columns steeper than 45 degrees are skipped; the estimate is the median of
/// the columns' residual standard deviations (robust to the few columns that straddle an edge).
/// Range noise projects unevenly (rays near the sensor's path see it vertically, grazing rays
/// little), so this is a typical, not a worst-case, figure.
/// `None` if fewer than 10 columns qualify.
pub(crate) fn surface_noise(points: &[[f64; 3]]) -> Option<f64> {
    const CELL_M: f64 = 0.03;
    let mut keyed: Vec<((i64, i64), [f64; 3])> = points
        .iter()
        .map(|p| {
            (
                (
                    (p[0] / CELL_M).floor() as i64,
                    (p[1] / CELL_M).floor() as i64,
                ),
                *p,
            )
        })
        .collect();
    keyed.sort_unstable_by_key(|a| a.0);
    let mut sigmas = Vec::new();
    for group in keyed.chunk_by(|a, b| a.0 == b.0) {
        if group.len() < 12 {
            continue;
        }
        let pts = group.iter().map(|(_, p)| *p);
        let Some((normal, centre)) = super::geom::fit_plane(pts.clone()) else {
            continue;
        };
        if normal[2] < std::f64::consts::FRAC_1_SQRT_2 {
            continue;
        }
        let ssr: f64 = pts
            .map(|p| {
                let d = super::geom::sub(p, centre);
                super::geom::dot(d, normal).powi(2)
            })
            .sum();
        sigmas.push((ssr / (group.len() - 3) as f64).sqrt());
    }
    if sigmas.len() < 10 {
        return None;
    }
    super::geom::median(&mut sigmas)
}

/// Lower envelope of `points` (x, y, z), already restricted to the band.
pub(crate) fn lower_envelope(points: &[[f64; 3]], params: EnvelopeParams) -> Envelope {
    let mut keyed: Vec<(i64, [f64; 3])> = points
        .iter()
        .map(|p| ((p[0] / params.bin_m).floor() as i64, *p))
        .collect();
    keyed.sort_unstable_by(|a, b| a.0.cmp(&b.0).then(a.1[2].total_cmp(&b.1[2])));
    let mut env = Envelope::default();
    // Per bin: key, support, mode mean height, samples.
    let mut modes: Vec<(i64, usize, f64, Vec<EnvelopeSample>)> = Vec::new();
    let mut start = 0;
    while start < keyed.len() {
        let key = keyed[start].0;
        let end = start + keyed[start..].iter().take_while(|(k, _)| *k == key).count();
        let bin: Vec<[f64; 3]> = keyed[start..end].iter().map(|(_, p)| *p).collect();
        match bin_mode(&bin, params) {
            Some((lo, hi)) => {
                env.outliers_below += lo;
                let mode = &bin[lo..hi];
                modes.push((
                    key,
                    mode.len(),
                    mean_z(mode),
                    line_samples(mode, params.noise_m),
                ));
            }
            None => env.unsupported_bins += 1,
        }
        start = end;
    }
    let fringe = fringe_bins(&modes, params);
    env.fringe_bins = fringe.iter().filter(|f| **f).count();
    for ((_, _, _, samples), is_fringe) in modes.into_iter().zip(fringe) {
        if !is_fringe {
            env.samples.extend(samples);
        }
    }
    env
}

/// Noise fringe: range noise smears a surface's edge beyond it (mostly along x, since a low
/// sensor sees the underside and the bumpers' lower edges along the vehicle), into bins that hold
/// fewer points than the surface. A bin is fringe if a bin within 4 noise sigma (at most
/// `FRINGE_REACH_M`; none without noise) along x has at
/// least `FRINGE_RATIO` x its support and a mode no higher than its own plus `max(3 sigma, 2 mm)`:
/// a sparser bin beside a denser surface at about the same height or lower. Ratio 2 is the
/// half-density point where a blurred edge truly ends: on lidar-only simulator clouds (VLP-16,
/// 1.5 cm range noise) the off-roader's bumper edge was smeared 2 cm forward and its approach
/// angle read 0.9 degree low with the ratio 4 used before, 0.3 degree high with 2. A sparse part
/// clearly lower than its dense neighbours (a tow ball below a bumper) is kept. Known cost, also
/// without noise: a part with less than half the support of a surface within 2 cm of it along x
/// and not lower than it is ignored (its effect is then bounded by those 2 cm); in sparse clouds,
/// where supports fluctuate, the outermost bins of an edge go first (an inward bias of a bin).
fn fringe_bins(
    modes: &[(i64, usize, f64, Vec<EnvelopeSample>)],
    params: EnvelopeParams,
) -> Vec<bool> {
    // The fringe is as wide as the noise blur: about 4 sigma, capped at `FRINGE_REACH_M`; a
    // noiseless cloud has none (its sparse bins are real corners, e.g. steep bumper faces).
    let reach_m = (4.0 * params.noise_m).min(FRINGE_REACH_M);
    if reach_m < 1e-4 {
        return vec![false; modes.len()];
    }
    let reach = (reach_m / params.bin_m).ceil() as i64;
    let tol = (3.0 * params.noise_m).max(0.002);
    modes
        .iter()
        .enumerate()
        .map(|(i, &(key, support, z, _))| {
            let lo = modes[..i].partition_point(|m| m.0 < key - reach);
            modes[lo..]
                .iter()
                .take_while(|m| m.0 <= key + reach)
                .any(|m| m.0 != key && m.1 >= FRINGE_RATIO * support && m.2 <= z + tol)
        })
        .collect()
}

/// How far along x a dense bin marks sparse neighbours as fringe.
const FRINGE_REACH_M: f64 = 0.02;
/// Support ratio that marks a bin as fringe.
const FRINGE_RATIO: usize = 2;

/// Index range (into the height-sorted bin) of the lowest mode.
fn bin_mode(bin: &[[f64; 3]], params: EnvelopeParams) -> Option<(usize, usize)> {
    let (w, m) = (params.half_window_m, params.min_support.max(1));
    let n = bin.len();
    let mut j = 0;
    let mut first = None;
    for i in 0..n {
        j = j.max(i);
        while j < n && bin[j][2] < bin[i][2] + 2.0 * w {
            j += 1;
        }
        if j - i >= m {
            first = Some((i, j));
            break;
        }
    }
    let (mut lo, mut hi) = first?;
    let window = |centre: f64| {
        (
            bin.partition_point(|p| p[2] < centre - w),
            bin.partition_point(|p| p[2] <= centre + w),
        )
    };
    for _ in 0..32 {
        // Mean shift to a local density peak.
        for _ in 0..64 {
            let (nlo, nhi) = window(mean_z(&bin[lo..hi]));
            if nhi - nlo < m || (nlo, nhi) == (lo, hi) {
                break;
            }
            (lo, hi) = (nlo, nhi);
        }
        // A peak in the noise tail of a denser surface just above it is not a surface of its
        // own: if the next 2 w above hold more than twice its points at its own lateral
        // positions, keep climbing. (Counted across the whole band, a floor 1.3 m wide outnumbered
        // the sedan's 12 cm wide silencer 2-3 cm below it, and every other bin of the silencer's
        // last 2 cm took the floor.)
        let mean = mean_z(&bin[lo..hi]);
        let (y_lo, y_hi) = y_range(&bin[lo..hi]);
        let above = bin[hi..bin.partition_point(|p| p[2] <= mean + 3.0 * w)]
            .iter()
            .filter(|p| p[1] >= y_lo && p[1] <= y_hi)
            .count();
        if above <= 2 * (hi - lo) {
            break;
        }
        let (nlo, nhi) = window(mean + w);
        if nhi - nlo < m {
            break;
        }
        (lo, hi) = (nlo, nhi);
    }
    Some((lo, hi))
}

/// Lowest and highest y of `points`.
fn y_range(points: &[[f64; 3]]) -> (f64, f64) {
    points.iter().fold((f64::MAX, f64::MIN), |(lo, hi), p| {
        (lo.min(p[1]), hi.max(p[1]))
    })
}

fn mean_z(points: &[[f64; 3]]) -> f64 {
    points.iter().map(|p| p[2]).sum::<f64>() / points.len().max(1) as f64
}

/// The two samples of a bin: its mode's line at the lowest and the highest x.
fn line_samples(mode: &[[f64; 3]], noise_m: f64) -> Vec<EnvelopeSample> {
    let n = mode.len() as f64;
    let (mx, my, mz) = mode.iter().fold((0.0, 0.0, 0.0), |(a, b, c), p| {
        (a + p[0], b + p[1], c + p[2])
    });
    let (mx, my, mz) = (mx / n, my / n, mz / n);
    let (mut sxx, mut sxz) = (0.0, 0.0);
    let (mut x_lo, mut x_hi, mut z_lo, mut z_hi) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for p in mode {
        sxx += (p[0] - mx).powi(2);
        sxz += (p[0] - mx) * (p[2] - mz);
        x_lo = x_lo.min(p[0]);
        x_hi = x_hi.max(p[0]);
        z_lo = z_lo.min(p[2]);
        z_hi = z_hi.max(p[2]);
    }
    let slope = if mode.len() >= 3 && sxx > 1e-12 {
        sxz / sxx
    } else {
        0.0
    };
    let at = |x: f64| (mz + slope * (x - mx)).clamp(z_lo, z_hi);
    let sample = |x: f64| EnvelopeSample {
        x_m: x,
        z_m: at(x),
        y_m: my,
        support: mode.len(),
    };
    let (x_lo, x_hi) = (
        (x_lo + 2.0 * noise_m).min(mx),
        (x_hi - 2.0 * noise_m).max(mx),
    );
    if x_hi - x_lo < 1e-9 {
        vec![sample(mx)]
    } else {
        vec![sample(x_lo), sample(x_hi)]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const P: EnvelopeParams = EnvelopeParams {
        bin_m: 0.01,
        half_window_m: 0.002,
        min_support: 5,
        noise_m: 0.0,
    };

    #[test]
    fn single_low_outlier_is_ignored() {
        let mut pts: Vec<[f64; 3]> = (0..40)
            .map(|i| [0.005, f64::from(i) * 0.01, 0.30])
            .collect();
        pts.push([0.005, 0.1, 0.10]);
        let env = lower_envelope(&pts, P);
        assert_eq!(env.outliers_below, 1);
        assert!(
            env.samples
                .iter()
                .all(|s| (s.z_m - 0.30).abs() < 1e-12 && s.support == 40)
        );
    }

    #[test]
    fn narrow_low_feature_with_support_wins() {
        let mut pts: Vec<[f64; 3]> = (0..40)
            .map(|i| [0.005, f64::from(i) * 0.01, 0.30])
            .collect();
        pts.extend((0..6).map(|i| [0.005, 0.5 + f64::from(i) * 0.005, 0.20]));
        let env = lower_envelope(&pts, P);
        assert!(
            env.samples
                .iter()
                .all(|s| (s.z_m - 0.20).abs() < 1e-12 && s.support == 6)
        );
    }

    #[test]
    fn sloped_surface_samples_lie_on_it() {
        let pts: Vec<[f64; 3]> = (0..200)
            .map(|i| {
                let x = f64::from(i % 20) * 0.0005;
                [x, f64::from(i / 20) * 0.01, 0.25 + 0.3 * x]
            })
            .collect();
        let env = lower_envelope(
            &pts,
            EnvelopeParams {
                half_window_m: 0.01,
                ..P
            },
        );
        assert_eq!(env.samples.len(), 2);
        for s in env.samples {
            assert!((s.z_m - (0.25 + 0.3 * s.x_m)).abs() < 1e-12, "{s:?}");
        }
    }

    #[test]
    fn sparse_bins_are_reported_not_used() {
        let pts = [[0.0, 0.0, 0.3], [0.0, 0.1, 0.5]];
        let env = lower_envelope(&pts, P);
        assert!(env.samples.is_empty());
        assert_eq!(env.unsupported_bins, 1);
    }

    /// A narrow part (a pipe 10 cm wide) 2 w below a surface across the whole band: the surface
    /// outnumbers the part's points in the bin, but not at the part's lateral positions, so the
    /// part is the bin's lowest mode, not a noise tail of the surface (the old rule counted the
    /// surface's points across the whole band and climbed to it).
    #[test]
    fn narrow_part_under_wide_surface_is_not_a_tail() {
        let w = 0.004;
        let mut pts: Vec<[f64; 3]> = (0..20)
            .map(|i| {
                let jitter = if i % 2 == 0 { 0.001 } else { -0.001 };
                [0.005, 0.40 + f64::from(i) * 0.005, 0.20 + jitter]
            })
            .collect();
        pts.extend((0..240).map(|i| [0.005, -0.6 + f64::from(i) * 0.005, 0.20 + 2.0 * w]));
        let env = lower_envelope(
            &pts,
            EnvelopeParams {
                half_window_m: w,
                ..P
            },
        );
        assert!(!env.samples.is_empty());
        for s in &env.samples {
            assert!((s.z_m - 0.20).abs() < 0.0015, "{s:?}");
        }
    }
}
