//! Minimal problems: the pose, or a part of it, from the fewest observations that fix it, in
//! closed form. The robust estimators ([`crate::robust`]) and the tracker's initialiser draw
//! minimal samples and solve them here; [`crate::refine`] then takes every answer to the least
//! squares of all its lines.
//!
//! - [`three_lines`]: every rotation that puts three lines into their planes (Kumar–Hanson
//!   eq. 8 for three lines: a degree-8 polynomial), Med_R_and_T's subsets.
//! - [`wahba`](mod@wahba): the rotation of three normal pairs (Wahba's SVD) and the upright yaw alone,
//!   the initialiser's samples (Koch–Teller §4.1).
//! - [`translation`]: the translation of lines under a known rotation (Kumar–Hanson eq. 9).

pub mod three_lines;
pub mod translation;
pub mod wahba;

pub use three_lines::three_line_rotations;
pub use translation::translation_given_rotation;
pub use wahba::{wahba, yaw_fit};
