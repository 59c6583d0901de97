//! The floor beneath a position: the prior that a worn or carried rig is a known height above
//! the floor it stands on (beyond the papers; KT §5.4 fixes the height outright for a cart).
//!
//! In: the model's faces (once, at start-up) and a position. Out: the height of the highest
//! near-horizontal face below the position whose outline contains it in plan, or `None` where
//! there is none (outside the building, or a model drawn without floors).
//!
//! Why: on real photographs a wrong pose that explains as much as the truth is most often one
//! that floats: the same room seen from decimetres too high or low, or from above a ceiling or
//! outside the walls. A floor under the rig and a height above it in the band that people carry
//! rigs at refuse those, and narrow the search's height.
//!
//! Memory: the horizontal faces' plan outlines, copied at start-up; a query allocates nothing.

use crate::model::Model;
use nalgebra::{Point2, Point3};

/// Faces whose normal is within this of the vertical are floors (or ceilings): ramps and
/// shallow stairs included, roofs' steep pitches not (rad).
const MAX_SLOPE_RAD: f64 = 30.0 * std::f64::consts::PI / 180.0;
/// A floor may be this far above the queried point and still be below it (m): rounding, and
/// a point placed on the floor itself.
const ON_FLOOR_M: f64 = 0.02;
/// A floor this close in plan still counts as beneath (m): floor plans drawn room by room leave
/// no floor in a doorway through a thick wall, and a rig stands in doorways.
const REACH_M: f64 = 0.5;

struct Horizontal {
    /// Range into `Floors::outline`.
    start: usize,
    end: usize,
    lo: Point2<f64>,
    hi: Point2<f64>,
    /// Plane: z = c0 + cx·x + cy·y.
    c: [f64; 3],
}

/// The model's floors, for [`Floors::below`].
pub struct Floors {
    faces: Vec<Horizontal>,
    outline: Vec<Point2<f64>>,
}

impl Floors {
    pub fn new(model: &Model) -> Floors {
        let mut faces = Vec::new();
        let mut outline = Vec::new();
        let min_nz = MAX_SLOPE_RAD.cos();
        for f in &model.faces {
            let n = f.normal.into_inner();
            if n.z.abs() < min_nz || f.vertices.len() < 3 {
                continue;
            }
            let start = outline.len();
            let (mut lo, mut hi) = (
                Point2::new(f64::INFINITY, f64::INFINITY),
                Point2::new(f64::NEG_INFINITY, f64::NEG_INFINITY),
            );
            for &v in &f.vertices {
                let p = model.vertices[v as usize];
                let q = Point2::new(p.x, p.y);
                lo = lo.inf(&q);
                hi = hi.sup(&q);
                outline.push(q);
            }
            faces.push(Horizontal {
                start,
                end: outline.len(),
                lo,
                hi,
                c: [f.offset / n.z, -n.x / n.z, -n.y / n.z],
            });
        }
        Floors { faces, outline }
    }

    /// Whether the model has any floor at all (a model of walls alone gives no height prior).
    pub fn any(&self) -> bool {
        !self.faces.is_empty()
    }

    /// The height of the floor beneath `p`: the highest horizontal face at most [`ON_FLOOR_M`]
    /// above it whose outline contains it in plan, or passes within [`REACH_M`] of it.
    pub fn below(&self, p: &Point3<f64>) -> Option<f64> {
        let q = Point2::new(p.x, p.y);
        let mut best: Option<f64> = None;
        for f in &self.faces {
            if q.x < f.lo.x - REACH_M || q.x > f.hi.x + REACH_M || q.y < f.lo.y - REACH_M || q.y > f.hi.y + REACH_M {
                continue;
            }
            let z = f.c[0] + f.c[1] * q.x + f.c[2] * q.y;
            if z > p.z + ON_FLOOR_M || best.is_some_and(|b| z <= b) {
                continue;
            }
            let ring = &self.outline[f.start..f.end];
            if contains(ring, &q) || distance(ring, &q) <= REACH_M {
                best = Some(z);
            }
        }
        best
    }
}

impl Floors {
    /// The heights within `slab` (lowest, highest) at which a rig carried `band` above a floor
    /// can stand at plan position (`x`, `y`), or `None` where no floor beneath can carry it
    /// there.
    ///
    /// The floor is looked for at least `band[0]` below the slab's top, for a floor any higher
    /// could only carry the rig above the slab. Looked for from the slab's top itself, the
    /// answer in a room lower than the slab is that room's ceiling (a horizontal face like any
    /// floor: winding says nothing), and the search skipped every such room (the closets of the
    /// ZInD house, ceilings at 2.24 m under a slab reaching 2.25 m).
    pub fn band(&self, x: f64, y: f64, slab: [f64; 2], band: [f64; 2]) -> Option<(f64, f64)> {
        let floor = self.below(&Point3::new(x, y, slab[1] - band[0]))?;
        let (lo, hi) = ((floor + band[0]).max(slab[0]), (floor + band[1]).min(slab[1]));
        (lo <= hi).then_some((lo, hi))
    }
}

/// Even-odd rule.
fn contains(ring: &[Point2<f64>], q: &Point2<f64>) -> bool {
    let mut inside = false;
    let mut j = ring.len() - 1;
    for i in 0..ring.len() {
        let (a, b) = (ring[i], ring[j]);
        if (a.y > q.y) != (b.y > q.y) && q.x < (b.x - a.x) * (q.y - a.y) / (b.y - a.y) + a.x {
            inside = !inside;
        }
        j = i;
    }
    inside
}

/// Distance in plan from `q` to the ring's edges.
fn distance(ring: &[Point2<f64>], q: &Point2<f64>) -> f64 {
    let mut d = f64::INFINITY;
    let mut j = ring.len() - 1;
    for i in 0..ring.len() {
        let (a, b) = (ring[j], ring[i]);
        let ab = b - a;
        let t = if ab.norm_squared() > 0.0 {
            ((q - a).dot(&ab) / ab.norm_squared()).clamp(0.0, 1.0)
        } else {
            0.0
        };
        d = d.min((q - (a + ab * t)).norm());
        j = i;
    }
    d
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two storeys: a 4 × 4 floor at 0 and a 4 × 2 slab at 3 over half of it, and a wall.
    fn two_storeys() -> Model {
        let obj = "v 0 0 0\nv 4 0 0\nv 4 4 0\nv 0 4 0\n\
                   v 0 0 3\nv 4 0 3\nv 4 2 3\nv 0 2 3\n\
                   v 0 0 0\nv 0 4 0\nv 0 4 3\nv 0 0 3\n\
                   f 1 2 3 4\nf 8 7 6 5\nf 9 10 11 12\n";
        Model::from_obj_str(obj, "two.obj").unwrap()
    }

    #[test]
    fn the_floor_below_is_the_highest_face_under_the_point_and_none_outside() {
        let floors = Floors::new(&two_storeys());
        assert!(floors.any());
        assert_eq!(floors.below(&Point3::new(2.0, 3.0, 1.5)), Some(0.0));
        assert_eq!(floors.below(&Point3::new(2.0, 1.0, 1.5)), Some(0.0));
        assert_eq!(floors.below(&Point3::new(2.0, 1.0, 4.5)), Some(3.0));
        // Beside the slab, the ground floor is still below.
        assert_eq!(floors.below(&Point3::new(2.0, 3.0, 4.5)), Some(0.0));
        assert_eq!(floors.below(&Point3::new(5.0, 1.0, 1.5)), None);
        // In a doorway through a thick wall: the floor a step away.
        assert_eq!(floors.below(&Point3::new(4.3, 1.0, 1.5)), Some(0.0));
        assert_eq!(floors.below(&Point3::new(2.0, 1.0, -0.5)), None);
    }

    #[test]
    fn a_room_lower_than_the_slab_is_searched_above_its_floor_not_its_ceiling() {
        // A closet 2 × 2 m, floor at 0 and ceiling at 2.2 m, under node layers reaching 2.25 m.
        let obj = "v 0 0 0\nv 2 0 0\nv 2 2 0\nv 0 2 0\n\
                   v 0 0 2.2\nv 2 0 2.2\nv 2 2 2.2\nv 0 2 2.2\n\
                   f 1 2 3 4\nf 8 7 6 5\n";
        let floors = Floors::new(&Model::from_obj_str(obj, "closet.obj").unwrap());
        assert_eq!(floors.band(1.0, 1.0, [0.75, 2.25], [1.0, 2.0]), Some((1.0, 2.0)));
        // The ceiling is what lies highest beneath the slab's top.
        assert_eq!(floors.below(&Point3::new(1.0, 1.0, 2.25)), Some(2.2));
        // Upstairs: the upper floor carries the rig in an upper slab.
        let two = Floors::new(&two_storeys());
        assert_eq!(two.band(2.0, 1.0, [3.75, 5.25], [1.0, 2.0]), Some((4.0, 5.0)));
        assert_eq!(two.band(2.0, 3.0, [0.75, 2.25], [1.0, 2.0]), Some((1.0, 2.0)));
        // Outside the building, or a band the slab cannot hold: nothing.
        assert_eq!(two.band(6.0, 1.0, [0.75, 2.25], [1.0, 2.0]), None);
        assert_eq!(two.band(2.0, 1.0, [0.75, 0.9], [1.0, 2.0]), None);
    }

    #[test]
    fn walls_alone_are_no_floor() {
        let walls = Model::from_obj_str("v 0 0 0\nv 4 0 0\nv 4 0 3\nv 0 0 3\nf 1 2 3 4\n", "w.obj").unwrap();
        let floors = Floors::new(&walls);
        assert!(!floors.any());
        assert_eq!(floors.below(&Point3::new(1.0, 1.0, 1.0)), None);
    }
}
