//! The solvers' tests, one binary: Kumar–Hanson's solvers (`kh`) and Koch–Teller's side of
//! them (`kt`), on synthetic correspondences seen by one pinhole and by the shipped six-sensor
//! rig. The allocator counts, for the consensus sampler's test of zero allocations.

#[global_allocator]
static ALLOCATOR: omnitrack_testkit::Counting = omnitrack_testkit::Counting;

mod kh;
mod kt;
