//! Side-view report as SVG, like the paper's Figure 6: ground, the body's lower envelope, the tyre
//! circles (static loaded radius dashed, fitted tread radius solid), the three tangent lines, the
//! witness points, the angle values and a scale bar. Pure: result in, SVG text out.

use std::fmt::Write as _;

use super::{AnglesResult, Axle, Zone};

const WIDTH_PX: f64 = 1200.0;
const MARGIN_PX: f64 = 40.0;

struct View {
    x0: f64,
    z_top: f64,
    px_per_m: f64,
}

impl View {
    fn x(&self, x_m: f64) -> f64 {
        MARGIN_PX + (x_m - self.x0) * self.px_per_m
    }
    fn y(&self, z_m: f64) -> f64 {
        MARGIN_PX + 40.0 + (self.z_top - z_m) * self.px_per_m
    }
}

/// Render the side view of `result` (vehicle front to the right) as a standalone SVG document.
pub fn side_view_svg(result: &AnglesResult) -> String {
    let env = &result.envelope;
    let (fa, ra) = (result.front_axle, result.rear_axle);
    let x_min = env
        .iter()
        .map(|s| s.x_m)
        .fold(ra.x_m - ra.free_radius_m, f64::min)
        - 0.3;
    let x_max = env
        .iter()
        .map(|s| s.x_m)
        .fold(fa.x_m + fa.free_radius_m, f64::max)
        + 0.3;
    let z_max = env
        .iter()
        .map(|s| s.z_m)
        .fold(2.0 * fa.free_radius_m.max(ra.free_radius_m), f64::max)
        + 0.15;
    let px_per_m = (WIDTH_PX - 2.0 * MARGIN_PX) / (x_max - x_min);
    let v = View {
        x0: x_min,
        z_top: z_max,
        px_per_m,
    };
    let height_px = v.y(-0.05) + 70.0;
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{WIDTH_PX}" height="{height_px:.0}" viewBox="0 0 {WIDTH_PX} {height_px:.0}" font-family="sans-serif" font-size="14">
<rect width="100%" height="100%" fill="white"/>
<text x="{MARGIN_PX}" y="24" font-size="18">passangle side view (front to the right), zone: {zone}, band y {b0} .. {b1} m</text>"#,
        zone = match result.zone {
            Zone::Tyre => "ahead of / behind the tyres (CFR/SAE)",
            Zone::Axle => "ahead of / behind the axles (EU)",
        },
        b0 = fmt_m(result.band_y_m.0),
        b1 = fmt_m(result.band_y_m.1),
    );
    // Ground.
    let _ = writeln!(
        s,
        r##"<line x1="{:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}" stroke="#7a5c3a" stroke-width="3"/>"##,
        v.x(x_min),
        v.y(0.0),
        v.x(x_max),
        v.y(0.0)
    );
    // Tyres first (translucent), then the envelope: in the band, the body lies between the tyres
    // laterally, so parts under the axles (differentials) show through.
    tyre_circles(&mut s, &v, fa);
    tyre_circles(&mut s, &v, ra);
    // Envelope of the body in the band.
    let drawn: Vec<[f64; 2]> = env.iter().map(|e| [v.x(e.x_m), v.y(e.z_m)]).collect();
    let pts: Vec<String> = simplified(&drawn, ENVELOPE_TOLERANCE_PX)
        .iter()
        .map(|p| format!("{:.1},{:.1}", p[0], p[1]))
        .collect();
    for chunk in pts.chunks(2000) {
        let _ = writeln!(
            s,
            r##"<polyline points="{}" fill="none" stroke="#333" stroke-width="1.5"/>"##,
            chunk.join(" ")
        );
    }
    tangent_lines(&mut s, &v, result);
    scale_bar(&mut s, &v, height_px);
    let _ = writeln!(
        s,
        r#"<text x="{x:.1}" y="{:.1}">wheelbase {:.3} m, {} envelope samples</text>
<text x="{x:.1}" y="{:.1}">tyres: solid = fitted tread radius; dashed = static loaded radius (front {:.3} m, rear {:.3} m), the circle the tangents touch</text>"#,
        height_px - 40.0,
        result.wheelbase_m,
        env.len(),
        height_px - 20.0,
        fa.loaded_radius_m,
        ra.loaded_radius_m,
        x = MARGIN_PX + v.px_per_m + 20.0,
    );
    s.push_str("</svg>\n");
    s
}

fn fmt_m(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.2}")
    } else {
        "all".to_string()
    }
}

fn tyre_circles(s: &mut String, v: &View, a: Axle) {
    let (cx, cy) = (v.x(a.x_m), v.y(a.loaded_radius_m));
    let _ = writeln!(
        s,
        r##"<circle cx="{cx:.1}" cy="{cy:.1}" r="{:.1}" fill="#d0d0d0" fill-opacity="0.5" stroke="#111" stroke-width="2"/>
<circle cx="{cx:.1}" cy="{cy:.1}" r="{:.1}" fill="none" stroke="#1565c0" stroke-width="1.5" stroke-dasharray="6 4"/>
<circle cx="{cx:.1}" cy="{cy:.1}" r="3" fill="#111"/>"##,
        a.free_radius_m * v.px_per_m,
        a.loaded_radius_m * v.px_per_m
    );
}

fn line(s: &mut String, v: &View, a: (f64, f64), b: (f64, f64), colour: &str) {
    let _ = writeln!(
        s,
        r#"<line x1="{:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}" stroke="{colour}" stroke-width="2"/>"#,
        v.x(a.0),
        v.y(a.1),
        v.x(b.0),
        v.y(b.1)
    );
}

fn witness(s: &mut String, v: &View, p: (f64, f64), colour: &str, label: &str, anchor: &str) {
    let _ = writeln!(
        s,
        r#"<circle cx="{:.1}" cy="{:.1}" r="5" fill="none" stroke="{colour}" stroke-width="2.5"/>
<text x="{:.1}" y="{:.1}" fill="{colour}" text-anchor="{anchor}" font-weight="bold">{label}</text>"#,
        v.x(p.0),
        v.y(p.1),
        v.x(p.0),
        v.y(p.1) - 16.0
    );
}

/// Ground point of a line through `p` with slope angle `a` rising in direction `dir` (+1: forward).
fn ground_hit(p: (f64, f64), a: f64, dir: f64) -> (f64, f64) {
    if a.tan() > 1e-6 {
        (p.0 - dir * p.1 / a.tan(), 0.0)
    } else {
        p
    }
}

fn tangent_lines(s: &mut String, v: &View, r: &AnglesResult) {
    let (fa, ra) = (r.front_axle, r.rear_axle);
    if let Some(f) = &r.approach {
        let w = (f.witness_in_vehicle[0], f.witness_in_vehicle[2]);
        let g = ground_hit(w, f.angle_rad, 1.0);
        let ext = (
            w.0 + 0.15 * f.angle_rad.cos(),
            w.1 + 0.15 * f.angle_rad.sin(),
        );
        line(s, v, g, ext, "#c62828");
        let label = format!(
            "approach {:.2}° ({} pts)",
            f.angle_rad.to_degrees(),
            f.support
        );
        witness(s, v, w, "#c62828", &label, "end");
        let _ = fa;
    }
    if let Some(f) = &r.departure {
        let w = (f.witness_in_vehicle[0], f.witness_in_vehicle[2]);
        let g = ground_hit(w, f.angle_rad, -1.0);
        let ext = (
            w.0 - 0.15 * f.angle_rad.cos(),
            w.1 + 0.15 * f.angle_rad.sin(),
        );
        line(s, v, g, ext, "#2e7d32");
        let label = format!(
            "departure {:.2}° ({} pts)",
            f.angle_rad.to_degrees(),
            f.support
        );
        witness(s, v, w, "#2e7d32", &label, "start");
    }
    if let Some(f) = &r.breakover {
        let w = (f.witness_in_vehicle[0], f.witness_in_vehicle[2]);
        if let Some((af, ar)) = f.parts_rad {
            line(s, v, w, ground_hit(w, af, -1.0), "#6a1b9a");
            line(s, v, w, ground_hit(w, ar, 1.0), "#6a1b9a");
        }
        let label = format!(
            "breakover {:.2}° ({} pts)",
            f.angle_rad.to_degrees(),
            f.support
        );
        witness(s, v, w, "#6a1b9a", &label, "middle");
    }
    if let Some(c) = &r.ground_clearance {
        let (x, z) = (c.witness_in_vehicle[0], c.witness_in_vehicle[2]);
        line(s, v, (x, 0.0), (x, z), "#ef6c00");
        let _ = writeln!(
            s,
            r##"<text x="{:.1}" y="{:.1}" fill="#ef6c00">clearance {:.3} m</text>"##,
            v.x(x) + 6.0,
            v.y(0.5 * z) + 20.0,
            c.height_m
        );
    }
    let _ = ra;
}

fn scale_bar(s: &mut String, v: &View, height_px: f64) {
    let y = height_px - 28.0;
    let x = MARGIN_PX;
    let len = v.px_per_m;
    let _ = writeln!(
        s,
        r##"<line x1="{x:.1}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#000" stroke-width="4"/>
<line x1="{x:.1}" y1="{:.1}" x2="{x:.1}" y2="{:.1}" stroke="#000" stroke-width="2"/>
<line x1="{:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}" stroke="#000" stroke-width="2"/>
<text x="{x:.1}" y="{:.1}">1 m</text>"##,
        x + len,
        y - 6.0,
        y + 6.0,
        x + len,
        y - 6.0,
        x + len,
        y + 6.0,
        y + 20.0
    );
}

/// How far the drawn envelope may leave its samples, pixels: a third of its stroke's width, so
/// the line looks the same with a fraction of the points (the samples are millimetres apart,
/// several per pixel).
const ENVELOPE_TOLERANCE_PX: f64 = 0.5;

/// The polyline through `points` with the vertices that lie within `tol` of the line through
/// their neighbours left out (Douglas-Peucker): every point stays within `tol` of the result.
fn simplified(points: &[[f64; 2]], tol: f64) -> Vec<[f64; 2]> {
    if points.len() < 3 {
        return points.to_vec();
    }
    let mut keep = vec![false; points.len()];
    keep[0] = true;
    keep[points.len() - 1] = true;
    let mut stack = vec![(0, points.len() - 1)];
    while let Some((a, b)) = stack.pop() {
        let (pa, pb) = (points[a], points[b]);
        let (dx, dy) = (pb[0] - pa[0], pb[1] - pa[1]);
        let len = dx.hypot(dy);
        let dist = |p: [f64; 2]| {
            if len < 1e-12 {
                (p[0] - pa[0]).hypot(p[1] - pa[1])
            } else {
                ((p[0] - pa[0]) * dy - (p[1] - pa[1]) * dx).abs() / len
            }
        };
        let far = (a + 1..b)
            .map(|i| (i, dist(points[i])))
            .max_by(|x, y| x.1.total_cmp(&y.1));
        if let Some((i, d)) = far
            && d > tol
        {
            keep[i] = true;
            stack.push((a, i));
            stack.push((i, b));
        }
    }
    points
        .iter()
        .zip(keep)
        .filter_map(|(p, k)| k.then_some(*p))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::simplified;

    /// Distance from `p` to the segment `a`-`b`.
    fn to_segment(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let t = (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / (dx * dx + dy * dy)).clamp(0.0, 1.0);
        (p[0] - a[0] - t * dx).hypot(p[1] - a[1] - t * dy)
    }

    #[test]
    fn a_simplified_polyline_stays_within_its_tolerance_of_every_point() {
        let points: Vec<[f64; 2]> = (0..2000)
            .map(|i| {
                let x = f64::from(i) * 0.2;
                [
                    x,
                    40.0 * (x / 30.0).sin() + if i % 7 == 0 { 0.3 } else { 0.0 },
                ]
            })
            .collect();
        let kept = simplified(&points, 0.5);
        assert!(kept.len() < points.len() / 5, "{} points kept", kept.len());
        assert_eq!(kept.first(), points.first());
        assert_eq!(kept.last(), points.last());
        for p in &points {
            let d = kept
                .windows(2)
                .map(|w| to_segment(*p, w[0], w[1]))
                .fold(f64::INFINITY, f64::min);
            assert!(d <= 0.5 + 1e-9, "{p:?} is {d} px off");
        }
        let line: Vec<[f64; 2]> = (0..100).map(|i| [f64::from(i), 2.0]).collect();
        assert_eq!(simplified(&line, 0.5), vec![[0.0, 2.0], [99.0, 2.0]]);
    }
}
