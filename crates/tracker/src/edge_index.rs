//! The frame's edges by the direction of their planes (beyond the paper): which edges a
//! predicted segment can match at all, without looking at every edge.
//!
//! In: a frame's [`Edge`]s (their planes' unit normals, rig frame, and sensors). Out: for a
//! sensor and a predicted plane normal, every edge of that sensor whose normal lies within a
//! gate angle of it, either way round ([`EdgeIndex::near`]); nothing the gate would pass is
//! left out, so a matcher that applies its own gate test to these edges gives the answer it
//! gives over all of them. And per sensor, the cap of directions its edges lie in: whether a
//! predicted segment can meet any of that sensor's edges at all ([`EdgeIndex::reach`],
//! [`Reach::may_share`]).
//!
//! **Why.** The initialiser's grid scores every position of its volume under every rotation
//! by matching the few dozen segments in sight against the frame's few hundred longest edges.
//! Matching all pairs made that scan cost segments × edges per position, and a volume of a
//! detailed building ran out of budget after a third of its cells. A predicted segment passes
//! a 6° gate with a small share of a frame's edges (those of one of its sensors whose planes
//! lean as its plane does), so the scan's cost follows the pairs that can match.
//!
//! **How.** A normal n and −n are the same plane: each edge's normal is taken with n_z ≥ 0
//! and binned by n_z ([`Z_BINS`] bins over [0, 1]) and azimuth ([`AZ_BINS`] bins), per sensor,
//! by a counting sort into arrays sized once. Two unit vectors within angle g are within chord
//! c = 2 sin(g/2), so their n_z differ by at most c, and their azimuths, seen from the axis, by
//! at most asin(c / r) where r is the query's distance from the axis (all azimuths when r ≤ c).
//! A plane may match the query's opposite (−m) only when both lie within c of the horizon:
//! then the window about the opposite azimuth is searched too.
//!
//! Fixed memory: sized in [`EdgeIndex::new`]; [`EdgeIndex::build`] and [`EdgeIndex::near`]
//! allocate nothing.

use nalgebra::Vector3;
use omnitrack_core::memory::resident;
use omnitrack_edges::Edge;
use std::f64::consts::{FRAC_PI_2, PI, TAU};

/// Bins of |n_z| over [0, 1].
pub const Z_BINS: usize = 16;
/// Bins of azimuth over [0, 2π).
pub const AZ_BINS: usize = 64;
const BUCKETS: usize = Z_BINS * AZ_BINS;

/// A frame's edges binned by sensor and plane normal.
pub struct EdgeIndex {
    /// Edge indices in bucket order.
    order: Vec<u16>,
    /// Per (sensor, bucket): where its edges start in `order`; one more entry at the end.
    start: Vec<u32>,
    /// Scratch of the counting sort: each edge's bucket.
    key: Vec<u32>,
    sensors: usize,
    /// Per sensor, where its edges are: see [`Cap`].
    caps: Vec<Cap>,
}

/// Where one sensor's edges lie: the cap of directions (axis, cosine of its radius) that holds
/// the end rays of all of them, and so their whole arcs (a cap narrower than a hemisphere holds
/// the shorter great-circle arc between any two of its points). `Anywhere` when no such cap is
/// narrower than [`CAP_MAX_RAD`] (a fisheye's edges may lie all round): then every segment
/// may meet them.
#[derive(Debug, Clone, Copy, Default)]
enum Cap {
    /// The sensor has no edges.
    #[default]
    Empty,
    Within(Vector3<f64>, f64),
    Anywhere,
}

/// The widest cap [`Reach::may_share`] tests against; beyond it the test's own bound
/// (the cap widened by the gate stays inside a hemisphere) would not hold.
const CAP_MAX_RAD: f64 = 1.3;

/// Slack (rad) added to a cap's radius against rounding: the test must never leave out a
/// segment that shares an angle with an edge.
const CAP_SLACK_RAD: f64 = 1e-6;

/// The bucket of a unit normal (taken with n_z ≥ 0).
fn bucket(n: &Vector3<f64>) -> (usize, usize) {
    let n = if n.z < 0.0 { -n } else { *n };
    let zb = ((n.z * Z_BINS as f64) as usize).min(Z_BINS - 1);
    (zb, az_bin(n.y.atan2(n.x)))
}

fn az_bin(az: f64) -> usize {
    let a = az.rem_euclid(TAU);
    ((a / TAU * AZ_BINS as f64) as usize).min(AZ_BINS - 1)
}

/// A sensor's cap of directions (where its edges lie) widened by a gate ([`EdgeIndex::reach`]).
#[derive(Debug, Clone, Copy)]
pub enum Reach {
    /// The sensor has no edges.
    Nothing,
    /// Its edges may lie anywhere.
    Anything,
    /// Every ray an edge passing the gate projects into a segment's plane is within the angle
    /// whose cosine is `cos` of `axis`.
    Within { axis: Vector3<f64>, cos: f64 },
}

impl Reach {
    /// Whether an edge of the sensor whose plane passes the gate against the plane through the
    /// sensor's centre and the arc from `a` to `b` (directions from that centre, less than half
    /// a turn apart) may share an angle of that plane with the arc, as [`crate::matching`]
    /// measures it (the edge's end rays projected into the plane). False only when it surely
    /// cannot: the projected rays stay within the reach, so the arc (or, for the measure's
    /// known defect, the direction opposite `a`: see `SegmentArc::shared`) must come that
    /// close to the axis. A segment in front of one sensor of a ring is then not looked for
    /// among most other sensors' edges, whose planes the index hands out whenever they lean
    /// the same way.
    #[inline]
    pub fn may_share(&self, a: &Vector3<f64>, b: &Vector3<f64>) -> bool {
        let (axis, cos) = match self {
            Reach::Nothing => return false,
            Reach::Anything => return true,
            Reach::Within { axis, cos } => (axis, *cos),
        };
        let (la, lb) = (a.norm(), b.norm());
        if !(la > 1e-12 && lb > 1e-12) {
            return true;
        }
        // An end within reach, or the direction opposite the first end (the known defect
        // counts an edge across it as covering the whole arc).
        let (da, db) = (axis.dot(a), axis.dot(b));
        if da >= cos * la || db >= cos * lb || -da >= cos * la {
            return true;
        }
        // Else only a point inside the arc can be: the axis projected into the arc's plane, if
        // that falls between the ends.
        let m = a.cross(b);
        let mm = m.norm_squared();
        if mm <= 1e-24 * la * la * lb * lb {
            return true;
        }
        let q = axis - m * (m.dot(axis) / mm);
        a.cross(&q).dot(&m) >= 0.0 && q.cross(b).dot(&m) >= 0.0 && q.norm() >= cos
    }
}

impl EdgeIndex {
    /// Room for `max_edges` edges (at most 65,536) over `sensors` sensors.
    pub fn new(max_edges: usize, sensors: usize) -> EdgeIndex {
        let sensors = sensors.max(1);
        EdgeIndex {
            order: resident(Vec::with_capacity(max_edges.min(1 << 16))),
            start: resident(vec![0; sensors * BUCKETS + 1]),
            key: resident(Vec::with_capacity(max_edges.min(1 << 16))),
            sensors,
            caps: resident(vec![Cap::Empty; sensors]),
        }
    }

    /// Bins `edges` (those of sensors beyond the index's count, and beyond its capacity, are
    /// left out).
    pub fn build(&mut self, edges: &[Edge]) {
        self.start.fill(0);
        self.key.clear();
        for e in edges.iter().take(self.key.capacity()) {
            let s = e.sensor as usize;
            let k = if s < self.sensors {
                let (zb, ab) = bucket(&e.plane.normal);
                (s * BUCKETS + zb * AZ_BINS + ab) as u32
            } else {
                u32::MAX
            };
            self.key.push(k);
            if k != u32::MAX {
                self.start[k as usize + 1] += 1;
            }
        }
        for i in 1..self.start.len() {
            self.start[i] += self.start[i - 1];
        }
        self.order.clear();
        self.order.resize(self.start[self.start.len() - 1] as usize, 0);
        // Each bucket's cursor runs from its first slot to its end, so the edges of a bucket
        // keep their order in the frame; then the starts are shifted back by one bucket.
        for (i, &k) in self.key.iter().enumerate() {
            if k != u32::MAX {
                let b = k as usize;
                self.order[self.start[b] as usize] = i as u16;
                self.start[b] += 1;
            }
        }
        for b in (1..self.start.len()).rev() {
            self.start[b] = self.start[b - 1];
        }
        self.start[0] = 0;
        self.build_caps(&edges[..self.key.len()]);
    }

    /// Each sensor's [`Cap`]: about the mean of its edges' end rays, as wide as the farthest.
    fn build_caps(&mut self, edges: &[Edge]) {
        let mut sum = [Vector3::zeros(); crate::matching::MAX_SENSORS];
        let sensors = self.sensors.min(sum.len());
        for e in edges.iter().filter(|e| (e.sensor as usize) < sensors) {
            sum[e.sensor as usize] += e.plane.ends[0].into_inner() + e.plane.ends[1].into_inner();
        }
        for (s, cap) in self.caps.iter_mut().enumerate() {
            *cap = match sum.get(s).and_then(|v| v.try_normalize(1e-9)) {
                _ if s >= sensors => Cap::Anywhere,
                None if sum[s] == Vector3::zeros() => Cap::Empty,
                None => Cap::Anywhere,
                Some(axis) => {
                    let cos = edges
                        .iter()
                        .filter(|e| e.sensor as usize == s)
                        .flat_map(|e| e.plane.ends)
                        .map(|r| axis.dot(&r))
                        .fold(1.0f64, f64::min);
                    let radius = cos.clamp(-1.0, 1.0).acos();
                    if radius < CAP_MAX_RAD {
                        Cap::Within(axis, radius)
                    } else {
                        Cap::Anywhere
                    }
                }
            };
        }
    }

    /// `sensor`'s cap widened by the tilt a gate (the cosine of its angle, `cos_gate`) allows an
    /// edge's plane: what [`Reach::may_share`] tests a segment against. Worked out once per
    /// gate and sensor, not once per segment.
    pub fn reach(&self, sensor: usize, cos_gate: f64) -> Reach {
        let (axis, radius) = match self.caps.get(sensor) {
            Some(Cap::Empty) => return Reach::Nothing,
            Some(Cap::Within(axis, radius)) => (*axis, *radius),
            _ => return Reach::Anything,
        };
        // An edge's ray is within this tilt of the arc's plane: |r · n| ≤ |n − m| for the
        // edge's normal m within the gate of n, and |n − m| is at most the gate's chord.
        let chord = (2.0 - 2.0 * cos_gate.clamp(-1.0, 1.0)).max(0.0).sqrt();
        let reach = radius + chord.min(1.0).asin() + CAP_SLACK_RAD;
        if reach >= FRAC_PI_2 {
            return Reach::Anything;
        }
        Reach::Within {
            axis,
            cos: reach.cos() - 1e-12,
        }
    }

    /// Calls `f` with the index of every edge of `sensor` whose plane normal is within the
    /// angle whose cosine is `cos_gate` of `m` or of −m (`m` unit length), and perhaps a few
    /// more: the caller applies its own test. Returns how many edges it handed out. Only reads
    /// the index, so that the threads of a search can share one.
    #[inline]
    pub fn near(&self, sensor: usize, m: &Vector3<f64>, cos_gate: f64, mut f: impl FnMut(usize)) -> u64 {
        if sensor >= self.sensors {
            return 0;
        }
        let m = if m.z < 0.0 { -m } else { *m };
        let chord = (2.0 - 2.0 * cos_gate.clamp(-1.0, 1.0)).max(0.0).sqrt();
        let z_lo = (((m.z - chord) * Z_BINS as f64).floor().max(0.0)) as usize;
        let z_hi = (((m.z + chord) * Z_BINS as f64) as usize).min(Z_BINS - 1);
        let r = (1.0 - m.z * m.z).max(0.0).sqrt();
        let az = m.y.atan2(m.x);
        let base = sensor * BUCKETS;
        let mut visit = |lo: f64, hi: f64, start: &[u32], order: &[u16], visited: &mut u64| {
            let (b_lo, span) = if hi - lo >= TAU {
                (0, AZ_BINS)
            } else {
                let b_lo = az_bin(lo);
                let w = TAU / AZ_BINS as f64;
                // Bins from the one holding `lo` to the one holding `hi`, going round.
                let first = (lo / w).floor();
                let last = (hi / w).floor();
                (b_lo, ((last - first) as usize + 1).min(AZ_BINS))
            };
            for zb in z_lo..=z_hi {
                for k in 0..span {
                    let b = base + zb * AZ_BINS + (b_lo + k) % AZ_BINS;
                    let (from, to) = (start[b] as usize, start[b + 1] as usize);
                    *visited += (to - from) as u64;
                    for &i in &order[from..to] {
                        f(i as usize);
                    }
                }
            }
        };
        let half = if r <= chord { PI } else { (chord / r).min(1.0).asin() };
        let mut visited = 0;
        visit(az - half, az + half, &self.start, &self.order, &mut visited);
        // Near the horizon the plane may match −m, whose canonical azimuth is the opposite
        // (unless the first window already went all the way round).
        if m.z <= chord && half < PI {
            visit(az + PI - half, az + PI + half, &self.start, &self.order, &mut visited);
        }
        visited
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;
    use omnitrack_core::geometry::EdgePlane;

    fn edge(sensor: u8, n: Vector3<f64>) -> Edge {
        let n = nalgebra::Unit::new_normalize(n);
        let a = nalgebra::Unit::new_normalize(n.cross(&Vector3::new(0.3, 0.5, 0.8)));
        let b = nalgebra::Unit::new_normalize(n.cross(&a));
        Edge {
            sensor,
            plane: EdgePlane {
                normal: n,
                centre: Point3::origin(),
                ends: [a, b],
            },
            px: [nalgebra::Point2::origin(); 2],
            length_rad: 0.1,
            strength: 1.0,
            hue: omnitrack_edges::HueSignature::NONE,
            polarity: 0,
            edgels: 10,
            rms_rad: 0.0,
            gaps: [[0.0; 2]; omnitrack_edges::MAX_GAPS],
            n_gaps: 0,
            shown: [[0.0; 2]; omnitrack_edges::MAX_GAPS + 1],
            n_shown: 0,
        }
    }

    /// xorshift64* in [0, 1).
    fn uniform(x: &mut u64) -> f64 {
        *x ^= *x >> 12;
        *x ^= *x << 25;
        *x ^= *x >> 27;
        (x.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
    }

    fn unit(x: &mut u64) -> Vector3<f64> {
        loop {
            let v = Vector3::new(2.0 * uniform(x) - 1.0, 2.0 * uniform(x) - 1.0, 2.0 * uniform(x) - 1.0);
            if v.norm() > 0.1 && v.norm() <= 1.0 {
                return v.normalize();
            }
        }
    }

    #[test]
    fn every_edge_within_the_gate_is_handed_out_and_none_twice() {
        let mut x = 0x1234_5678_9abc_def1u64;
        let mut edges = Vec::new();
        for k in 0..600 {
            // Many near the horizon and near the pole, where the bins wrap and the windows
            // widen; the rest anywhere.
            let n = match k % 4 {
                0 => Vector3::new(
                    uniform(&mut x) - 0.5,
                    uniform(&mut x) - 0.5,
                    0.02 * (uniform(&mut x) - 0.5),
                ),
                1 => Vector3::new(0.05 * (uniform(&mut x) - 0.5), 0.05 * (uniform(&mut x) - 0.5), 1.0),
                _ => unit(&mut x),
            };
            edges.push(edge((k % 3) as u8, n));
        }
        let mut index = EdgeIndex::new(1024, 3);
        index.build(&edges);
        let (mut total_visited, mut counted) = (0, 0);
        for q in 0..2000 {
            let m = match q % 4 {
                0 => Vector3::new(
                    uniform(&mut x) - 0.5,
                    uniform(&mut x) - 0.5,
                    0.03 * (uniform(&mut x) - 0.5),
                )
                .normalize(),
                1 => Vector3::new(0.1 * (uniform(&mut x) - 0.5), 0.1 * (uniform(&mut x) - 0.5), -1.0).normalize(),
                _ => unit(&mut x),
            };
            let sensor = q % 3;
            let gate: f64 = [2.0f64, 6.0, 12.0][q % 3].to_radians();
            let mut seen = vec![0u32; edges.len()];
            counted += index.near(sensor, &m, gate.cos(), |i| seen[i] += 1);
            for (i, e) in edges.iter().enumerate() {
                let passes = e.sensor as usize == sensor && m.dot(&e.plane.normal).abs() >= gate.cos();
                assert!(seen[i] <= 1, "edge {i} handed out {} times", seen[i]);
                assert!(!passes || seen[i] == 1, "edge {i} within {gate} of {m:?} left out");
                assert!(
                    seen[i] == 0 || e.sensor as usize == sensor,
                    "edge {i} of another sensor"
                );
            }
            total_visited += seen.iter().sum::<u32>();
        }
        // Far fewer than all of a sensor's edges per query.
        assert!(total_visited < 2000 * 200 / 4, "visited {total_visited}");
        assert_eq!(counted, u64::from(total_visited));
    }

    /// No edge that shares an angle with a segment within the gate (as `SegmentArc::shared`
    /// measures it, its known defect included) is left out by its sensor's cap (a ring of five
    /// sensors with edges up to 55° off their axes, segments anywhere round, gates from 2° to
    /// 12°), and most segments are ruled out for most sensors.
    #[test]
    fn a_sensors_cap_never_rules_out_an_edge_that_shares_an_angle() {
        use crate::matching::{Gate, Predicted, SegmentArc};
        let mut x = 0x0dd_ba11_cafe_f00du64;
        let centres: Vec<Point3<f64>> = (0..5)
            .map(|k| {
                let t = k as f64 * TAU / 5.0;
                Point3::new(0.05 * t.cos(), 0.05 * t.sin(), 0.0)
            })
            .collect();
        let axes: Vec<Vector3<f64>> = (0..5)
            .map(|k| {
                let t = k as f64 * TAU / 5.0;
                Vector3::new(t.cos(), t.sin(), 0.0)
            })
            .collect();
        let within = |r: &Vector3<f64>, s: usize| axes[s].dot(r) >= 55f64.to_radians().cos();
        let (mut shared, mut ruled_out, mut tried) = (0, 0, 0);
        for round in 0..300 {
            let gate_deg = [2.0, 6.0, 12.0][round % 3];
            let gate = Gate::geometric(f64::to_radians(gate_deg));
            let ends = [
                Point3::from(unit(&mut x) * (1.0 + 4.0 * uniform(&mut x))),
                Point3::from(unit(&mut x) * (1.0 + 4.0 * uniform(&mut x))),
            ];
            let pred = Predicted::new(&ends, &omnitrack_core::geometry::Pose::identity(), &centres);
            // Edges in or near the segment's plane of each sensor, tilted within the gate, their
            // ends anywhere along that plane inside the sensor's view (behind the segment too,
            // across the direction opposite its first end). They alone make up the caps.
            let mut edges = Vec::new();
            for s in 0..5 {
                let n = pred.normals[s];
                for _ in 0..8 {
                    let tilt = nalgebra::UnitQuaternion::from_scaled_axis(
                        unit(&mut x) * gate_deg.to_radians() * uniform(&mut x),
                    );
                    let m = tilt * n;
                    let u = unit(&mut x).cross(&m).normalize();
                    let w = m.cross(&u);
                    let ray = |t: f64| u * t.cos() + w * t.sin();
                    let (t0, t1) = (TAU * uniform(&mut x), 0.6 * (uniform(&mut x) - 0.5));
                    let (r0, r1) = (ray(t0), ray(t0 + t1));
                    if within(&r0, s) && within(&r1, s) {
                        let mut e = edge(s as u8, m);
                        e.plane.ends = [nalgebra::Unit::new_normalize(r0), nalgebra::Unit::new_normalize(r1)];
                        edges.push(e);
                    }
                }
            }
            let mut index = EdgeIndex::new(1024, 5);
            index.build(&edges);
            for (s, centre) in centres.iter().enumerate() {
                let c = centre.coords;
                let (a, b) = (pred.ends_rig[0] - c, pred.ends_rig[1] - c);
                let may = index.reach(s, gate.cos_alpha).may_share(&a, &b);
                tried += 1;
                ruled_out += usize::from(!may);
                let Some(arc) = SegmentArc::new(&pred, centre, &pred.normals[s]) else {
                    continue;
                };
                for e in edges.iter().filter(|e| e.sensor as usize == s) {
                    let (common, _, _) = arc.shared(e);
                    if pred.normals[s].dot(&e.plane.normal).abs() >= gate.cos_alpha && common > 0.0 {
                        shared += 1;
                        assert!(may, "round {round}, sensor {s}: an edge sharing {common} rad ruled out");
                    }
                }
            }
        }
        assert!(
            shared > 200,
            "only {shared} edges shared an angle: the test tests little"
        );
        assert!(ruled_out * 2 > tried, "{ruled_out} of {tried} ruled out");
    }
}
