//! omnitrack-io: frames in from the sensors, poses out to other processes.
//!
//! In: V4L2 and USB3 Vision devices (features `v4l`, `usb`) or a recording on disk, chosen by a
//! typed `--source` spec ([`capture::SourceSpec`]). Out: multi-sensor frames with capture
//! timestamps ([`capture`], filling core's [`FrameSet`](omnitrack_core::frame::FrameSet)); pose
//! and status samples on iceoryx2 shared memory ([`publish`]). Depends on omnitrack-core only.

pub mod capture;
pub mod publish;
