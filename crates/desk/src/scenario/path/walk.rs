//! From polyline to walk: a tour in; out, a densely sampled path with every corner rounded by an
//! arc the walls allow ([`smooth`]), walking speeds along it ([`speeds`]) and the positions and
//! headings at each frame's instant ([`walk`]).

use super::geometry::cross;
use super::space::Space;
use super::{Rng, ARC_SLACK_M, P2, V2};

/// Largest corner radius.
const MAX_TURN_RADIUS_M: f64 = 1.5;

/// A densely sampled smooth path: points about 5 cm apart, with the curvature at each.
pub struct Dense {
    pub points: Vec<P2>,
    pub curvature: Vec<f64>,
    /// Arc length at each point.
    pub s: Vec<f64>,
}

/// Rounds every corner of the polyline with a circular arc: radius up to
/// `MAX_TURN_RADIUS_M`, its tangent length at most half of either adjoining leg, halved until
/// the arc keeps `ARC_SLACK_M` beyond the inflated walls (down to a sharp corner, which is on
/// the clear polyline).
pub fn smooth(space: &Space, poly: &[P2]) -> Dense {
    const STEP: f64 = 0.05;
    let mut points = vec![poly[0]];
    let mut curvature = vec![0.0];
    let push_line = |points: &mut Vec<P2>, curvature: &mut Vec<f64>, to: P2| {
        let from = *points.last().unwrap();
        let n = ((to - from).norm() / STEP).ceil() as usize;
        for i in 1..=n {
            points.push(from + (to - from) * (i as f64 / n as f64));
            curvature.push(0.0);
        }
    };
    for i in 1..poly.len() {
        if i + 1 == poly.len() {
            push_line(&mut points, &mut curvature, poly[i]);
            break;
        }
        let (a, p, b) = (poly[i - 1], poly[i], poly[i + 1]);
        let (la, lb) = ((p - a).norm(), (b - p).norm());
        let (d1, d2) = ((p - a) / la, (b - p) / lb);
        let phi = cross(d1, d2).atan2(d1.dot(&d2));
        if phi.abs() < 1e-4 {
            push_line(&mut points, &mut curvature, p);
            continue;
        }
        let tan_half = (phi.abs() / 2.0).tan();
        let mut tl = (MAX_TURN_RADIUS_M * tan_half).min(0.5 * la).min(0.5 * lb);
        let mut arc = None;
        for _ in 0..8 {
            let r = tl / tan_half;
            let t1 = p - d1 * tl;
            let left = V2::new(-d1.y, d1.x) * phi.signum();
            let c = t1 + left * r;
            let a0 = (t1 - c).y.atan2((t1 - c).x);
            let n = ((r * phi.abs()) / STEP).ceil().max(2.0) as usize;
            let pts: Vec<P2> = (1..=n)
                .map(|k| {
                    let ang = a0 + phi * k as f64 / n as f64;
                    c + V2::new(ang.cos(), ang.sin()) * r
                })
                .collect();
            let mut prev = t1;
            let ok = pts.iter().all(|&q| {
                let good = space.clear(prev, q, ARC_SLACK_M);
                prev = q;
                good
            }) && space.clear(points.last().copied().unwrap(), t1, ARC_SLACK_M);
            if ok {
                arc = Some((t1, pts, 1.0 / r));
                break;
            }
            tl *= 0.5;
        }
        match arc {
            Some((t1, pts, k)) => {
                push_line(&mut points, &mut curvature, t1);
                for q in pts {
                    points.push(q);
                    curvature.push(k);
                }
            }
            None => {
                push_line(&mut points, &mut curvature, p);
                *curvature.last_mut().unwrap() = f64::INFINITY;
            }
        }
    }
    let mut s = vec![0.0];
    for w in points.windows(2) {
        s.push(s.last().unwrap() + (w[1] - w[0]).norm());
    }
    Dense { points, curvature, s }
}

/// Walking speeds at the dense points: 1.0–1.5 m/s varying smoothly along the path, limited in
/// turns by a lateral acceleration (not below 0.75 m/s), and changing at most 0.5 m/s² along it.
pub fn speeds(dense: &Dense, rng: &mut Rng) -> Vec<f64> {
    const A_LAT: f64 = 0.8;
    const A_LONG: f64 = 0.5;
    const V_TURN_MIN: f64 = 0.75;
    let (p1, p2) = (
        rng.range(0.0, std::f64::consts::TAU),
        rng.range(0.0, std::f64::consts::TAU),
    );
    let tau = std::f64::consts::TAU;
    let mut v: Vec<f64> = dense
        .s
        .iter()
        .zip(&dense.curvature)
        .map(|(&s, &k)| {
            let base = 1.25 + 0.18 * (tau * s / 17.0 + p1).sin() + 0.07 * (tau * s / 5.3 + p2).sin();
            let turn = if k > 0.0 {
                (A_LAT / k).sqrt().max(V_TURN_MIN)
            } else {
                f64::INFINITY
            };
            base.min(turn)
        })
        .collect();
    // Acceleration limit, both ways: v² changes by at most 2·a·ds. Starts from rest-free walking.
    for i in 1..v.len() {
        let ds = dense.s[i] - dense.s[i - 1];
        v[i] = v[i].min((v[i - 1] * v[i - 1] + 2.0 * A_LONG * ds).sqrt());
    }
    for i in (0..v.len() - 1).rev() {
        let ds = dense.s[i + 1] - dense.s[i];
        v[i] = v[i].min((v[i + 1] * v[i + 1] + 2.0 * A_LONG * ds).sqrt());
    }
    v
}

/// Positions and path headings at `frames` instants `dt` apart, walking the dense path at the
/// given speeds; `None` when the path is too short.
pub fn walk(dense: &Dense, v: &[f64], frames: usize, dt: f64) -> Option<Vec<(P2, f64)>> {
    const SUB: usize = 20;
    let total = *dense.s.last().unwrap();
    let mut out = Vec::with_capacity(frames);
    let mut s = 0.0;
    let mut idx = 0;
    let locate = |s: f64, idx: &mut usize| {
        while *idx + 2 < dense.s.len() && dense.s[*idx + 1] <= s {
            *idx += 1;
        }
        let (s0, s1) = (dense.s[*idx], dense.s[*idx + 1]);
        if s1 > s0 {
            ((s - s0) / (s1 - s0)).clamp(0.0, 1.0)
        } else {
            0.0
        }
    };
    for k in 0..frames {
        if k > 0 {
            for _ in 0..SUB {
                let f = locate(s, &mut idx);
                let speed = v[idx] + (v[idx + 1] - v[idx]) * f;
                s += speed * dt / SUB as f64;
            }
        }
        if s > total {
            return None;
        }
        let f = locate(s, &mut idx);
        let (a, b) = (dense.points[idx], dense.points[idx + 1]);
        let p = a + (b - a) * f;
        let d = b - a;
        out.push((p, d.y.atan2(d.x)));
    }
    Some(out)
}
