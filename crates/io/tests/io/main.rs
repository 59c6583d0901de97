//! Integration tests of omnitrack-io's frames in: the replay mock camera, the live sources' pixel
//! conversions and a rig's capture devices; one test binary for several files, so that they link
//! once. The allocator counts, for the replay's steady state. (The USB3 Vision parser is a binary
//! of its own, `u3v.rs`: CI runs it again with every feature on.)

#[global_allocator]
static ALLOCATOR: omnitrack_testkit::Counting = omnitrack_testkit::Counting;

mod convert;
mod devices;
mod replay;
