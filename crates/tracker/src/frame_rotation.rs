//! The rig's turn between consecutive frames from their edges alone (issue 47, item 4; beyond
//! the papers, whose motion model is KT §6.2's suggestion only).
//!
//! In: each frame's edges, and a prior for the turn since the previous frame (the motion
//! model's). Out: the turn Q measured from the image, with the lines that agree on it, or
//! nothing when the image does not fix it.
//!
//! Why: a narrow view turning with the head loses its model lines for a few frames (a plain
//! wall, a floor, clutter in front); the motion filter then coasts on the last turn rate, its
//! rotation σ passes the 15° jump limit within two or three frames, and a pose coasted into a
//! turn meets its next lines wrongly (docs/decisions.md, "what a one-pinhole rig's frames can
//! give"). But clutter, texture and the building's own lines still move with the turn, model or
//! not, and a turn moves every line of the view the same way: the plane through the sensor and
//! an edge turns with the rig, whatever the line is and however far (a translation moves it by
//! about the step over the line's distance, which the inlier angle absorbs for the lines a few
//! metres away that dominate a view).
//!
//! Directions: Q takes a direction in the rig frame of the previous frame to the same world
//! direction in the rig frame of this one (d₁ = Q d₀): for poses `T_world_rig` R₀ and R₁,
//! Q = R₁ᵀ R₀, so R₁ = R₀ Qᵀ.
//!
//! How:
//! 1. The frame's longest edges ([`LINES`]) are kept; an edge's plane normal is oriented by its
//!    polarity (which side is brighter, a property of the line, unlike the order of its ends)
//!    where the image says.
//! 2. Pairs: an edge of the previous frame and one of this frame whose normals are within
//!    [`PAIR_GATE_RAD`] under the prior turn, whose arcs lie near each other and whose
//!    lengths differ by less than `LENGTH_RATIO` (and whose polarities agree where both are
//!    known).
//! 3. A consensus: turns from two pairs of well separated normals (Wahba's problem, solved by
//!    SVD), and the prior itself, each scored by the length of this frame's edges that some pair
//!    of theirs explains within the inlier angle; as many as draw two right pairs with
//!    probability `SUCCESS` at the share of pairs the best so far explains (KT eq. 2, λ = 2), at
//!    most `HYPOTHESES`; the best refitted on its pairs twice.
//! 4. Taken when at least [`MIN_LINES`] edges agree and two of them are at least
//!    `MIN_SPREAD_RAD` apart in direction (one line, or many parallel normals, leave a turn
//!    about them free).
//!
//! Nothing here allocates after [`FrameRotation::new`].

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use omnitrack_edges::Edge;
use omnitrack_solver::sample_count;
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};

/// The longest edges of a frame that take part: many more than the few a turn needs, few enough
/// that pairing them costs tens of microseconds.
pub const LINES: usize = 96;
/// Most candidate pairs kept per frame.
const MAX_PAIRS: usize = 2048;
/// How far (rad) an edge's normal may lie from its partner's under the prior turn (12°): the
/// turn a head makes between frames beyond what the motion model predicts (the renders' 5 Hz
/// frames turn by up to 12° unforeseen).
pub const PAIR_GATE_RAD: f64 = 0.21;
/// Partners' lengths differ by less than this factor (an edge broken by an occluder, or grown
/// by merging, changes length; a different line usually differs by more).
const LENGTH_RATIO: f64 = 2.5;
/// Most turns tried besides the prior …
const HYPOTHESES: usize = 128;
/// … and fewer when this chance of drawing two right pairs is reached sooner.
const SUCCESS: f64 = 0.99;
/// A turn is taken only when this many of the frame's edges agree on it …
pub const MIN_LINES: usize = 6;
/// … and two of them are at least this far apart in direction (rad, 20°).
const MIN_SPREAD_RAD: f64 = 0.35;

/// One kept edge: its plane normal (rig frame; oriented by polarity when `oriented`), the
/// direction of its midpoint and its length (rad).
#[derive(Debug, Clone, Copy)]
struct Line {
    normal: Vector3<f64>,
    mid: Vector3<f64>,
    length: f64,
    oriented: bool,
}

impl Line {
    fn of(e: &Edge) -> Option<Line> {
        let mid = (e.plane.ends[0].into_inner() + e.plane.ends[1].into_inner()).try_normalize(1e-9)?;
        let sign = if e.polarity < 0 { -1.0 } else { 1.0 };
        Some(Line {
            normal: e.plane.normal.into_inner() * sign,
            mid,
            length: e.length_rad,
            oriented: e.polarity != 0,
        })
    }
}

/// A turn measured from the image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameTurn {
    /// Q: d₁ = Q d₀ (module doc).
    pub rotation: UnitQuaternion<f64>,
    /// This frame's edges that agree on it within the inlier angle.
    pub lines: usize,
}

/// The previous frame's lines and the scratch of the consensus.
#[derive(Debug)]
pub struct FrameRotation {
    previous: Vec<Line>,
    /// The time of the frame `previous` holds.
    previous_ns: Option<u64>,
    current: Vec<Line>,
    order: Vec<(f32, u32)>,
    /// (previous line, current line).
    pairs: Vec<(u16, u16)>,
    /// The previous frame's normals under the turn being tried (the prior while pairing), and
    /// its midpoints under the prior.
    turned: Vec<Vector3<f64>>,
    turned_mid: Vec<Vector3<f64>>,
    /// The pairs a refit uses: one per current line.
    chosen: Vec<(u16, u16)>,
    /// Per current line: explained by the turn last scored (`support`).
    hit: Vec<bool>,
    rng: SmallRng,
}

impl FrameRotation {
    /// Buffers for frames of at most `max_edges` edges.
    pub fn new(max_edges: usize) -> FrameRotation {
        FrameRotation {
            previous: Vec::with_capacity(LINES),
            previous_ns: None,
            current: Vec::with_capacity(LINES),
            order: Vec::with_capacity(max_edges),
            pairs: Vec::with_capacity(MAX_PAIRS),
            chosen: Vec::with_capacity(LINES),
            turned: Vec::with_capacity(LINES),
            turned_mid: Vec::with_capacity(LINES),
            hit: Vec::with_capacity(LINES),
            rng: SmallRng::seed_from_u64(0x7e57_f00d),
        }
    }

    /// The turn from the frame of time `previous_ns` to this one (time `now_ns`), from `edges`
    /// (those at least `min_len` rad long), starting from the prior turn `prior` and judging
    /// agreement within `inlier_rad`; nothing when the frame last given was not the one of
    /// `previous_ns` (frames in between went elsewhere: a search, a gap). This frame becomes the
    /// previous one.
    pub fn measure(
        &mut self,
        edges: &[Edge],
        prior: &UnitQuaternion<f64>,
        min_len: f64,
        inlier_rad: f64,
        previous_ns: u64,
        now_ns: u64,
    ) -> Option<FrameTurn> {
        self.keep_longest(edges, min_len);
        let turn = if self.previous_ns == Some(previous_ns) {
            self.consensus(prior, inlier_rad)
        } else {
            None
        };
        std::mem::swap(&mut self.previous, &mut self.current);
        self.previous_ns = Some(now_ns);
        turn
    }

    fn keep_longest(&mut self, edges: &[Edge], min_len: f64) {
        self.order.clear();
        for (i, e) in edges.iter().enumerate() {
            if e.length_rad >= min_len && self.order.len() < self.order.capacity() {
                self.order.push((-(e.length_rad as f32), i as u32));
            }
        }
        let n = self.order.len().min(LINES);
        if n > 0 && n < self.order.len() {
            self.order.select_nth_unstable_by(n - 1, |a, b| a.0.total_cmp(&b.0));
        }
        self.current.clear();
        for &(_, i) in &self.order[..n] {
            if let Some(l) = Line::of(&edges[i as usize]) {
                self.current.push(l);
            }
        }
    }

    fn consensus(&mut self, prior: &UnitQuaternion<f64>, inlier_rad: f64) -> Option<FrameTurn> {
        if self.previous.len() < MIN_LINES || self.current.len() < MIN_LINES {
            return None;
        }
        // 2. Pairs under the prior (the previous frame's normals and midpoints turned once).
        let cos_gate = PAIR_GATE_RAD.cos();
        self.turn_previous(prior);
        let r = prior.to_rotation_matrix();
        self.turned_mid.clear();
        self.turned_mid.extend(self.previous.iter().map(|p| r * p.mid));
        self.pairs.clear();
        'outer: for j in 0..self.current.len() {
            let c = self.current[j];
            for i in 0..self.previous.len() {
                let p = &self.previous[i];
                if !(c.length < LENGTH_RATIO * p.length && p.length < LENGTH_RATIO * c.length) {
                    continue;
                }
                // Midpoints no further apart than the gate and half of both lengths.
                let reach = PAIR_GATE_RAD + 0.5 * (c.length + p.length);
                if self.turned_mid[i].dot(&c.mid) < reach.min(std::f64::consts::PI).cos() {
                    continue;
                }
                let pair = (i as u16, j as u16);
                if self.agreement(pair) < cos_gate {
                    continue;
                }
                if self.pairs.len() == self.pairs.capacity() {
                    break 'outer;
                }
                self.pairs.push(pair);
            }
        }
        if self.pairs.len() < MIN_LINES {
            return None;
        }
        // 3. The consensus: the prior, then turns from two pairs.
        let cos_in = inlier_rad.cos();
        let mut best = (self.support(prior, cos_in), *prior);
        // As many turns as give a pair of right pairs with probability SUCCESS, at the share of
        // pairs the best turn so far explains (KT eq. 2 with λ = 2), at most HYPOTHESES.
        let mut needed = self.turns_needed();
        let min_sin = MIN_SPREAD_RAD.sin();
        let mut tried = 0;
        while tried < needed {
            tried += 1;
            let a = self.pairs[self.rng.random_range(0..self.pairs.len())];
            let b = self.pairs[self.rng.random_range(0..self.pairs.len())];
            if a.1 == b.1 {
                continue;
            }
            let (ca, cb) = (self.current[a.1 as usize].normal, self.current[b.1 as usize].normal);
            if ca.cross(&cb).norm() < min_sin {
                continue;
            }
            let Some(q) = self.fit(prior, [a, b].into_iter()) else {
                continue;
            };
            let s = self.support(&q, cos_in);
            if s > best.0 {
                best = (s, q);
                needed = needed.min(self.turns_needed());
            }
        }
        // Refit on the best turn's pairs, twice.
        let mut q = best.1;
        for _ in 0..2 {
            self.choose_pairs(&q, cos_in);
            q = self.fit(&q, self.chosen.iter().copied())?;
        }
        // 4. Enough lines, spread.
        self.support(&q, cos_in);
        let agreeing = self.hit.iter().filter(|h| **h).count();
        let spread = self.hit.iter().enumerate().filter(|(_, h)| **h).any(|(j, _)| {
            self.hit
                .iter()
                .enumerate()
                .filter(|(k, h)| **h && *k > j)
                .any(|(k, _)| self.current[j].normal.cross(&self.current[k].normal).norm() >= min_sin)
        });
        (agreeing >= MIN_LINES && spread).then_some(FrameTurn {
            rotation: q,
            lines: agreeing,
        })
    }

    /// How many turns from two pairs find one from right pairs with probability [`SUCCESS`],
    /// when the lines `self.hit` marks are the share of the pairs that are right (one right
    /// pair each), at most [`HYPOTHESES`].
    fn turns_needed(&self) -> usize {
        let right = self.hit.iter().filter(|h| **h).count();
        let outliers = 100.0 * (1.0 - right as f64 / self.pairs.len().max(1) as f64);
        sample_count(2, self.pairs.len(), outliers, SUCCESS).min(HYPOTHESES as u64) as usize
    }

    /// `self.turned` ← the previous frame's normals under turn `q`: once per turn tried, not
    /// once per pair.
    fn turn_previous(&mut self, q: &UnitQuaternion<f64>) {
        let r = q.to_rotation_matrix();
        self.turned.clear();
        self.turned.extend(self.previous.iter().map(|p| r * p.normal));
    }

    /// The cosine between the pair (i, j)'s normals under the turn of `self.turned` (its
    /// absolute value when either is unoriented).
    fn agreement(&self, (i, j): (u16, u16)) -> f64 {
        let (p, c) = (&self.previous[i as usize], &self.current[j as usize]);
        let cos = self.turned[i as usize].dot(&c.normal);
        if c.oriented && p.oriented {
            cos
        } else {
            cos.abs()
        }
    }

    /// The length of this frame's lines that a pair explains under `q`; `self.hit` marks them.
    fn support(&mut self, q: &UnitQuaternion<f64>, cos_in: f64) -> f64 {
        self.turn_previous(q);
        self.hit.clear();
        self.hit.resize(self.current.len(), false);
        for k in 0..self.pairs.len() {
            let pair = self.pairs[k];
            if !self.hit[pair.1 as usize] && self.agreement(pair) >= cos_in {
                self.hit[pair.1 as usize] = true;
            }
        }
        self.hit
            .iter()
            .zip(&self.current)
            .filter(|(h, _)| **h)
            .map(|(_, l)| l.length)
            .sum()
    }

    /// `self.chosen` ← per line of this frame, its pair that agrees best with `q` within the
    /// inlier angle (`self.pairs` runs line by line).
    fn choose_pairs(&mut self, q: &UnitQuaternion<f64>, cos_in: f64) {
        self.turn_previous(q);
        self.chosen.clear();
        let mut best: Option<((u16, u16), f64)> = None;
        for k in 0..=self.pairs.len() {
            let pair = self.pairs.get(k).copied();
            if let Some(((_, j), _)) = best {
                if pair.is_none_or(|p| p.1 != j) {
                    self.chosen.push(best.take().expect("a pair").0);
                }
            }
            let Some(pair) = pair else { break };
            let cos = self.agreement(pair);
            if cos >= cos_in && best.is_none_or(|(_, c)| cos > c) {
                best = Some((pair, cos));
            }
        }
    }

    /// Wahba's problem over `pairs`: the turn taking the previous normals onto the current ones,
    /// weighted by length; an unoriented normal takes the sign `near` gives it.
    fn fit(&self, near: &UnitQuaternion<f64>, pairs: impl Iterator<Item = (u16, u16)>) -> Option<UnitQuaternion<f64>> {
        let mut b = Matrix3::zeros();
        let mut n = 0;
        for (i, j) in pairs {
            let (p, c) = (&self.previous[i as usize], &self.current[j as usize]);
            let sign = if (near * p.normal).dot(&c.normal) < 0.0 {
                -1.0
            } else {
                1.0
            };
            b += c.normal * (p.normal * sign).transpose() * c.length.min(p.length);
            n += 1;
        }
        if n < 2 {
            return None;
        }
        let svd = b.svd(true, true);
        let (u, v_t) = (svd.u?, svd.v_t?);
        let d = (u * v_t).determinant().signum();
        let r = u * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * v_t;
        Some(UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(
            r,
        )))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_edges::edge_on;
    use nalgebra::{Point3, Unit};
    use omnitrack_core::geometry::EdgePlane;

    /// An edge between two directions, of polarity `polarity`.
    fn edge(a: Vector3<f64>, b: Vector3<f64>, polarity: i8) -> Edge {
        let mut e = edge_on(
            0,
            EdgePlane {
                normal: Unit::new_normalize(a.cross(&b)),
                centre: Point3::origin(),
                ends: [Unit::new_normalize(a), Unit::new_normalize(b)],
            },
            10,
        );
        e.polarity = polarity;
        e
    }

    /// A cluttered view: `n` segments of pseudo-random directions ahead of the rig (+x).
    fn scene(n: usize, seed: u64) -> Vec<(Vector3<f64>, Vector3<f64>, i8)> {
        let mut rng = SmallRng::seed_from_u64(seed);
        (0..n)
            .map(|i| {
                let mut d = || Vector3::new(3.0, rng.random_range(-1.5..1.5), rng.random_range(-1.2..1.2));
                let (a, b) = (d(), d());
                (a, b, [-1i8, 0, 1][i % 3])
            })
            .collect()
    }

    /// The frame seen after the rig turned by Q (d₁ = Q d₀).
    fn seen(lines: &[(Vector3<f64>, Vector3<f64>, i8)], q: &UnitQuaternion<f64>) -> Vec<Edge> {
        lines.iter().map(|(a, b, p)| edge(q * a, q * b, *p)).collect()
    }

    #[test]
    fn a_turn_is_measured_from_the_lines_whatever_they_are() {
        let lines = scene(40, 3);
        let mut fr = FrameRotation::new(256);
        let id = UnitQuaternion::identity();
        assert_eq!(fr.measure(&seen(&lines, &id), &id, 0.0, 0.026, 0, 1), None);
        // A 10° turn about an oblique axis, the prior expecting none.
        let q = UnitQuaternion::from_scaled_axis(Vector3::new(0.02, -0.05, 0.16));
        let turn = fr.measure(&seen(&lines, &q), &id, 0.0, 0.026, 1, 2).expect("a turn");
        assert!(
            turn.rotation.angle_to(&q) < 1e-9,
            "off by {}",
            turn.rotation.angle_to(&q)
        );
        assert_eq!(turn.lines, 40);
    }

    #[test]
    fn lines_that_did_not_turn_with_the_view_are_outvoted() {
        let lines = scene(30, 5);
        let q = UnitQuaternion::from_scaled_axis(Vector3::new(0.0, 0.0, -0.12));
        let mut before = seen(&lines, &UnitQuaternion::identity());
        let mut after = seen(&lines, &q);
        // A third of the lines move on their own (people, a swinging door).
        let movers = scene(15, 9);
        before.extend(seen(&movers, &UnitQuaternion::identity()));
        after.extend(seen(
            &movers,
            &UnitQuaternion::from_scaled_axis(Vector3::new(0.1, 0.05, 0.08)),
        ));
        let mut fr = FrameRotation::new(256);
        let id = UnitQuaternion::identity();
        fr.measure(&before, &id, 0.0, 0.026, 0, 1);
        let turn = fr.measure(&after, &id, 0.0, 0.026, 1, 2).expect("a turn");
        // A mover that happens to lie within the inlier angle of a line under the turn pulls
        // the fit a little (one of 45 here, by 5·10⁻⁵ rad); the rest are refused.
        assert!(
            turn.rotation.angle_to(&q) < 1e-3,
            "off by {}",
            turn.rotation.angle_to(&q)
        );
        assert!((30..=32).contains(&turn.lines), "{} lines agree", turn.lines);
    }

    #[test]
    fn one_line_or_a_blank_view_fixes_no_turn() {
        let one = [(Vector3::new(3.0, -1.0, 0.0), Vector3::new(3.0, 1.0, 0.0), 1i8)];
        let mut fr = FrameRotation::new(16);
        // Six copies of one line: many edges, one direction.
        let many: Vec<_> = (0..8).flat_map(|_| one).collect();
        let id = UnitQuaternion::identity();
        fr.measure(&seen(&many, &id), &id, 0.0, 0.026, 0, 1);
        let q = UnitQuaternion::from_scaled_axis(Vector3::new(0.05, 0.0, 0.0));
        assert_eq!(fr.measure(&seen(&many, &q), &id, 0.0, 0.026, 1, 2), None);
        assert_eq!(fr.measure(&[], &id, 0.0, 0.026, 2, 3), None);
    }

    #[test]
    fn a_frame_that_does_not_follow_the_previous_one_measures_nothing() {
        let lines = scene(40, 3);
        let id = UnitQuaternion::identity();
        let mut fr = FrameRotation::new(256);
        fr.measure(&seen(&lines, &id), &id, 0.0, 0.026, 0, 1);
        // The frames of times 2–4 went to a search: the one of time 1 is not this one's previous.
        assert_eq!(fr.measure(&seen(&lines, &id), &id, 0.0, 0.026, 4, 5), None);
        assert!(fr.measure(&seen(&lines, &id), &id, 0.0, 0.026, 5, 6).is_some());
    }
}
