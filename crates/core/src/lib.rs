//! omnitrack-core: the shared vocabulary of the tracker, depending on no other omnitrack crate.
//!
//! In: rig files (TOML), building models (OBJ), trajectories (TUM), lines files (CSV). Out: the
//! types every layer above speaks — [`Pose`], [`geometry::Correspondence`] and
//! [`geometry::EdgePlane`], the lenses, [`Rig`], [`Model`] with its segments and spatial index,
//! timestamped poses, and the rig's frames ([`FrameSet`] of [`SensorImage`]s, plain data that
//! capture fills and the edge stage reads).

pub mod frame;
pub mod geometry;
pub mod lines;
pub mod model;
pub mod rig;
pub mod text_file;
pub mod trajectory;

pub use frame::{FrameSet, ImageFault, SensorImage};
pub use geometry::Pose;
pub use model::{Face, Model, Segment};
pub use rig::{Rig, Sensor};
