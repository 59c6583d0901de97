//! Ear clipping of planar polygons (simple, possibly non-convex, counter-clockwise about a normal).
//!
//! In: a polygon's 3D corners and its normal. Out: `n − 2` triangles as index triples into the
//! corners, counter-clockwise about the same normal, covering the polygon exactly.

use nalgebra::{Point2, Point3, Vector3};

/// Triangulates a planar polygon given in 3D: its corners are expressed in an orthonormal basis
/// (u, v) of its plane with u × v = `normal`, so a polygon counter-clockwise about `normal` stays
/// counter-clockwise in 2D, then clipped with [`ear_clip`].
pub fn triangulate_polygon(corners: &[Point3<f64>], normal: &Vector3<f64>) -> Vec<[usize; 3]> {
    let n = normal.normalize();
    let helper = if n.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
    let u = n.cross(&helper).normalize();
    let v = n.cross(&u);
    let pts: Vec<Point2<f64>> = corners
        .iter()
        .map(|p| Point2::new(p.coords.dot(&u), p.coords.dot(&v)))
        .collect();
    ear_clip(&pts)
}

/// Twice the signed area of a 2D polygon (positive when counter-clockwise).
pub fn signed_area2(pts: &[Point2<f64>]) -> f64 {
    let n = pts.len();
    (0..n)
        .map(|i| {
            let (a, b) = (pts[i], pts[(i + 1) % n]);
            a.x * b.y - a.y * b.x
        })
        .sum()
}

fn cross(o: Point2<f64>, a: Point2<f64>, b: Point2<f64>) -> f64 {
    (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x)
}

/// Ear clipping of a simple 2D polygon (either orientation). Returns `n − 2` index triples for
/// `n ≥ 3` corners, oriented like the input polygon; collinear corners give zero-area triangles
/// (harmless to a ray caster, and they keep the count at `n − 2`). If no ear can be found (a
/// self-intersecting or numerically degenerate polygon) the remainder is fanned.
pub fn ear_clip(pts: &[Point2<f64>]) -> Vec<[usize; 3]> {
    let n = pts.len();
    if n < 3 {
        return Vec::new();
    }
    let mut out = Vec::with_capacity(n - 2);
    let ccw = signed_area2(pts) >= 0.0;
    // Work on a counter-clockwise index ring; emit triangles in the input orientation.
    let mut ring: Vec<usize> = if ccw { (0..n).collect() } else { (0..n).rev().collect() };
    let scale = pts
        .iter()
        .fold(0.0f64, |m, p| m.max(p.x.abs()).max(p.y.abs()))
        .max(1e-300);
    let eps = 1e-12 * scale * scale;
    let emit = |out: &mut Vec<[usize; 3]>, a: usize, b: usize, c: usize| {
        out.push(if ccw { [a, b, c] } else { [a, c, b] });
    };
    while ring.len() > 3 {
        let m = ring.len();
        let mut clipped = None;
        // First pass: a strictly convex ear with no other corner in or on it.
        for i in 0..m {
            let (ia, ib, ic) = (ring[(i + m - 1) % m], ring[i], ring[(i + 1) % m]);
            let (a, b, c) = (pts[ia], pts[ib], pts[ic]);
            if cross(a, b, c) <= eps {
                continue;
            }
            let blocked = ring.iter().any(|&j| {
                if j == ia || j == ib || j == ic {
                    return false;
                }
                let p = pts[j];
                if p == a || p == b || p == c {
                    return false;
                }
                cross(a, b, p) >= -eps && cross(b, c, p) >= -eps && cross(c, a, p) >= -eps
            });
            if !blocked {
                clipped = Some(i);
                break;
            }
        }
        // Second pass: a collinear (flat) corner can go as a zero-area triangle.
        if clipped.is_none() {
            clipped = (0..m).find(|&i| {
                let (a, b, c) = (pts[ring[(i + m - 1) % m]], pts[ring[i]], pts[ring[(i + 1) % m]]);
                cross(a, b, c).abs() <= eps
            });
        }
        let i = clipped.unwrap_or(0);
        let (ia, ib, ic) = (ring[(i + m - 1) % m], ring[i], ring[(i + 1) % m]);
        emit(&mut out, ia, ib, ic);
        ring.remove(i);
    }
    emit(&mut out, ring[0], ring[1], ring[2]);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn area(pts: &[Point2<f64>], tris: &[[usize; 3]]) -> f64 {
        tris.iter().map(|t| cross(pts[t[0]], pts[t[1]], pts[t[2]]) / 2.0).sum()
    }

    #[test]
    fn comb_is_covered() {
        // A comb: many reflex corners.
        let mut pts = vec![Point2::new(0.0, 0.0), Point2::new(10.0, 0.0)];
        for k in (0..5).rev() {
            let x = 2.0 * k as f64;
            pts.push(Point2::new(x + 2.0, 3.0));
            pts.push(Point2::new(x + 1.0, 3.0));
            pts.push(Point2::new(x + 1.0, 1.0));
            pts.push(Point2::new(x, 1.0));
        }
        pts.pop();
        pts.push(Point2::new(0.0, 3.0));
        let tris = ear_clip(&pts);
        assert_eq!(tris.len(), pts.len() - 2);
        assert!((area(&pts, &tris) - signed_area2(&pts) / 2.0).abs() < 1e-9);
        assert!(tris.iter().all(|t| cross(pts[t[0]], pts[t[1]], pts[t[2]]) >= -1e-12));
        let rev: Vec<_> = pts.iter().rev().copied().collect();
        let tris = ear_clip(&rev);
        assert!((area(&rev, &tris) - signed_area2(&rev) / 2.0).abs() < 1e-9);
    }
}
