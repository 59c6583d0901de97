//! omnitrack: 6-DOF egomotion of an omnidirectional camera rig inside a known building model.
//!
//! Koch & Teller 2007 (edge-to-segment matching, INIT-SEGMENT-EDGE, maintenance, prior
//! visibility) on the line pose solvers of Kumar & Hanson 1989. Module per stage; the maths
//! (`geometry`) depends on nothing else here.

pub mod capture;
pub mod config;
pub mod edges;
pub mod geometry;
pub mod lines;
pub mod model;
pub mod publish;
pub mod rig;
pub mod runtime;
pub mod solver;
pub mod tracker;
pub mod trajectory;
pub mod visibility;

#[cfg(feature = "desk")]
pub mod desk;

pub use geometry::Pose;
pub use model::{Face, Model, Segment};
pub use rig::{Rig, Sensor};
