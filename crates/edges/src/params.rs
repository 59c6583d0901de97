//! The detector's tuning beyond tracker.toml: [`EdgeParams`] and its [`Smoothing`].
//!
//! In: nothing (defaults, or a benchmark's choices). Out: the thresholds and switches every
//! sensor's extraction reads (gradient, chains, fits, merges, hue strips, the a-contrario test,
//! the worker count); `Default` is what the benchmarks measured.

/// Smoothing of each colour channel before the Sobel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Smoothing {
    /// None: the plain 3×3 Sobel (edges 2 px apart stay apart, but noisier directions).
    None,
    /// The binomial [1 2 1]² (a 5×5 derivative: steadier directions and sub-pixel positions,
    /// but edges closer than ~3 px blend into one).
    Full,
    /// [1 2 1] along the derivative's cross axis only: each derivative is 3 px wide across
    /// (near-parallel edges 2–3 px apart stay apart) and 5 px long along the edge.
    Along,
}

/// Tuning of the detector beyond [`EdgeConfig`](omnitrack_config::EdgeConfig); `Default` is what the benchmarks measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdgeParams {
    /// Minimum L1 gradient magnitude |gx| + |gy| of an edgel: Sobel of the binomially smoothed
    /// grey image ×16 (a step of h grey levels gives ≈ 4h·16 = 64h across its peak).
    pub gradient_threshold: u16,
    /// Smoothing of each channel before the Sobel.
    pub smoothing: Smoothing,
    /// Chains shorter than this (edgels) are dropped.
    pub min_chain_edgels: usize,
    /// A chain is split where a ray deviates more than this (rad) from the great circle of the
    /// piece's end rays; pieces are merged when all their rays stay within it.
    pub split_tolerance_rad: f64,
    /// Pieces of different chains merge when their normals agree within this (rad)…
    pub merge_angle_rad: f64,
    /// …and the angular gap between them is at most this (rad)…
    pub merge_gap_rad: f64,
    /// …and the pieces cover at least this fraction of the merged edge's span (0: no check)…
    pub merge_min_support: f64,
    /// …and the image shows the line along at least this share of the gap between them (a
    /// gradient across the line within a pixel; 0: no check). Off by default: at 0.9 it raises
    /// YorkUrban precision from 17 to 30 % and recall from 63 to 68 %, and synthetic recall on
    /// most rows, but costs grey and very noisy frames 2–3 points and on the real ZInD
    /// panoramas two hinted runs settled 0.3 and 0.8 m off instead of within 10 cm (docs/decisions.md).
    pub merge_gap_evidence: f64,
    /// Distance (px) from the edge to the first pixel of each hue strip.
    pub hue_strip_offset_px: f32,
    /// At most this many positions along an edge piece are sampled for hue (evenly spread; a
    /// merged edge sums its pieces'). 16 would save a sixth of the edge stage's CPU, but the
    /// noisier signatures let maintenance lose its hold where 48 keep it (docs/decisions.md,
    /// 2026-11-30).
    pub hue_samples_per_edge: usize,
    /// Threads working on a frame, the calling thread included (0: available cores, at most 2).
    pub threads: usize,
    /// The two-line test, off at 0: a chain piece is cut, and two pieces are not merged, where
    /// one plane leaves more residual than two by more than noise explains and by more than
    /// lines ~2 × this × `split_tolerance_rad` apart would (0.3: ~0.6 px at the default). It
    /// keeps a wall corner and a box edge continuing it a pixel or two aside from becoming one
    /// tilted edge, and raises `lab` recall from 92.6 to 97.3 % (docs/edges.md). Below ~0.3 the pixel
    /// staircases of aliased images start to split single lines.
    pub two_line_excess: f64,
    /// Validate each piece of an edge (the CSV's `pieces`, [`Edge::shown`](crate::Edge::shown)) a contrario, as LSD
    /// does (Grompone von Gioi et al., IPOL 2012): keep it only where the number of pixels along
    /// it whose gradient is across the line (within 22.5°) makes its number of false alarms
    /// below 1. Off: every piece is shown. The edges themselves do not change.
    pub piece_nfa: bool,
    /// With `piece_nfa`, trim each piece to its first and last pixel whose gradient is across
    /// the line before the test (which only lowers its number of false alarms).
    pub piece_trim: bool,
}

impl EdgeParams {
    /// The defaults less what no tracker stage reads: the a-contrario test of the pieces each
    /// edge shows (`piece_nfa` off; [`Edge::shown`](crate::Edge::shown) then lists every piece
    /// between the gaps). The edges are the same in every other field: the test only
    /// decides which of an edge's pieces a line detector's user is shown.
    pub fn for_tracking() -> EdgeParams {
        EdgeParams {
            piece_nfa: false,
            ..EdgeParams::default()
        }
    }
}

impl Default for EdgeParams {
    fn default() -> Self {
        EdgeParams {
            gradient_threshold: 640,
            smoothing: Smoothing::Along,
            min_chain_edgels: 8,
            split_tolerance_rad: 0.2f64.to_radians(),
            merge_angle_rad: 5.0f64.to_radians(),
            merge_gap_rad: 10.0f64.to_radians(),
            merge_min_support: 0.0,
            merge_gap_evidence: 0.0,
            hue_strip_offset_px: 2.0,
            hue_samples_per_edge: 48,
            threads: 0,
            two_line_excess: 0.3,
            piece_nfa: true,
            piece_trim: true,
        }
    }
}
