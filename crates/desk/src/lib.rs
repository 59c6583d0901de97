//! Offline (desk) work: building models from floor plans, and the other inputs and checks prepared
//! on a workstation, never on the device path. Compiled only with the `desk` feature (on by
//! default); the device build (`--no-default-features`) leaves it and its dependencies out.

pub mod basalt;
pub mod calib_rig;
pub mod demo;
pub mod eval;
pub mod floorplan;
pub mod kalibr;
pub mod observations;
pub mod opencv_calib;
pub mod pictures;
pub mod recording;
pub mod render;
pub mod results;
pub mod scenario;
pub mod vis_truth;
