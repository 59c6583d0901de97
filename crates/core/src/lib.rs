//! omnitrack-core: the shared vocabulary of the tracker, depending on no other omnitrack crate.
//!
//! In: rig files (TOML), building models (OBJ), trajectories (TUM), lines files (CSV). Out: the
//! types every layer above speaks — [`Pose`], [`geometry::Correspondence`] and
//! [`geometry::EdgePlane`], the lenses, [`Rig`], [`Model`] with its segments and spatial index,
//! timestamped poses, and the rig's frames ([`FrameSet`] of [`SensorImage`]s, plain data that
//! capture fills and the edge stage reads); and [`memory::resident`], which every layer's
//! start-up buffers go through so that they take their memory when they are made.
//!
//! A rig of one 50° pinhole looking along the rig's x axis, and where a point 3 m ahead lands:
//!
//! ```
//! use nalgebra::Point3;
//! use omnitrack_core::Rig;
//!
//! let rig = Rig::from_toml_str(
//!     "name = \"one\"\n[[sensors]]\nid = 0\nresolution = [640, 480]\nmodel = \"pinhole\"\n\
//!      intrinsics = [686.0, 686.0, 319.5, 239.5]\nrotation_wxyz = [0.5, -0.5, 0.5, -0.5]\n\
//!      translation_m = [0.0, 0.0, 0.0]\n",
//!     "one.toml",
//! )?;
//! let sensor = &rig.sensors[0];
//! let px = sensor.project_from_rig(&Point3::new(3.0, 0.0, 0.0)).expect("ahead, on the image");
//! assert!((px.x - 319.5).abs() < 1e-9 && (px.y - 239.5).abs() < 1e-9);
//! // And back: the ray through that pixel points along x.
//! let ray = sensor.ray_in_rig(&px).unwrap();
//! assert!((ray.x - 1.0).abs() < 1e-12);
//! // Behind the rig nothing is imaged.
//! assert!(sensor.project_from_rig(&Point3::new(-3.0, 0.0, 0.0)).is_none());
//! # Ok::<(), omnitrack_core::rig::RigError>(())
//! ```

pub mod frame;
pub mod geometry;
pub mod lines;
pub mod memory;
pub mod model;
pub mod rig;
pub mod status;
pub mod text_file;
pub mod trajectory;

pub use frame::{FrameSet, ImageFault, SensorImage};
pub use geometry::Pose;
pub use model::{Face, Model, Segment};
pub use rig::{Rig, Sensor};
