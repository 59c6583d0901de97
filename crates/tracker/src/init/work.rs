//! The costs the search charges, in work units (about a microsecond of one core of the
//! reference machine, the 2-core x86-64 VM this was measured on: per step, the mean time over
//! the searches of the ZInD benchmark from the 1.5 and 3 m hints and of `lab`, within ±20 % of
//! both; a cell's cost fitted over 399 cells, median error 18 %). That VM's own pace varies by
//! ±30 % from one hour to the next, which is why the budget is not the clock.
//!
//! In: nothing (constants). Out: what each step of [`Initialiser::run`](super::Initialiser::run) is charged.

/// [`Initialiser::coarse_merit`](super::Initialiser): per segment scored, per 100 edges
/// it is scored against. With module `edge_index` and one pass over the pairs it hands out
/// for both shares, a score took 130 µs for 44 segments on the ZInD panoramas from 3 m
/// (charged 111). With the support scored in a second pass, `pano_29`'s search from 3 m
/// took 1.34 s on the clock for its 0.95 s of work; in one pass, 0.71 s.
pub const MERIT_PER_SEGMENT_100_EDGES: u64 = 1;
/// The coarse merit's blank test (`grid_blank`): points looked up per work unit, each a
/// transform, the view's cell and up to one cell per sensor in the map of directions near an
/// edge (70–75 ns per point on ZInD `pano_13`, `pano_14`, `pano_29` from 3 m).
pub const BLANK_POINTS_PER_UNIT: u64 = 14;
/// That map (module `near_edges`): cells marked per work unit (6.6 ns per cell on the same
/// panoramas; 590,000–820,000 cells, 4–5 ms, for 630–820 edges).
pub const NEAR_MARKS_PER_UNIT: u64 = 150;
/// The segments in sight from a position (ray cast against the model), at least.
pub const SIGHT: u64 = 400;
/// A polish (gathers and refits at three gates, the simplex, the scores), at least.
pub const POLISH: u64 = 5_000;
/// One truncated-ξ score of a pose, at least.
pub const SCORE: u64 = 450;
/// Occlusion rays cast per work unit. A step that casts rays is charged the larger of its
/// figure above (the mean over the ZInD house and `lab`, rays included) and its rays at
/// this rate: on those models the figures hold, and on a detailed one the rays decide
/// (FZK-Haus: a polish casts about 16,000, against 2,900 on the ZInD house; a ray costs
/// 0.43 µs there and 1.05 µs on FZK-Haus's 13,340 triangles).
pub const RAYS_PER_UNIT: u64 = 3;
/// The translation vote under one rotation, per edge voting.
pub const VOTE_PER_EDGE: u64 = 64;
/// One cell of INIT-SEGMENT-EDGE: fixed, per 50 triplet matches, per sample drawn.
pub const CELL: u64 = 600;
pub const CELL_PER_50_MATCHES: u64 = 1;
pub const CELL_PER_SAMPLE: u64 = 12;
