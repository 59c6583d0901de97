//! The floor beneath a position: the prior that a worn or carried rig is a known height above
//! the floor it stands on (beyond the papers; KT §5.4 fixes the height outright for a cart).
//!
//! In: the model's faces (once, at start-up) and a position. Out: the height of the highest
//! near-horizontal face below the position whose outline contains it in plan (or passes near
//! it, with nothing in the way: a doorway through a thick wall), or `None` where there is none
//! (outside the building, inside a wall, or a model drawn without floors). Nothing here reads
//! the faces' winding: a floor and a ceiling are both horizontal faces, told apart only by
//! where the position stands.
//!
//! Why: on real photographs a wrong pose that explains as much as the truth is most often one
//! that floats: the same room seen from decimetres too high or low, or from above a ceiling or
//! outside the walls. A floor under the rig and a height above it in the band that people carry
//! rigs at refuse those, and narrow the search's height.
//!
//! Memory: the horizontal faces' plan outlines, copied at start-up; the step onto a floor from
//! a doorway casts a ray against the model's triangles that the caller holds (the BVH of
//! `visibility::at_pose`). A query allocates nothing.

use nalgebra::{Point2, Point3};
use omnitrack_core::model::bvh::{Ray, TriangleBvh};
use omnitrack_core::model::Model;

/// Faces whose normal is within this of the vertical are floors (or ceilings): ramps and
/// shallow stairs included, roofs' steep pitches not (rad).
const MAX_SLOPE_RAD: f64 = 30.0 * std::f64::consts::PI / 180.0;
/// A floor may be this far above the queried point and still be below it (m): rounding, and
/// a point placed on the floor itself.
const ON_FLOOR_M: f64 = 0.02;
/// A floor this close in plan still counts as beneath (m): floor plans drawn room by room leave
/// no floor in a doorway through a thick wall, and a rig stands in doorways.
const REACH_M: f64 = 0.5;
/// ... provided the rig can step onto it: the straight way from the rig to this far past the
/// floor's edge (m) meets no face of the model. A doorway passes; the inside of a wall, which
/// the floors' edges pass just as near, does not.
const STEP_PAST_M: f64 = 0.05;

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
    /// above it whose outline contains it in plan, or passes within [`REACH_M`] of it with
    /// nothing of `solid` (the model's triangles) in the way from `p` ([`STEP_PAST_M`]).
    pub fn below(&self, p: &Point3<f64>, solid: &TriangleBvh) -> Option<f64> {
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
            if contains(ring, &q) || steps_onto(ring, p, solid) {
                best = Some(z);
            }
        }
        best
    }

    /// The heights within `slab` (lowest, highest) at which a rig carried `band` above a floor
    /// can stand at plan position (`x`, `y`), or `None` where no floor beneath can carry it
    /// there.
    ///
    /// The floor is looked for at least `band[0]` below the slab's top, for a floor any higher
    /// could only carry the rig above the slab. Looked for from the slab's top itself, the
    /// answer in a room lower than the slab is that room's ceiling (a horizontal face like any
    /// floor: winding says nothing), and the search skipped every such room (the closets of the
    /// ZInD house, ceilings at 2.24 m under a slab reaching 2.25 m).
    pub fn band(&self, x: f64, y: f64, slab: [f64; 2], band: [f64; 2], solid: &TriangleBvh) -> Option<(f64, f64)> {
        let floor = self.below(&Point3::new(x, y, slab[1] - band[0]), solid)?;
        let (lo, hi) = ((floor + band[0]).max(slab[0]), (floor + band[1]).min(slab[1]));
        (lo <= hi).then_some((lo, hi))
    }
}

/// Whether a rig at `p`, outside the outline `ring` in plan, can step onto it: the ring
/// passes within [`REACH_M`] and the level way from `p` to [`STEP_PAST_M`] beyond its
/// nearest point crosses no face (a doorway, not the inside of a wall: the walls around a
/// room stand on its outline). Only the way to the nearest point is tried: in a doorway
/// that is straight through the opening, except within a few centimetres of a jamb at a
/// room's corner.
fn steps_onto(ring: &[Point2<f64>], p: &Point3<f64>, solid: &TriangleBvh) -> bool {
    let q = Point2::new(p.x, p.y);
    let (near, d) = nearest(ring, &q);
    if d > REACH_M {
        return false;
    }
    if d < 1e-9 {
        return true;
    }
    let dir = (near - q) / d;
    let length = d + STEP_PAST_M;
    let ray = Ray::new([p.x as f32, p.y as f32, p.z as f32], [dir.x as f32, dir.y as f32, 0.0]);
    !solid.occluded(&ray, 1e-4, length as f32)
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

/// The point of the ring's edges nearest `q` in plan, and its distance.
fn nearest(ring: &[Point2<f64>], q: &Point2<f64>) -> (Point2<f64>, f64) {
    let mut best = (ring[0], f64::INFINITY);
    let mut j = ring.len() - 1;
    for i in 0..ring.len() {
        let (a, b) = (ring[j], ring[i]);
        let ab = b - a;
        let t = if ab.norm_squared() > 0.0 {
            ((q - a).dot(&ab) / ab.norm_squared()).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let r = a + ab * t;
        let d = (q - r).norm();
        if d < best.1 {
            best = (r, d);
        }
        j = i;
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::visibility::at_pose::PoseVisibility;

    /// The floors of `model` and its triangles, as the initialisation holds them.
    fn floors_of(model: &Model) -> (Floors, TriangleBvh) {
        (Floors::new(model), PoseVisibility::new(model).solid().clone())
    }

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
        let (floors, solid) = floors_of(&two_storeys());
        assert!(floors.any());
        assert_eq!(floors.below(&Point3::new(2.0, 3.0, 1.5), &solid), Some(0.0));
        assert_eq!(floors.below(&Point3::new(2.0, 1.0, 1.5), &solid), Some(0.0));
        assert_eq!(floors.below(&Point3::new(2.0, 1.0, 4.5), &solid), Some(3.0));
        // Beside the slab, the ground floor is still below.
        assert_eq!(floors.below(&Point3::new(2.0, 3.0, 4.5), &solid), Some(0.0));
        assert_eq!(floors.below(&Point3::new(5.0, 1.0, 1.5), &solid), None);
        // In a doorway through a thick wall: the floor a step away.
        assert_eq!(floors.below(&Point3::new(4.3, 1.0, 1.5), &solid), Some(0.0));
        assert_eq!(floors.below(&Point3::new(2.0, 1.0, -0.5), &solid), None);
    }

    #[test]
    fn a_room_lower_than_the_slab_is_searched_above_its_floor_not_its_ceiling() {
        // A closet 2 × 2 m, floor at 0 and ceiling at 2.2 m, under node layers reaching 2.25 m.
        let obj = "v 0 0 0\nv 2 0 0\nv 2 2 0\nv 0 2 0\n\
                   v 0 0 2.2\nv 2 0 2.2\nv 2 2 2.2\nv 0 2 2.2\n\
                   f 1 2 3 4\nf 8 7 6 5\n";
        let (floors, solid) = floors_of(&Model::from_obj_str(obj, "closet.obj").unwrap());
        assert_eq!(
            floors.band(1.0, 1.0, [0.75, 2.25], [1.0, 2.0], &solid),
            Some((1.0, 2.0))
        );
        // The ceiling is what lies highest beneath the slab's top.
        assert_eq!(floors.below(&Point3::new(1.0, 1.0, 2.25), &solid), Some(2.2));
        // Upstairs: the upper floor carries the rig in an upper slab.
        let (two, two_solid) = floors_of(&two_storeys());
        assert_eq!(
            two.band(2.0, 1.0, [3.75, 5.25], [1.0, 2.0], &two_solid),
            Some((4.0, 5.0))
        );
        assert_eq!(
            two.band(2.0, 3.0, [0.75, 2.25], [1.0, 2.0], &two_solid),
            Some((1.0, 2.0))
        );
        // Outside the building, or a band the slab cannot hold: nothing.
        assert_eq!(two.band(6.0, 1.0, [0.75, 2.25], [1.0, 2.0], &two_solid), None);
        assert_eq!(two.band(2.0, 1.0, [0.75, 0.9], [1.0, 2.0], &two_solid), None);
    }

    /// Two rooms 2 m square, floors drawn room by room, a 0.2 m wall between them (its two faces
    /// on the rooms' outlines) with a doorway from y = 0.8 to 1.6, 2 m high.
    fn doorway() -> Model {
        let mut obj = String::from(
            "v 0 0 0\nv 2 0 0\nv 2 2 0\nv 0 2 0\nv 2.2 0 0\nv 4.2 0 0\nv 4.2 2 0\nv 2.2 2 0\nf 1 2 3 4\nf 5 6 7 8\n",
        );
        let mut n = 8;
        for x in [2.0, 2.2] {
            for (y0, y1, z0, z1) in [(0.0, 0.8, 0.0, 2.5), (1.6, 2.0, 0.0, 2.5), (0.8, 1.6, 2.0, 2.5)] {
                obj += &format!("v {x} {y0} {z0}\nv {x} {y1} {z0}\nv {x} {y1} {z1}\nv {x} {y0} {z1}\n");
                obj += &format!("f {} {} {} {}\n", n + 1, n + 2, n + 3, n + 4);
                n += 4;
            }
        }
        Model::from_obj_str(&obj, "doorway.obj").unwrap()
    }

    #[test]
    fn a_doorway_through_a_thick_wall_has_a_floor_and_the_inside_of_the_wall_has_none() {
        let (floors, solid) = floors_of(&doorway());
        assert_eq!(floors.below(&Point3::new(2.1, 1.2, 1.4), &solid), Some(0.0));
        assert_eq!(floors.below(&Point3::new(2.1, 0.4, 1.4), &solid), None);
        assert_eq!(floors.below(&Point3::new(2.1, 1.9, 1.4), &solid), None);
        // Above the doorway's head the wall is solid again.
        assert_eq!(floors.below(&Point3::new(2.1, 1.2, 2.2), &solid), None);
        // Inside either room, and beside the building within reach with nothing in the way.
        assert_eq!(floors.below(&Point3::new(1.0, 0.4, 1.4), &solid), Some(0.0));
        assert_eq!(floors.below(&Point3::new(-0.3, 1.0, 1.4), &solid), Some(0.0));
    }

    #[test]
    fn walls_alone_are_no_floor() {
        let walls = Model::from_obj_str("v 0 0 0\nv 4 0 0\nv 4 0 3\nv 0 0 3\nf 1 2 3 4\n", "w.obj").unwrap();
        let (floors, solid) = floors_of(&walls);
        assert!(!floors.any());
        assert_eq!(floors.below(&Point3::new(1.0, 1.0, 1.0), &solid), None);
    }
}
