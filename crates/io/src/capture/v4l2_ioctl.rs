//! The real V4L2 control ioctls behind [`V4l2ControlIo`] (cargo feature `v4l`).
//!
//! In: an open V4L2 device's file descriptor. Out: `VIDIOC_QUERYCTRL`, `VIDIOC_G_CTRL`,
//! `VIDIOC_S_CTRL`, `VIDIOC_G_PARM` and `VIDIOC_S_PARM` issued with the kernel's structures
//! (the `v4l` crate's bindings), errors as errno values. What the controls mean is
//! [`super::control::v4l2`]'s; this file only moves the structures' fields.

use super::control::v4l2::{CaptureParm, QueryCtrl, V4l2ControlIo, EINVAL};
use std::os::raw::{c_int, c_void};
use v4l::v4l2;
use v4l::v4l_sys::{v4l2_control, v4l2_queryctrl, v4l2_streamparm};

/// `V4L2_BUF_TYPE_VIDEO_CAPTURE`.
const VIDEO_CAPTURE: u32 = 1;

/// The control ioctls of one open device (the descriptor stays owned by its `v4l::Device`).
pub struct DeviceControls {
    fd: c_int,
}

impl DeviceControls {
    pub fn new(device: &v4l::Device) -> DeviceControls {
        DeviceControls {
            fd: device.handle().fd(),
        }
    }

    /// # Safety of the calls below
    /// `arg` points at a live, zero-initialised structure of the size the request names: every
    /// call below passes one of its own locals.
    fn ioctl<T>(&self, request: v4l2::vidioc::_IOC_TYPE, arg: &mut T) -> Result<(), i32> {
        // SAFETY: see the doc above; the kernel writes at most size_of::<T>() bytes.
        unsafe { v4l2::ioctl(self.fd, request, arg as *mut T as *mut c_void) }
            .map_err(|e| e.raw_os_error().unwrap_or(EINVAL))
    }

    fn parm(&self) -> Result<v4l2_streamparm, i32> {
        // SAFETY: an all-zero v4l2_streamparm is a valid value of the C structure.
        let mut p: v4l2_streamparm = unsafe { std::mem::zeroed() };
        p.type_ = VIDEO_CAPTURE;
        self.ioctl(v4l2::vidioc::VIDIOC_G_PARM, &mut p)?;
        Ok(p)
    }
}

fn capture_parm(p: &v4l2_streamparm) -> CaptureParm {
    // SAFETY: the `capture` member is the one of a VIDEO_CAPTURE stream, which the type set.
    let c = unsafe { p.parm.capture };
    CaptureParm {
        capability: c.capability,
        numerator: c.timeperframe.numerator,
        denominator: c.timeperframe.denominator,
    }
}

impl V4l2ControlIo for DeviceControls {
    fn query_ctrl(&mut self, id: u32) -> Result<QueryCtrl, i32> {
        // SAFETY: an all-zero v4l2_queryctrl is a valid value of the C structure.
        let mut q: v4l2_queryctrl = unsafe { std::mem::zeroed() };
        q.id = id;
        self.ioctl(v4l2::vidioc::VIDIOC_QUERYCTRL, &mut q)?;
        let end = q.name.iter().position(|&b| b == 0).unwrap_or(q.name.len());
        Ok(QueryCtrl {
            id: q.id,
            kind: q.type_,
            name: String::from_utf8_lossy(&q.name[..end]).into_owned(),
            minimum: q.minimum,
            maximum: q.maximum,
            step: q.step,
            default_value: q.default_value,
            flags: q.flags,
        })
    }

    fn g_ctrl(&mut self, id: u32) -> Result<i32, i32> {
        let mut c = v4l2_control { id, value: 0 };
        self.ioctl(v4l2::vidioc::VIDIOC_G_CTRL, &mut c)?;
        Ok(c.value)
    }

    fn s_ctrl(&mut self, id: u32, value: i32) -> Result<i32, i32> {
        let mut c = v4l2_control { id, value };
        self.ioctl(v4l2::vidioc::VIDIOC_S_CTRL, &mut c)?;
        Ok(c.value)
    }

    fn g_parm(&mut self) -> Result<CaptureParm, i32> {
        self.parm().map(|p| capture_parm(&p))
    }

    fn s_parm(&mut self, numerator: u32, denominator: u32) -> Result<CaptureParm, i32> {
        // The driver's other capture parameters as they are, only the interval changed.
        let mut p = self.parm()?;
        // Writing a union's field is safe; the `capture` member is the one G_PARM filled.
        p.parm.capture.timeperframe.numerator = numerator;
        p.parm.capture.timeperframe.denominator = denominator;
        self.ioctl(v4l2::vidioc::VIDIOC_S_PARM, &mut p)?;
        Ok(capture_parm(&p))
    }
}
