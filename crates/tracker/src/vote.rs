//! Translation by voting, once a rotation is known: a second way for the initialisation to
//! find poses, beside the triplet sampling of Figure 4.
//!
//! In: a rotation hypothesis R (`T_world_rig`'s rotation), the frame's strongest edges, the
//! model segments visible from a search volume, a plan grid over the volume. Out: the few plan
//! positions (x, y) that the most edges agree on, for [`super::Initialiser`] to polish from
//! each node height and score.
//!
//! Why: the triplet sampling finds the rotation far more reliably than the translation. In a
//! corridor of evenly spaced doors it lands on the right heading (or the 180° twin of a
//! symmetric corridor) a door or two away, and those poses explain half of what the true pose
//! explains (measured on `corridor`: truncated ξ 2.8–3.4·10⁻⁴ against 1–2·10⁻⁴ at the truth,
//! which polishing reaches from any start nearby). With R fixed, pairing an edge (world normal
//! n = R n_rig, sensor centre t + R c) with a segment lying in its plane (n ⟂ the segment's
//! direction) puts the translation on the plane n · t = n · (A − R c), A any point of the
//! segment. For edges whose planes are vertical (upright structure: door jambs, corners) that
//! is a line in the plan whatever the height, so a Hough vote over a plan grid, each edge
//! voting at most once per cell and only where the segment overlaps the edge along their
//! plane, finds where the most edges have a segment, however repetitive the structure. The
//! height is left to the polish: a plan position a cell off moves a shallow plane's height by
//! decimetres, so horizontal lines vote for heights poorly.
//!
//! Fixed memory: the grid (at most [`MAX_XY`]² cells) and the segment list are sized at
//! start-up; a larger volume gets coarser cells.

use nalgebra::{Point3, Translation3, UnitQuaternion, Vector3};
use omnitrack_core::geometry::Pose;
use omnitrack_core::memory::resident;
use omnitrack_core::model::Model;
use omnitrack_edges::Edge;

/// Grid cells per plan axis, at most.
pub(super) const MAX_XY: usize = 64;
/// Finest cell (m): about the basin of the polish's widest gate at a few metres.
const CELL_M: f64 = 0.1;
/// A segment lies in an edge's plane when its direction is within this of the plane (rad):
/// rotation hypotheses are a fraction of a degree off.
const IN_PLANE_RAD: f64 = 2.0 * std::f64::consts::PI / 180.0;
/// Peaks returned per rotation, at least this far apart (m), with at least this many edges.
pub(super) const PEAKS: usize = 3;
const PEAK_SEPARATION_M: f64 = 0.5;
const MIN_VOTES: u16 = 6;
/// Edge planes this close to vertical (rad) vote.
const VERTICAL_PLANE_RAD: f64 = 5.0 * std::f64::consts::PI / 180.0;

/// Whether the segment (world end points `a`, `b`), seen from the sensor centre `c`, overlaps
/// the edge (world unit end rays `e1`, `e2`, plane normal `n`) along their common plane: a
/// pairing that only shares the plane, somewhere else along it, votes for nothing.
fn overlaps(
    n: &Vector3<f64>,
    e1: &Vector3<f64>,
    e2: &Vector3<f64>,
    a: &Vector3<f64>,
    b: &Vector3<f64>,
    c: &Vector3<f64>,
) -> bool {
    let u2 = n.cross(e1);
    let angle = |v: &Vector3<f64>| v.dot(&u2).atan2(v.dot(e1));
    let (lo_e, hi_e) = {
        let t = angle(e2);
        (t.min(0.0), t.max(0.0))
    };
    let (sa, sb) = (angle(&(a - c)), angle(&(b - c)));
    if (sa - sb).abs() > std::f64::consts::PI {
        // The segment's interval wraps through the back: it surrounds the sensor.
        return false;
    }
    sa.max(sb) > lo_e && sa.min(sb) < hi_e
}

/// The plan square searched, its cells, and the height the few non-vertical planes' small
/// rise is taken at.
#[derive(Debug, Clone, Copy)]
pub(super) struct Grid {
    lo: [f64; 2],
    cell: f64,
    n: usize,
    z: f64,
}

impl Grid {
    /// The square of side `diameter` about `centre` (height `centre.z`).
    pub fn new(centre: &Point3<f64>, diameter: f64) -> Grid {
        let n = ((diameter / CELL_M).ceil() as usize).clamp(1, MAX_XY);
        Grid {
            lo: [centre.x - 0.5 * diameter, centre.y - 0.5 * diameter],
            cell: diameter / n as f64,
            n,
            z: centre.z,
        }
    }

    fn centre_of(&self, x: usize, y: usize) -> Vector3<f64> {
        Vector3::new(
            self.lo[0] + (x as f64 + 0.5) * self.cell,
            self.lo[1] + (y as f64 + 0.5) * self.cell,
            self.z,
        )
    }
}

/// The voting buffers, sized once.
pub(super) struct TranslationVote {
    count: Vec<u16>,
    /// The last edge (1-based) that voted for each cell: one vote per edge and cell.
    stamp: Vec<u16>,
    /// Segments visible from the volume, and a per-model-segment mark to collect them once.
    pub segs: Vec<u32>,
    seen: Vec<u32>,
    mark: u32,
}

impl TranslationVote {
    pub fn new(model_segments: usize) -> TranslationVote {
        let cells = MAX_XY * MAX_XY;
        TranslationVote {
            count: resident(vec![0; cells]),
            stamp: resident(vec![0; cells]),
            segs: resident(Vec::with_capacity(model_segments)),
            seen: resident(vec![0; model_segments]),
            mark: 0,
        }
    }

    /// Starts a new segment list.
    pub fn clear_segments(&mut self) {
        self.segs.clear();
        self.mark = self.mark.wrapping_add(1);
        if self.mark == 0 {
            self.seen.iter_mut().for_each(|m| *m = 0);
            self.mark = 1;
        }
    }

    /// Adds segments (each once).
    pub fn add_segments(&mut self, ids: &[u32]) {
        for &s in ids {
            if let Some(m) = self.seen.get_mut(s as usize) {
                if *m != self.mark {
                    *m = self.mark;
                    self.segs.push(s);
                }
            }
        }
    }

    /// Votes for the plan positions of `grid` under rotation `rotation`; writes up to
    /// [`PEAKS`] poses (rotation, plan position, the grid's height), most votes first, into
    /// `out` and returns how many.
    pub fn run(
        &mut self,
        model: &Model,
        edges: &[Edge],
        rotation: &UnitQuaternion<f64>,
        grid: &Grid,
        out: &mut [(u16, Pose); PEAKS],
    ) -> usize {
        let n_cells = grid.n * grid.n;
        self.count[..n_cells].iter_mut().for_each(|c| *c = 0);
        self.stamp[..n_cells].iter_mut().for_each(|c| *c = 0);
        let sin_in_plane = IN_PLANE_RAD.sin();
        let sin_vertical = VERTICAL_PLANE_RAD.sin();
        for (ei, e) in edges.iter().enumerate().take(u16::MAX as usize - 1) {
            let stamp = ei as u16 + 1;
            let n = rotation * e.plane.normal.into_inner();
            if n.z.abs() > sin_vertical {
                continue;
            }
            let offset = rotation * e.plane.centre.coords;
            let (e1, e2) = (
                rotation * e.plane.ends[0].into_inner(),
                rotation * e.plane.ends[1].into_inner(),
            );
            // Rasterise the line n_x x + n_y y = d along its steeper axis k.
            let (k, i) = if n.x.abs() >= n.y.abs() { (0, 1) } else { (1, 0) };
            for &s in &self.segs {
                let seg = &model.segments[s as usize];
                let dir = seg.b - seg.a;
                let len = dir.norm();
                if len < 1e-9 || n.dot(&dir).abs() > sin_in_plane * len {
                    continue;
                }
                let mid = (seg.a.coords + seg.b.coords) * 0.5;
                // n · (A − R c − t) = 0, the small n_z t_z taken at the grid's height.
                let d = n.dot(&(mid - offset)) - n.z * grid.z;
                for a in 0..grid.n {
                    let ti = grid.lo[i] + (a as f64 + 0.5) * grid.cell;
                    let tk = (d - n[i] * ti) / n[k];
                    // The two cells nearest the line: the rotation hypothesis and the edge
                    // normals are a fraction of a degree off, centimetres at a few metres.
                    let c = ((tk - grid.lo[k]) / grid.cell).round() as i64;
                    let cell_of = |ck: i64| {
                        (0..grid.n as i64).contains(&ck).then(|| {
                            let mut idx = [0usize; 2];
                            idx[i] = a;
                            idx[k] = ck as usize;
                            idx[1] * grid.n + idx[0]
                        })
                    };
                    let cells = [cell_of(c - 1), cell_of(c)];
                    if cells.iter().flatten().all(|&cell| self.stamp[cell] == stamp) {
                        continue;
                    }
                    let mut t = Vector3::new(0.0, 0.0, grid.z);
                    t[i] = ti;
                    t[k] = tk;
                    if !overlaps(&n, &e1, &e2, &seg.a.coords, &seg.b.coords, &(t + offset)) {
                        continue;
                    }
                    for cell in cells.into_iter().flatten() {
                        if self.stamp[cell] != stamp {
                            self.stamp[cell] = stamp;
                            self.count[cell] = self.count[cell].saturating_add(1);
                        }
                    }
                }
            }
        }
        self.peaks(rotation, grid, out)
    }

    /// The best-voted cells, at least [`PEAK_SEPARATION_M`] apart.
    fn peaks(&self, rotation: &UnitQuaternion<f64>, grid: &Grid, out: &mut [(u16, Pose); PEAKS]) -> usize {
        let mut found = 0;
        let mut centres = [Vector3::zeros(); PEAKS];
        while found < PEAKS {
            let mut best: Option<(u16, Vector3<f64>)> = None;
            for y in 0..grid.n {
                for x in 0..grid.n {
                    let v = self.count[y * grid.n + x];
                    if v < MIN_VOTES || best.is_some_and(|(b, _)| v <= b) {
                        continue;
                    }
                    let p = grid.centre_of(x, y);
                    if centres[..found].iter().any(|c| (c - p).norm() < PEAK_SEPARATION_M) {
                        continue;
                    }
                    best = Some((v, p));
                }
            }
            let Some((v, p)) = best else { break };
            centres[found] = p;
            out[found] = (v, Pose::from_parts(Translation3::from(p), *rotation));
            found += 1;
        }
        found
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Unit;
    use omnitrack_core::geometry::EdgePlane;
    use omnitrack_core::model::{ModelStats, Segment};

    /// Upright posts (floor to 2.5 m) at irregular plan positions.
    fn posts() -> Model {
        let at = [
            (2.0, 0.5),
            (-1.5, 2.5),
            (3.5, -2.0),
            (-3.0, -1.0),
            (0.5, 3.5),
            (-0.5, -3.5),
            (4.0, 2.2),
            (-4.2, 1.7),
            (1.2, -2.7),
            (-2.2, -3.1),
        ];
        Model {
            vertices: vec![],
            faces: vec![],
            segments: at
                .iter()
                .map(|&(x, y)| Segment {
                    a: Point3::new(x, y, 0.0),
                    b: Point3::new(x, y, 2.5),
                    faces: vec![],
                })
                .collect(),
            labels: vec![String::new()],
            stats: ModelStats::default(),
        }
    }

    /// The edges a rig with one centred sensor at `pose` sees of every segment.
    fn edges_seen(model: &Model, pose: &Pose) -> Vec<Edge> {
        let inv = pose.inverse();
        model
            .segments
            .iter()
            .map(|s| {
                let (a, b) = ((inv * s.a).coords.normalize(), (inv * s.b).coords.normalize());
                let plane = EdgePlane {
                    normal: Unit::new_normalize(a.cross(&b)),
                    centre: Point3::origin(),
                    ends: [Unit::new_normalize(a), Unit::new_normalize(b)],
                };
                crate::test_edges::edge_on(0, plane, 100)
            })
            .collect()
    }

    fn vote(model: &Model, edges: &[Edge], rotation: &UnitQuaternion<f64>, centre: &Point3<f64>) -> Vec<(u16, Pose)> {
        let mut v = TranslationVote::new(model.segments.len());
        v.clear_segments();
        let all: Vec<u32> = (0..model.segments.len() as u32).collect();
        v.add_segments(&all);
        v.add_segments(&all);
        assert_eq!(v.segs.len(), model.segments.len(), "each segment is listed once");
        let mut out = [(0u16, Pose::identity()); PEAKS];
        let n = v.run(model, edges, rotation, &Grid::new(centre, 3.0), &mut out);
        out[..n].to_vec()
    }

    #[test]
    fn the_best_voted_plan_position_is_the_true_one() {
        let model = posts();
        let rotation = UnitQuaternion::from_euler_angles(0.02, -0.01, 0.7);
        let truth = Pose::from_parts(Translation3::new(0.33, -0.41, 1.2), rotation);
        let edges = edges_seen(&model, &truth);
        let peaks = vote(&model, &edges, &rotation, &Point3::new(-0.4, 0.3, 1.5));
        let (votes, best) = peaks[0];
        assert_eq!(votes as usize, model.segments.len(), "every post votes for the truth");
        let off = (best.translation.vector.xy() - truth.translation.vector.xy()).norm();
        assert!(off <= 0.1, "peak {off:.3} m from the truth");
        assert_eq!(best.rotation, rotation);
        for (v, p) in &peaks[1..] {
            assert!(*v < votes, "a second peak has fewer votes");
            assert!((p.translation.vector - best.translation.vector).norm() >= PEAK_SEPARATION_M);
        }
    }

    #[test]
    fn a_wrong_heading_gathers_fewer_votes() {
        let model = posts();
        let rotation = UnitQuaternion::from_euler_angles(0.0, 0.0, 0.7);
        let truth = Pose::from_parts(Translation3::new(0.33, -0.41, 1.2), rotation);
        let edges = edges_seen(&model, &truth);
        let right = vote(&model, &edges, &rotation, &Point3::new(0.0, 0.0, 1.2))[0].0;
        let turned = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::PI) * rotation;
        let wrong = vote(&model, &edges, &turned, &Point3::new(0.0, 0.0, 1.2))
            .first()
            .map_or(0, |p| p.0);
        assert!(
            wrong < right,
            "the 180° twin of an irregular scene: {wrong} votes against {right}"
        );
    }

    #[test]
    fn a_segment_elsewhere_along_the_plane_does_not_overlap() {
        let n = Vector3::z();
        let (e1, e2) = (Vector3::x(), Vector3::new(1.0, 1.0, 0.0).normalize());
        let c = Vector3::zeros();
        // Inside the edge's 45°, partly inside, beside it, behind the sensor.
        assert!(overlaps(
            &n,
            &e1,
            &e2,
            &Vector3::new(2.0, 0.5, 0.0),
            &Vector3::new(2.0, 1.0, 0.0),
            &c
        ));
        assert!(overlaps(
            &n,
            &e1,
            &e2,
            &Vector3::new(1.0, 0.5, 0.0),
            &Vector3::new(0.0, 2.0, 0.0),
            &c
        ));
        assert!(!overlaps(
            &n,
            &e1,
            &e2,
            &Vector3::new(-1.0, 2.0, 0.0),
            &Vector3::new(0.0, 2.0, 0.0),
            &c
        ));
        assert!(!overlaps(
            &n,
            &e1,
            &e2,
            &Vector3::new(-2.0, 0.5, 0.0),
            &Vector3::new(-2.0, -0.5, 0.0),
            &c
        ));
    }
}
