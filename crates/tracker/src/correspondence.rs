//! Correspondence lifetimes (Koch–Teller §4.2.4, Figure 8) and the tracker's correspondence set
//! S_t: one entry per model segment of the current visibility set.
//!
//! In: per frame, whether each correspondence was observed (and with which edge), and the new
//! visibility set VIS(T_{t+1}). Out: the states unknown → pending → accepted and back, the edge
//! and hue signature each one holds, and S_{t+1}.
//!
//! Figure 8 as implemented, with k = `accept_after_frames`:
//! - unknown, observed → pending (the edge and its hue signature are kept from now on);
//! - pending, observed k consecutive frames → accepted;
//! - accepted, unobserved → pending ("degrades from accepted to pending if it is unobserved for at
//!   least one but no more than k−1 frames");
//! - such a demoted correspondence that is observed again within k−1 frames "evolves to accepted"
//!   at once (it had earned its k observations already);
//! - pending, unobserved k consecutive frames → unknown; the signature is dropped.
//!
//! The table has a fixed capacity chosen at start-up (the largest visibility set of the table,
//! twice over, see [`CorrespondenceTable::new`]); updating it never allocates.

use omnitrack_core::geometry::EdgePlane;
use omnitrack_edges::{Edge, HueSignature};

/// A correspondence's status (Figure 8).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CorrespondenceState {
    Unknown,
    Pending,
    Accepted,
}

impl CorrespondenceState {
    /// 0 unknown, 1 pending, 2 accepted (the code of the pictures and traces).
    pub fn code(self) -> u8 {
        match self {
            CorrespondenceState::Unknown => 0,
            CorrespondenceState::Pending => 1,
            CorrespondenceState::Accepted => 2,
        }
    }

    /// The state of a code 0, 1 or 2 (see [`code`](Self::code)).
    pub fn from_code(code: u8) -> Option<Self> {
        match code {
            0 => Some(CorrespondenceState::Unknown),
            1 => Some(CorrespondenceState::Pending),
            2 => Some(CorrespondenceState::Accepted),
            _ => None,
        }
    }

    /// `unknown`, `pending` or `accepted`.
    pub fn name(self) -> &'static str {
        match self {
            CorrespondenceState::Unknown => "unknown",
            CorrespondenceState::Pending => "pending",
            CorrespondenceState::Accepted => "accepted",
        }
    }
}

/// The edge a correspondence holds: its plane and hue signature at its last observation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeldEdge {
    pub plane: EdgePlane,
    pub hue: HueSignature,
    /// [`Edge::polarity`].
    pub polarity: i8,
    pub sensor: u8,
}

impl From<&Edge> for HeldEdge {
    fn from(e: &Edge) -> Self {
        HeldEdge {
            plane: e.plane,
            hue: e.hue,
            polarity: e.polarity,
            sensor: e.sensor,
        }
    }
}

impl HeldEdge {
    /// The plane normal turned towards the brighter side (`None` if neither side is clearly
    /// brighter): it does not depend on the order of the edge's ends, which may change from
    /// frame to frame.
    pub fn bright_normal(&self) -> Option<nalgebra::Vector3<f64>> {
        (self.polarity != 0).then(|| self.plane.normal.into_inner() * f64::from(self.polarity))
    }
}

/// One model segment's correspondence.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Track {
    /// Index into `Model::segments`.
    pub segment: u32,
    pub state: CorrespondenceState,
    /// Kept while pending or accepted.
    pub edge: Option<HeldEdge>,
    /// Consecutive frames observed.
    pub streak: u32,
    /// Consecutive frames unobserved.
    pub missed: u32,
    /// Demoted from accepted and not yet back or unknown.
    pub demoted: bool,
}

impl Track {
    pub fn unknown(segment: u32) -> Track {
        Track {
            segment,
            state: CorrespondenceState::Unknown,
            edge: None,
            streak: 0,
            missed: 0,
            demoted: false,
        }
    }

    /// An accepted correspondence with `edge` (from initialisation, whose consensus already
    /// verified it).
    pub fn accepted(segment: u32, edge: HeldEdge) -> Track {
        Track {
            segment,
            state: CorrespondenceState::Accepted,
            edge: Some(edge),
            streak: 1,
            missed: 0,
            demoted: false,
        }
    }

    /// Figure 8 on an observation with `edge`.
    pub fn observe(&mut self, edge: HeldEdge, k: u32) {
        self.edge = Some(edge);
        self.streak += 1;
        self.missed = 0;
        self.state = match self.state {
            CorrespondenceState::Accepted => CorrespondenceState::Accepted,
            _ if self.demoted || self.streak >= k => CorrespondenceState::Accepted,
            _ => CorrespondenceState::Pending,
        };
        if self.state == CorrespondenceState::Accepted {
            self.demoted = false;
        }
    }

    /// Figure 8 on a frame without an observation.
    pub fn miss(&mut self, k: u32) {
        self.streak = 0;
        self.missed += 1;
        match self.state {
            CorrespondenceState::Accepted => {
                self.state = CorrespondenceState::Pending;
                self.demoted = true;
                if self.missed >= k {
                    self.forget();
                }
            }
            CorrespondenceState::Pending if self.missed >= k => self.forget(),
            _ => {}
        }
    }

    fn forget(&mut self) {
        self.state = CorrespondenceState::Unknown;
        self.edge = None;
        self.demoted = false;
    }
}

/// S_t: the correspondences of the current visibility set, sorted by segment.
#[derive(Debug, Clone)]
pub struct CorrespondenceTable {
    tracks: Vec<Track>,
    scratch: Vec<Track>,
    capacity: usize,
    /// Segments of a new visibility set that did not fit (counted, never silent).
    pub overflow: u64,
}

impl CorrespondenceTable {
    /// Room for `capacity` correspondences.
    pub fn new(capacity: usize) -> CorrespondenceTable {
        let capacity = capacity.max(1);
        CorrespondenceTable {
            tracks: omnitrack_core::memory::resident(Vec::with_capacity(capacity)),
            scratch: omnitrack_core::memory::resident(Vec::with_capacity(capacity)),
            capacity,
            overflow: 0,
        }
    }

    pub fn tracks(&self) -> &[Track] {
        &self.tracks
    }

    pub fn tracks_mut(&mut self) -> &mut [Track] {
        &mut self.tracks
    }

    pub fn capacity(&self) -> usize {
        self.capacity
    }

    pub fn clear(&mut self) {
        self.tracks.clear();
    }

    /// How many correspondences are in `state`.
    pub fn count(&self, state: CorrespondenceState) -> usize {
        self.tracks.iter().filter(|t| t.state == state).count()
    }

    /// Replaces the table with `tracks` (sorted by segment, deduplicated; beyond capacity dropped
    /// and counted).
    pub fn reset_with(&mut self, tracks: impl Iterator<Item = Track>) {
        self.tracks.clear();
        for t in tracks {
            if self.tracks.len() < self.capacity {
                self.tracks.push(t);
            } else {
                self.overflow += 1;
            }
        }
        self.tracks.sort_unstable_by_key(|t| t.segment);
        self.tracks.dedup_by_key(|t| t.segment);
    }

    /// Figure 7 lines 12–13 with the new visibility set `visible` (ascending segment indices):
    /// segments no longer visible are removed once they are unknown (a pending or accepted one
    /// is still being seen: the prior visibility is not conservative, KT §4.3), and new ones
    /// are inserted as unknown.
    pub fn update_visible(&mut self, visible: &[u32]) {
        self.scratch.clear();
        let (mut i, mut j) = (0, 0);
        let old = &self.tracks;
        while i < old.len() || j < visible.len() {
            let next = match (old.get(i), visible.get(j)) {
                (Some(t), Some(&s)) if t.segment == s => {
                    i += 1;
                    j += 1;
                    Some(*t)
                }
                (Some(t), Some(&s)) if t.segment < s => {
                    i += 1;
                    (t.state != CorrespondenceState::Unknown).then_some(*t)
                }
                (Some(t), None) => {
                    i += 1;
                    (t.state != CorrespondenceState::Unknown).then_some(*t)
                }
                (_, Some(&s)) => {
                    j += 1;
                    Some(Track::unknown(s))
                }
                (None, None) => None,
            };
            if let Some(t) = next {
                if self.scratch.len() < self.capacity {
                    self.scratch.push(t);
                } else {
                    self.overflow += 1;
                }
            }
        }
        std::mem::swap(&mut self.tracks, &mut self.scratch);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Point3, Vector3};

    fn edge() -> HeldEdge {
        HeldEdge {
            plane: EdgePlane::from_rays(Point3::origin(), &Vector3::x(), &Vector3::y()).unwrap(),
            hue: HueSignature {
                left_mean: 0.1,
                left_var: 0.0,
                right_mean: 0.5,
                right_var: 0.0,
                left_kept: 1.0,
                right_kept: 1.0,
            },
            polarity: 1,
            sensor: 0,
        }
    }

    #[test]
    fn figure_8_unknown_pending_accepted_and_back() {
        use CorrespondenceState::*;
        let k = 4;
        let mut t = Track::unknown(7);
        t.observe(edge(), k);
        assert_eq!(t.state, Pending);
        assert!(t.edge.is_some());
        t.observe(edge(), k);
        t.observe(edge(), k);
        assert_eq!(t.state, Pending);
        t.observe(edge(), k);
        assert_eq!(t.state, Accepted, "accepted after k = 4 consecutive observations");
        // Unobserved 1..k−1 frames: pending, the signature kept; observed again: accepted.
        t.miss(k);
        assert_eq!(t.state, Pending);
        t.miss(k);
        assert!(t.edge.is_some());
        t.observe(edge(), k);
        assert_eq!(t.state, Accepted);
        // Unobserved k consecutive frames: unknown, the signature dropped.
        for _ in 0..k {
            t.miss(k);
        }
        assert_eq!(t.state, Unknown);
        assert!(t.edge.is_none());
        // A fresh pending one that misses a frame must start its k observations again.
        t.observe(edge(), k);
        t.observe(edge(), k);
        t.miss(k);
        t.observe(edge(), k);
        assert_eq!(t.state, Pending);
    }

    #[test]
    fn visibility_update_removes_unknown_keeps_seen_inserts_new() {
        let mut table = CorrespondenceTable::new(8);
        table.reset_with([Track::unknown(1), Track::accepted(3, edge()), Track::unknown(5)].into_iter());
        table.update_visible(&[2, 5, 9]);
        let segs: Vec<u32> = table.tracks().iter().map(|t| t.segment).collect();
        assert_eq!(segs, vec![2, 3, 5, 9]);
        assert_eq!(table.tracks()[1].state, CorrespondenceState::Accepted);
        let mut small = CorrespondenceTable::new(2);
        small.update_visible(&[1, 2, 3]);
        assert_eq!(small.tracks().len(), 2);
        assert_eq!(small.overflow, 1);
    }
}
