//! omnitrack-core: the shared vocabulary of the tracker, depending on no other omnitrack crate.
//!
//! In: rig files (TOML), building models (OBJ), trajectories (TUM), lines files (CSV). Out: the
//! types every layer above speaks — [`Pose`], [`geometry::Correspondence`] and
//! [`geometry::EdgePlane`], the lenses, [`Rig`], [`Model`] with its segments and spatial index,
//! and timestamped poses.

pub mod geometry;
pub mod lines;
pub mod model;
pub mod rig;
pub mod text_file;
pub mod trajectory;

pub use geometry::Pose;
pub use model::{Face, Model, Segment};
pub use rig::{Rig, Sensor};
