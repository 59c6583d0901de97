//! A fake V4L2 device at the ioctl level: controls with the kernel's `v4l2_queryctrl` fields,
//! answering as the V4L2 control framework does (EINVAL for an unknown control or menu index,
//! EACCES for read-only and write-only ones, ERANGE out of range unless the driver clamps,
//! values rounded to the step), and a frame interval that snaps to the nearest the device offers.

use omnitrack_io::capture::control::v4l2::*;

#[derive(Debug, Clone)]
pub struct FakeCtrl {
    pub query: QueryCtrl,
    pub value: i32,
    /// The hardware ignores writes: G_CTRL keeps returning this value.
    pub stuck: bool,
    /// S_CTRL accepts only values up to here (a range that shrank after the query, as an
    /// exposure limited by the frame interval does on some sensors).
    pub accepts_up_to: Option<i32>,
}

pub struct FakeV4l2 {
    pub controls: Vec<FakeCtrl>,
    pub capability: u32,
    /// Frame intervals offered, as (numerator, denominator) seconds.
    pub intervals: Vec<(u32, u32)>,
    pub interval: (u32, u32),
    /// Every ioctl, in order, for the tests to look at.
    pub log: Vec<String>,
}

/// A control of `[minimum, maximum, step]`.
pub fn ctrl(id: u32, kind: u32, name: &str, [min, max, step]: [i32; 3], value: i32, flags: u32) -> FakeCtrl {
    FakeCtrl {
        query: QueryCtrl {
            id,
            kind,
            name: name.into(),
            minimum: min,
            maximum: max,
            step,
            default_value: value,
            flags,
        },
        value,
        stuck: false,
        accepts_up_to: None,
    }
}

impl FakeV4l2 {
    /// A UVC webcam: exposure menu of manual (1) and aperture priority (3) only, exposure in
    /// 100 µs from 3 to 2047, gain 0–255, auto gain, auto white balance, 15/30/60 Hz.
    pub fn uvc() -> FakeV4l2 {
        FakeV4l2 {
            controls: vec![
                ctrl(CID_EXPOSURE_AUTO, TYPE_MENU, "Auto Exposure", [1, 3, 1], 3, 0),
                ctrl(
                    CID_EXPOSURE_ABSOLUTE,
                    TYPE_INTEGER,
                    "Exposure Time, Absolute",
                    [3, 2047, 1],
                    250,
                    FLAG_INACTIVE,
                ),
                ctrl(CID_GAIN, TYPE_INTEGER, "Gain", [0, 255, 1], 64, 0),
                ctrl(CID_AUTOGAIN, TYPE_BOOLEAN, "Gain, Automatic", [0, 1, 1], 1, 0),
                ctrl(
                    CID_AUTO_WHITE_BALANCE,
                    TYPE_BOOLEAN,
                    "White Balance, Automatic",
                    [0, 1, 1],
                    1,
                    0,
                ),
            ],
            capability: CAP_TIMEPERFRAME,
            intervals: vec![(1, 15), (1, 30), (1, 60)],
            interval: (1, 30),
            log: Vec::new(),
        }
    }

    pub fn control(&self, id: u32) -> &FakeCtrl {
        self.controls
            .iter()
            .find(|c| c.query.id == id)
            .expect("the fake has it")
    }

    pub fn control_mut(&mut self, id: u32) -> &mut FakeCtrl {
        self.controls
            .iter_mut()
            .find(|c| c.query.id == id)
            .expect("the fake has it")
    }

    fn find(&mut self, id: u32) -> Result<&mut FakeCtrl, i32> {
        self.controls.iter_mut().find(|c| c.query.id == id).ok_or(EINVAL)
    }
}

impl V4l2ControlIo for FakeV4l2 {
    fn query_ctrl(&mut self, id: u32) -> Result<QueryCtrl, i32> {
        self.log.push(format!("QUERYCTRL {id:#x}"));
        Ok(self.find(id)?.query.clone())
    }

    fn g_ctrl(&mut self, id: u32) -> Result<i32, i32> {
        self.log.push(format!("G_CTRL {id:#x}"));
        let c = self.find(id)?;
        if c.query.flags & FLAG_WRITE_ONLY != 0 {
            return Err(EACCES);
        }
        Ok(c.value)
    }

    fn s_ctrl(&mut self, id: u32, value: i32) -> Result<i32, i32> {
        self.log.push(format!("S_CTRL {id:#x} {value}"));
        let c = self.find(id)?;
        let q = &c.query;
        if q.flags & FLAG_READ_ONLY != 0 {
            return Err(EACCES);
        }
        if value < q.minimum || value > q.maximum || c.accepts_up_to.is_some_and(|m| value > m) {
            return Err(ERANGE);
        }
        let stepped = q.minimum + (value - q.minimum) / q.step.max(1) * q.step.max(1);
        if q.kind == TYPE_MENU && id == CID_EXPOSURE_AUTO && stepped == 2 {
            // A menu index the device does not list (UVC has no shutter priority here).
            return Err(EINVAL);
        }
        if !c.stuck {
            c.value = stepped;
        }
        let value = c.value;
        if id == CID_EXPOSURE_AUTO {
            // The framework marks the absolute exposure inactive while an auto mode runs.
            let manual = value == EXPOSURE_MANUAL;
            if let Ok(abs) = self.find(CID_EXPOSURE_ABSOLUTE) {
                abs.query.flags = if manual {
                    abs.query.flags & !FLAG_INACTIVE
                } else {
                    abs.query.flags | FLAG_INACTIVE
                };
            }
        }
        Ok(value)
    }

    fn g_parm(&mut self) -> Result<CaptureParm, i32> {
        self.log.push("G_PARM".into());
        Ok(CaptureParm {
            capability: self.capability,
            numerator: self.interval.0,
            denominator: self.interval.1,
        })
    }

    fn s_parm(&mut self, numerator: u32, denominator: u32) -> Result<CaptureParm, i32> {
        self.log.push(format!("S_PARM {numerator}/{denominator}"));
        if denominator == 0 {
            return Err(EINVAL);
        }
        if self.capability & CAP_TIMEPERFRAME != 0 {
            // The nearest interval the device offers, as uvcvideo picks it.
            let asked = f64::from(numerator) / f64::from(denominator);
            let best = self
                .intervals
                .iter()
                .min_by(|a, b| {
                    let d = |x: &(u32, u32)| (f64::from(x.0) / f64::from(x.1) - asked).abs();
                    d(a).total_cmp(&d(b))
                })
                .copied();
            if let Some(best) = best {
                self.interval = best;
            }
        }
        self.g_parm()
    }
}
