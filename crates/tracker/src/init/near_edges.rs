//! The directions near some edge of the frame, per sensor: [`Candidate::blank`](super::Candidate::blank)'s
//! test as a table look-up, so that the grid's coarse merit can afford it at every position.
//!
//! In: a frame's edges and the blank radius. Out: a [`NearEdges`], asked "does an edge of
//! sensor s run within the radius of this direction from s's centre?".
//!
//! **Why.** The grid ranks its positions by explained × support, and on real photographs the
//! truth's neighbourhood can rank below twins that line a few long segments up with texture and
//! draw the rest across plain wall: ZInD `pano_13` from the 3 m hint, coarse merit 0.331 at the
//! truth against 0.400 for the best kept position. The final merit has the blank term that
//! tells them apart, but it costs points × edges plane tests, a millisecond or two per pose,
//! where the grid scores thousands. With this map the grid can rank by the same three factors
//! (`initialisation.grid_blank`: in a bounded volume's search by default, not the whole
//! model's; measured, and why: docs/decisions.md, 2026-11-30).
//!
//! **How.** One cube map of directions per sensor (from that sensor's centre: sensors of a
//! backpack rig may stand decimetres apart), [`FACE_CELLS`]² cells per face, one bit per cell.
//! Each edge marks the band about its arc: along it from `radius` before its first end to
//! `radius` past its last, across it `radius` either side, in steps below the smallest cell.
//! That band holds every direction [`Candidate::blank`](super::Candidate::blank)'s test calls
//! near (within the radius of the plane, the two end angles summing to at most the edge's
//! length plus twice the radius) and a little more at the band's corners and by the cells'
//! size (under a degree): a coarse test that never calls a near direction blank.
//!
//! Fixed memory: sized in [`NearEdges::new`]; [`NearEdges::build`] allocates nothing.

use nalgebra::{Point3, Vector3};
use omnitrack_core::memory::resident;
use omnitrack_core::rig::view::cube_cell;
use omnitrack_edges::Edge;

/// Cells along each edge of a cube face: 0.9° at a face's centre, 0.42° at its corners.
pub const FACE_CELLS: usize = 128;
/// The marking's step along and across an edge (rad): a square lattice of step h has a point
/// in every square cell wider than h√2 however the cell is turned, and the smallest cells
/// are 0.42° wide, so the band has no holes.
const STEP_RAD: f64 = 0.28 * std::f64::consts::PI / 180.0;
const WORDS_PER_SENSOR: usize = 6 * FACE_CELLS * FACE_CELLS / 64;

/// Per sensor, the cube map of the directions within the radius of one of its edges.
pub struct NearEdges {
    bits: Vec<u64>,
    sensors: usize,
    /// Cells marked in the last build (counted with repeats): its cost.
    marks: u64,
}

impl NearEdges {
    /// A map for `sensors` sensors, empty.
    pub fn new(sensors: usize) -> NearEdges {
        NearEdges {
            bits: resident(vec![0; sensors * WORDS_PER_SENSOR]),
            sensors,
            marks: 0,
        }
    }

    /// Marks the directions within `radius_rad` of each of `edges` (edges of sensors beyond
    /// the map's are left out). A radius of 0 marks nothing.
    pub fn build(&mut self, edges: &[Edge], radius_rad: f64) {
        self.bits.fill(0);
        self.marks = 0;
        if radius_rad <= 0.0 {
            return;
        }
        let across = (2.0 * radius_rad / STEP_RAD).ceil() as usize;
        let across_step = 2.0 * radius_rad / across as f64;
        for e in edges {
            let s = usize::from(e.sensor);
            if s >= self.sensors {
                continue;
            }
            let n = e.plane.normal.into_inner();
            let start = e.plane.ends[0].into_inner();
            // The direction in the plane a quarter turn on from the first end, towards the last.
            // (The normal's sign carries no meaning, so the last end says which way.)
            let Some(mut toward) = n.cross(&start).try_normalize(1e-12) else {
                continue;
            };
            if toward.dot(&e.plane.ends[1]) < 0.0 {
                toward = -toward;
            }
            let span = e.length_rad + 2.0 * radius_rad;
            let along = (span / STEP_RAD).ceil() as usize;
            let along_step = span / along as f64;
            let words = &mut self.bits[s * WORDS_PER_SENSOR..(s + 1) * WORDS_PER_SENSOR];
            // Both angles stepped by rotation (a sine and a cosine per step, not per mark):
            // over at most a few hundred steps the drift stays far below a cell.
            let (along_sin, along_cos) = along_step.sin_cos();
            let (across_sin, across_cos) = across_step.sin_cos();
            let (r_sin, r_cos) = radius_rad.sin_cos();
            let (mut t_cos, mut t_sin) = (r_cos, -r_sin);
            for _ in 0..=along {
                let a = start * t_cos + toward * t_sin;
                let (mut u_cos, mut u_sin) = (r_cos, -r_sin);
                for _ in 0..=across {
                    let d = a * u_cos + n * u_sin;
                    if let Some(c) = cube_cell(&d, FACE_CELLS) {
                        words[c / 64] |= 1 << (c % 64);
                    }
                    (u_cos, u_sin) = (
                        u_cos * across_cos - u_sin * across_sin,
                        u_sin * across_cos + u_cos * across_sin,
                    );
                }
                (t_cos, t_sin) = (
                    t_cos * along_cos - t_sin * along_sin,
                    t_sin * along_cos + t_cos * along_sin,
                );
            }
            self.marks += ((along + 1) * (across + 1)) as u64;
        }
    }

    /// Whether an edge of some sensor runs near the point `p` (rig frame), seen from that
    /// sensor's centre (`centres`, one per sensor of the map).
    #[inline]
    pub fn near_point(&self, p: &Vector3<f64>, centres: &[Point3<f64>]) -> bool {
        centres
            .iter()
            .take(self.sensors)
            .enumerate()
            .any(|(s, c)| self.near(s, &(p - c.coords)))
    }

    /// Whether an edge of sensor `s` runs near the direction `d` (from its centre, rig frame).
    #[inline]
    pub fn near(&self, s: usize, d: &Vector3<f64>) -> bool {
        s < self.sensors
            && cube_cell(d, FACE_CELLS).is_some_and(|c| self.bits[s * WORDS_PER_SENSOR + c / 64] & (1 << (c % 64)) != 0)
    }

    /// Cells marked by the last [`Self::build`], repeats included: what it cost.
    pub fn marks(&self) -> u64 {
        self.marks
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use omnitrack_core::geometry::EdgePlane;

    fn edge(sensor: u8, a: Vector3<f64>, b: Vector3<f64>) -> Edge {
        crate::test_edges::edge_on(sensor, EdgePlane::from_rays(Point3::origin(), &a, &b).unwrap(), 10)
    }

    /// Blank's own test (`Initialiser::blank_share`): within `r` of the plane, and the end
    /// angles summing to at most the length plus 2r.
    fn exact(e: &Edge, d: &Vector3<f64>, r: f64) -> bool {
        let d = d.normalize();
        let a0 = e.plane.ends[0].dot(&d).clamp(-1.0, 1.0).acos();
        let a1 = e.plane.ends[1].dot(&d).clamp(-1.0, 1.0).acos();
        e.plane.normal.dot(&d).abs() <= r.sin() && a0 + a1 - e.length_rad <= 2.0 * r
    }

    #[test]
    fn every_direction_near_an_edge_is_marked_and_far_ones_are_not() {
        let r = 2f64.to_radians();
        // Edges across face borders and corners, short and long, on two sensors.
        let edges = [
            edge(0, Vector3::new(1.0, -0.3, 0.2), Vector3::new(1.0, 0.9, 1.1)),
            edge(0, Vector3::new(0.2, 1.0, -1.0), Vector3::new(-0.7, 1.0, -0.95)),
            edge(1, Vector3::new(0.0, 0.05, 1.0), Vector3::new(0.02, -0.03, 1.0)),
            edge(1, Vector3::new(-1.0, -1.0, -1.0), Vector3::new(-1.0, -0.8, -1.2)),
        ];
        let mut map = NearEdges::new(2);
        map.build(&edges, r);
        // Directions sampled over the sphere (a Fibonacci lattice), tested against each sensor.
        let (mut near, mut missed, mut far_marked) = (0, 0, 0);
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        for k in 0..200_000 {
            let z = 1.0 - 2.0 * (k as f64 + 0.5) / 200_000.0;
            let rho = (1.0 - z * z).sqrt();
            let d = Vector3::new(rho * (golden * k as f64).cos(), rho * (golden * k as f64).sin(), z);
            for s in 0..2u8 {
                let mine: Vec<_> = edges.iter().filter(|e| e.sensor == s).collect();
                let truth = mine.iter().any(|e| exact(e, &d, r));
                // Far: more than the radius and a cell and a half from every edge's band.
                let far = !mine.iter().any(|e| exact(e, &d, r + 1.4f64.to_radians()));
                let marked = map.near(usize::from(s), &d);
                near += usize::from(truth);
                missed += usize::from(truth && !marked);
                far_marked += usize::from(far && marked);
            }
        }
        assert!(
            near > 500,
            "{near} directions near an edge: the test samples too sparsely"
        );
        assert_eq!(missed, 0, "{missed} of {near} directions near an edge were not marked");
        assert_eq!(far_marked, 0, "{far_marked} directions far from every edge were marked");
    }

    #[test]
    fn a_point_is_seen_from_each_sensors_own_centre() {
        // Two sensors 0.3 m apart along y; sensor 1 sees an edge straight ahead (along x).
        let centres = [Point3::new(0.0, 0.15, 0.0), Point3::new(0.0, -0.15, 0.0)];
        let e = edge(1, Vector3::new(1.0, 0.0, -0.05), Vector3::new(1.0, 0.0, 0.05));
        let mut map = NearEdges::new(2);
        map.build(&[e], 1f64.to_radians());
        // A point 2 m ahead of sensor 1 is near its edge; seen from the rig's origin it is
        // 4.3° off, and from sensor 0 8.5° off.
        let p = Vector3::new(2.0, -0.15, 0.0);
        assert!(map.near_point(&p, &centres));
        assert!(!map.near(1, &p) && !map.near(0, &(p - centres[0].coords)));
        assert!(!map.near_point(&Vector3::new(2.0, 0.15, 0.0), &centres));
    }

    #[test]
    fn no_radius_marks_nothing() {
        let mut map = NearEdges::new(1);
        map.build(&[edge(0, Vector3::x(), Vector3::y())], 0.0);
        assert!(!map.near(0, &Vector3::new(1.0, 1.0, 0.0)));
        assert_eq!(map.marks(), 0);
    }
}
