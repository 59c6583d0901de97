//! How long the rig may have been moving since its hint (beyond the papers; issue 47, item 3).
//!
//! A hint (`run --init x,y,z,r`) says where the rig was when tracking started. A wearer who
//! walks off before the first pose leaves it: measured on the `corridor` recording replayed at
//! 30 Hz from a hint of 3 m about the first pose, the searches fell behind the frames, the
//! rig walked 5.4 m from the hint, and a search of the hint's volume committed the door 4 m
//! behind it (the truth, outside the volume, was not there to refuse it). So the volume a
//! search uses grows by what the rig can have walked (`motion.max_speed_m_s`) while the images
//! say it was moving; a rig standing still keeps the hint as given.
//!
//! The images say it: the longest edges of an *anchor* frame (the first, at first) are looked
//! for in each later frame searched; while most of them (by length) are still there, each
//! plane within twice the edge noise (`noise.edge_normal_sigma_deg`) of its anchor's and
//! overlapping it, the rig is where the anchor saw it (a step of a few centimetres already
//! turns the planes of lines a few metres off by more). Once they are not, the rig may have
//! moved for all of the time since the anchor, which is counted, and this frame becomes the
//! anchor. A turn on the spot counts too: without a pose, a turn and a step cannot be told
//! apart, and counting a turn only widens the volume. People crossing the view hide a few lines,
//! not most of the longest.
//!
//! In: the frames' [`Edge`]s and capture times, in order, while the tracker initialises from
//! a hint. Out: the seconds the rig may have been moving ([`HintAge::moving_s`]). Fixed memory:
//! the anchor's lines and the frame's edge order are kept in buffers sized at start-up. Bounded
//! time: a frame costs at most [`ANCHOR_EDGES`] × its edges plane comparisons (a few tens of
//! microseconds), and only before the first pose.

use nalgebra::Vector3;
use omnitrack_core::memory::resident;
use omnitrack_edges::Edge;

/// Anchor edges compared: the longest this many.
const ANCHOR_EDGES: usize = 48;

/// The share of the anchor's edge length that must be found again for the rig to count as
/// where the anchor saw it.
const STILL_SHARE: f64 = 0.75;

/// One anchor edge: its sensor, its plane's unit normal, the unit ray of its middle and its
/// half length (rad), also its weight. (A line seen by another sensor has another plane: the
/// planes pass through the sensors' centres.)
#[derive(Debug, Clone, Copy)]
struct Line {
    sensor: u8,
    normal: Vector3<f64>,
    middle: Vector3<f64>,
    half_rad: f64,
}

impl Line {
    fn of(e: &Edge) -> Line {
        let [a, b] = e.plane.ends.map(|r| r.into_inner());
        Line {
            sensor: e.sensor,
            normal: e.plane.normal.into_inner(),
            middle: (a + b).try_normalize(1e-12).unwrap_or(a),
            half_rad: 0.5 * e.length_rad,
        }
    }
}

/// The moving time since the hint (module doc).
#[derive(Debug)]
pub(super) struct HintAge {
    anchor: Vec<Line>,
    anchor_ns: Option<u64>,
    moving_ns: u64,
    /// cos of the largest angle between an anchor's plane and the same line's in a frame of
    /// a rig that has not moved.
    same_plane_cos: f64,
    /// A frame's edges (indices), the longest picked out when it becomes the anchor.
    order: Vec<u32>,
}

impl HintAge {
    /// For frames of at most `max_edges` edges whose planes scatter by `edge_sigma_rad`.
    pub(super) fn new(edge_sigma_rad: f64, max_edges: usize) -> HintAge {
        HintAge {
            anchor: resident(Vec::with_capacity(ANCHOR_EDGES)),
            anchor_ns: None,
            moving_ns: 0,
            same_plane_cos: (2.0 * edge_sigma_rad).cos(),
            order: resident(Vec::with_capacity(max_edges)),
        }
    }

    /// The seconds the rig may have been moving up to the last frame looked at.
    pub(super) fn moving_s(&self) -> f64 {
        self.moving_ns as f64 * 1e-9
    }

    /// A frame, in capture order: counts the time since the anchor when the rig has moved
    /// since it (module doc), and makes the frame the anchor then (and for the first frame).
    /// A frame without edges says nothing and is passed over; one older than the anchor too.
    pub(super) fn observe(&mut self, edges: &[Edge], timestamp_ns: u64) {
        if edges.is_empty() || self.anchor_ns.is_some_and(|a| timestamp_ns < a) {
            return;
        }
        let Some(anchor_ns) = self.anchor_ns else {
            self.anchor_from(edges, timestamp_ns);
            return;
        };
        if !self.still_there(edges) {
            self.moving_ns += timestamp_ns - anchor_ns;
            self.anchor_from(edges, timestamp_ns);
        }
    }

    /// Whether most of the anchor's length is found again in `edges`.
    fn still_there(&self, edges: &[Edge]) -> bool {
        let total: f64 = self.anchor.iter().map(|l| l.half_rad).sum();
        if total <= 0.0 {
            return false;
        }
        let found: f64 = self
            .anchor
            .iter()
            .filter(|a| {
                edges.iter().any(|e| {
                    e.sensor == a.sensor && a.normal.dot(&e.plane.normal).abs() >= self.same_plane_cos && {
                        let b = Line::of(e);
                        a.middle.angle(&b.middle) <= a.half_rad + b.half_rad
                    }
                })
            })
            .map(|l| l.half_rad)
            .sum();
        found >= STILL_SHARE * total
    }

    fn anchor_from(&mut self, edges: &[Edge], timestamp_ns: u64) {
        self.order.clear();
        self.order
            .extend((0..edges.len().min(self.order.capacity())).map(|k| k as u32));
        let n = ANCHOR_EDGES.min(self.order.len());
        if n < self.order.len() {
            self.order.select_nth_unstable_by(n, |&a, &b| {
                edges[b as usize].length_rad.total_cmp(&edges[a as usize].length_rad)
            });
        }
        self.anchor.clear();
        self.anchor
            .extend(self.order[..n].iter().map(|&k| Line::of(&edges[k as usize])));
        self.anchor_ns = Some(timestamp_ns);
    }
}

#[cfg(test)]
mod tests {
    use super::HintAge;
    use crate::test_edges::edge_on;
    use nalgebra::{Point3, Rotation3, Vector3};
    use omnitrack_core::geometry::EdgePlane;
    use omnitrack_edges::Edge;

    fn edge_between(a: &Vector3<f64>, b: &Vector3<f64>) -> Edge {
        edge_on(0, EdgePlane::from_rays(Point3::origin(), a, b).unwrap(), 100)
    }

    /// Lines round a room 4 m wide seen from `at`: the wall-ceiling and wall-floor junctions
    /// and the vertical corners, as edges of sensor 0.
    fn room(at: Vector3<f64>, turn_deg: f64) -> Vec<Edge> {
        let r = Rotation3::from_axis_angle(&Vector3::z_axis(), turn_deg.to_radians());
        let mut lines = Vec::new();
        let c = [(-2.0, -2.0), (2.0, -2.0), (2.0, 2.0), (-2.0, 2.0)];
        for k in 0..4 {
            let (x0, y0) = c[k];
            let (x1, y1) = c[(k + 1) % 4];
            for z in [0.0, 2.5] {
                lines.push((Vector3::new(x0, y0, z), Vector3::new(x1, y1, z)));
            }
            lines.push((Vector3::new(x0, y0, 0.0), Vector3::new(x0, y0, 2.5)));
        }
        lines
            .iter()
            .map(|(a, b)| {
                let rel = |p: &Vector3<f64>| r.inverse() * (p - at - Vector3::new(0.0, 0.0, 1.2));
                edge_between(&rel(a), &rel(b))
            })
            .collect()
    }

    const FRAME_NS: u64 = 33_333_333;

    #[test]
    fn a_rig_standing_still_ages_nothing_and_one_walking_ages_by_the_time_it_moved() {
        let mut age = HintAge::new(0.5f64.to_radians(), 64);
        let here = Vector3::new(0.3, -0.2, 0.0);
        for k in 0..30 {
            age.observe(&room(here, 0.0), k * FRAME_NS);
        }
        assert_eq!(age.moving_s(), 0.0);
        // Frames without edges (a covered lens) say nothing.
        age.observe(&[], 30 * FRAME_NS);
        assert_eq!(age.moving_s(), 0.0);
        // Walking 1 m/s along x from frame 30: within a few frames the lines have moved.
        for k in 30..60u64 {
            let step = (k - 30) as f64 * 1.0 * FRAME_NS as f64 * 1e-9;
            age.observe(&room(here + Vector3::new(step, 0.0, 0.0), 0.0), k * FRAME_NS);
        }
        let walked = age.moving_s();
        assert!(walked > 0.8 && walked <= 59.0 * FRAME_NS as f64 * 1e-9, "{walked}");
        // Standing still again adds nothing.
        let there = here + Vector3::new(30.0 * FRAME_NS as f64 * 1e-9, 0.0, 0.0);
        for k in 60..90 {
            age.observe(&room(there, 0.0), k * FRAME_NS);
        }
        assert!((age.moving_s() - walked).abs() < 0.1, "{} {walked}", age.moving_s());
    }

    #[test]
    fn a_turn_on_the_spot_counts_as_moving_and_a_few_lines_hidden_do_not() {
        let mut age = HintAge::new(0.5f64.to_radians(), 64);
        let here = Vector3::zeros();
        age.observe(&room(here, 0.0), 0);
        age.observe(&room(here, 5.0), FRAME_NS);
        assert!((age.moving_s() - FRAME_NS as f64 * 1e-9).abs() < 1e-9);
        let mut age = HintAge::new(0.5f64.to_radians(), 64);
        let all = room(here, 0.0);
        age.observe(&all, 0);
        // Someone crossing the view hides two of the twelve lines.
        age.observe(&all[2..], FRAME_NS);
        assert_eq!(age.moving_s(), 0.0);
    }
}
