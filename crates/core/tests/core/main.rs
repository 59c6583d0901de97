//! Integration tests of omnitrack-core: lenses, rigs, models; one test binary for several files,
//! so that they link once.

mod control;
mod lens;
mod model;
mod rig;
