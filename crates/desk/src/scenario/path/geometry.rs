//! Plane geometry for paths: points, segments and polygons in (metres, the plan's x–y),
//! distances, crossings, areas and containment out.

use super::{P2, V2};

/// A point within this of a room's outline counts as inside it (door centres lie on outlines).
const ROOM_TOLERANCE_M: f64 = 0.02;

pub(super) fn seg_point_dist(a: P2, b: P2, p: P2) -> f64 {
    let ab = b - a;
    let l2 = ab.norm_squared();
    let t = if l2 > 0.0 {
        ((p - a).dot(&ab) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (a + ab * t - p).norm()
}

pub(super) fn cross(a: V2, b: V2) -> f64 {
    a.x * b.y - a.y * b.x
}

pub(super) fn segments_intersect(a: P2, b: P2, c: P2, d: P2) -> bool {
    let d1 = cross(b - a, c - a);
    let d2 = cross(b - a, d - a);
    let d3 = cross(d - c, a - c);
    let d4 = cross(d - c, b - c);
    ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0)) && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
}

/// Distance between two 2D segments.
pub(super) fn seg_seg_dist(a: P2, b: P2, c: P2, d: P2) -> f64 {
    if segments_intersect(a, b, c, d) {
        return 0.0;
    }
    seg_point_dist(a, b, c)
        .min(seg_point_dist(a, b, d))
        .min(seg_point_dist(c, d, a))
        .min(seg_point_dist(c, d, b))
}

pub(super) fn point_in_polygon(poly: &[P2], p: P2) -> bool {
    let mut inside = false;
    let n = poly.len();
    let mut j = n - 1;
    for i in 0..n {
        let (pi, pj) = (poly[i], poly[j]);
        if (pi.y > p.y) != (pj.y > p.y) && p.x < (pj.x - pi.x) * (p.y - pi.y) / (pj.y - pi.y) + pi.x {
            inside = !inside;
        }
        j = i;
    }
    inside
}

pub(super) fn polygon_boundary_dist(poly: &[P2], p: P2) -> f64 {
    (0..poly.len())
        .map(|i| seg_point_dist(poly[i], poly[(i + 1) % poly.len()], p))
        .fold(f64::INFINITY, f64::min)
}

/// Area of a simple polygon (shoelace), positive whatever the orientation.
pub fn polygon_area(poly: &[P2]) -> f64 {
    let n = poly.len();
    (0..n)
        .map(|i| cross(poly[i].coords, poly[(i + 1) % n].coords))
        .sum::<f64>()
        .abs()
        / 2.0
}

pub(super) fn in_rooms(outlines: &[Vec<P2>], p: P2) -> bool {
    outlines
        .iter()
        .any(|o| point_in_polygon(o, p) || polygon_boundary_dist(o, p) < ROOM_TOLERANCE_M)
}

pub(super) fn turn_angle(a: P2, b: P2, c: P2) -> f64 {
    let (u, v) = (b - a, c - b);
    if u.norm() < 1e-9 || v.norm() < 1e-9 {
        return 0.0;
    }
    cross(u, v).atan2(u.dot(&v)).abs()
}

pub(super) fn length(poly: &[P2]) -> f64 {
    poly.windows(2).map(|w| (w[1] - w[0]).norm()).sum()
}
