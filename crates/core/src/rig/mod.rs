//! The rig: N sensors, each a lens, an image size and a mounting `T_rig_sensor`.
//!
//! In: the rig TOML of docs/interfaces.md, "Rig file" (`firmware_config/*.toml`, `REC/rig.toml`).
//! Out: a validated [`Rig`]; every error is one line naming the file, the sensor and the key.
//! [`view`] says which directions the rig sees, [`reproject`] where model segments land in a
//! sensor's image.
//!
//! The TOML is walked by hand rather than through serde derive so that each message can say which
//! sensor (by id) a bad key belongs to, which serde's path-less errors cannot.

pub mod control;
pub mod reproject;
pub mod view;

pub use control::{CameraControl, Setting, Trigger};
pub use reproject::project_segments;
pub use view::ViewMap;

use crate::geometry::{
    pose_from_parts, rotation_to_wxyz, DoubleSphere, Equirectangular, Eucm, Kb4, Lens, Omni, Pinhole, Pose, Radtan,
};
use nalgebra::{Point2, Point3, Unit, Vector3};
use std::fmt::Write as _;
use std::path::Path;
use toml::{Table, Value};

/// The most pixels one sensor's image may have (8192 × 8192: twice a 32-megapixel
/// equirectangular panorama); the stages' buffers are sized by it.
pub const MAX_SENSOR_PIXELS: u64 = 1 << 26;

/// The most sensors a rig may have. The tracker keeps its per-sensor figures of a model segment
/// (its plane in each sensor, its arc, which edges it may meet) in fixed arrays that are copied
/// for every segment a search scores, so their size is fixed at build time; a rig of more is
/// refused when it is read rather than having sensors the tracker would leave out.
pub const MAX_SENSORS: usize = 16;

/// One camera of the rig.
#[derive(Debug, Clone, PartialEq)]
pub struct Sensor {
    /// 0..N-1, its index in [`Rig::sensors`].
    pub id: usize,
    pub width: u32,
    pub height: u32,
    pub lens: Lens,
    /// Sensor frame (OpenCV camera) → rig frame; its translation is the optical centre in the rig.
    pub t_rig_sensor: Pose,
    /// Live capture device (e.g. `/dev/video0`), if the rig file names one.
    pub device: Option<String>,
    /// Serial number of this sensor's USB3 Vision camera (`usb_serial`), if the rig file names
    /// one; either every sensor has one or none does (see [`UsbRig`]).
    pub usb_serial: Option<String>,
    /// `crop = [x, y, width, height]`: this sensor's image is that window of its device's frame
    /// (several sensors may share one device, e.g. a dual-fisheye camera); width and height are
    /// the sensor's resolution.
    pub crop: Option<[u32; 4]>,
    /// What the rig asks of this sensor's camera: its `[sensors.control]` keys over the rig's
    /// `[control]`; empty leaves the camera as it is ([`control`]).
    pub control: CameraControl,
}

/// How the rig's USB3 Vision cameras are found on the bus: the optional `[usb]` table.
///
/// Every camera with this vendor and product id is a candidate. When the sensors name their
/// `usb_serial`, each takes the camera with that serial number; when none does, the sensors take
/// the cameras in USB port order (bus number, then the port path from the root hub), so that the
/// mapping follows the cabling and survives replugging into the same ports.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UsbRig {
    pub vendor_id: u16,
    pub product_id: u16,
}

/// The whole camera rig: a generalised camera whose sensors do not share a centre.
#[derive(Debug, Clone, PartialEq)]
pub struct Rig {
    pub name: String,
    /// Indexed by sensor id.
    pub sensors: Vec<Sensor>,
    /// The `[usb]` table, for `--source usb`.
    pub usb: Option<UsbRig>,
    /// The rig-wide `[control]` table, every sensor's default (each sensor's merged control is
    /// [`Sensor::control`]); kept to write the file back as it was.
    pub control: CameraControl,
}

/// A rig file that cannot be used, with everything needed to fix it in one line.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{file}: {place}{message}")]
pub struct RigError {
    pub file: String,
    /// "sensor 3, key 'intrinsics': " or "" for file-level problems.
    pub place: String,
    pub message: String,
}

/// The lens models a rig file may name.
const LENS_MODELS: &str = "\"kb4\", \"pinhole\", \"radtan\", \"equirectangular\", \"ds\", \"eucm\" or \"omni\"";

const SENSOR_KEYS: [&str; 11] = [
    "id",
    "resolution",
    "model",
    "intrinsics",
    "distortion",
    "rotation_wxyz",
    "translation_m",
    "device",
    "usb_serial",
    "crop",
    "control",
];

impl Sensor {
    /// Optical centre in the rig frame.
    pub fn centre(&self) -> Point3<f64> {
        Point3::from(self.t_rig_sensor.translation.vector)
    }

    /// Whether a pixel lies on the image (pixel centres at integers, so the image spans
    /// [-0.5, width-0.5] × [-0.5, height-0.5]).
    pub fn contains(&self, px: &Point2<f64>) -> bool {
        px.x >= -0.5 && px.y >= -0.5 && px.x <= self.width as f64 - 0.5 && px.y <= self.height as f64 - 0.5
    }

    /// Largest angle (rad) between the optical axis and the ray through any pixel of the image:
    /// at a corner for the lenses centred on their axis (θd grows with distance from the
    /// principal point in normalised coordinates), at the middle of a side border for a panorama
    /// (whose corners are its poles, 90° off the axis, and whose side borders are straight
    /// behind). A corner without a ray lies past the lens's own border (a circular fisheye's
    /// image circle inside its sensor): then the image reaches that border, [`Lens::max_theta`].
    pub fn max_off_axis(&self) -> f64 {
        let (w, h) = (self.width as f64 - 0.5, self.height as f64 - 0.5);
        let (mu, mv) = (0.5 * (w - 0.5), 0.5 * (h - 0.5));
        let corners = [(-0.5, -0.5), (w, -0.5), (-0.5, h), (w, h)];
        if corners
            .iter()
            .any(|&(u, v)| self.lens.unproject(&Point2::new(u, v)).is_none())
        {
            return self.lens.max_theta();
        }
        corners
            .iter()
            .chain(&[(-0.5, mv), (w, mv), (mu, -0.5), (mu, h)])
            .filter_map(|&(u, v)| self.lens.unproject(&Point2::new(u, v)))
            .map(|r| r.z.clamp(-1.0, 1.0).acos())
            .fold(0.0, f64::max)
    }

    /// Unit ray through a pixel, in the rig frame (starting at [`Sensor::centre`]).
    pub fn ray_in_rig(&self, px: &Point2<f64>) -> Option<Unit<Vector3<f64>>> {
        let ray = self.lens.unproject(px)?;
        Some(Unit::new_unchecked(self.t_rig_sensor.rotation * ray.into_inner()))
    }

    /// Pixel of a rig-frame point if it lands on this sensor's image.
    pub fn project_from_rig(&self, p_rig: &Point3<f64>) -> Option<Point2<f64>> {
        let p = self.t_rig_sensor.inverse_transform_point(p_rig);
        self.lens.project(&p.coords).filter(|px| self.contains(px))
    }
}

impl Rig {
    /// Reads and validates a rig TOML file.
    pub fn load(path: &Path) -> Result<Rig, RigError> {
        let file = path.display().to_string();
        let text = crate::text_file::read_text(path, crate::text_file::SMALL_FILE_LIMIT).map_err(|e| RigError {
            file: file.clone(),
            place: String::new(),
            message: format!("cannot read rig file: {e}"),
        })?;
        Rig::from_toml_str(&text, &file)
    }

    /// Parses and validates rig TOML; `file` is the name used in error messages.
    pub fn from_toml_str(text: &str, file: &str) -> Result<Rig, RigError> {
        let err = |place: String, message: String| RigError {
            file: file.to_string(),
            place,
            message,
        };
        let table: Table = text.parse().map_err(|e: toml::de::Error| {
            err(String::new(), format!("not valid TOML: {}", one_line(&e.to_string())))
        })?;
        for key in table.keys() {
            if !["name", "sensors", "usb", "control"].contains(&key.as_str()) {
                return Err(err(
                    format!("key '{key}': "),
                    "unknown key (expected 'name', [[sensors]], an optional [usb] and an optional [control])".into(),
                ));
            }
        }
        let name = match table.get("name") {
            Some(Value::String(s)) if !s.trim().is_empty() => s.clone(),
            Some(_) => return Err(err("key 'name': ".into(), "must be a non-empty string".into())),
            None => return Err(err("key 'name': ".into(), "missing".into())),
        };
        let entries = match table.get("sensors") {
            Some(Value::Array(a)) if !a.is_empty() => a,
            Some(Value::Array(_)) | None => return Err(err("key 'sensors': ".into(), "no [[sensors]] entries".into())),
            Some(_) => {
                return Err(err(
                    "key 'sensors': ".into(),
                    "must be an array of tables ([[sensors]])".into(),
                ))
            }
        };
        if entries.len() > MAX_SENSORS {
            return Err(err(
                "key 'sensors': ".into(),
                format!("{} sensors; a rig may have at most {MAX_SENSORS}", entries.len()),
            ));
        }
        let control = control::rig_control(&table).map_err(|(key, m)| err(format!("key '{key}': "), m))?;
        let mut sensors: Vec<Option<Sensor>> = vec![None; entries.len()];
        for (index, entry) in entries.iter().enumerate() {
            let sensor = parse_sensor(entry, index, entries.len(), &control).map_err(|(place, m)| err(place, m))?;
            let id = sensor.id;
            if sensors[id].is_some() {
                return Err(err(format!("sensor {id}, key 'id': "), "duplicate id".into()));
            }
            sensors[id] = Some(sensor);
        }
        // N entries with unique ids in 0..N cover every slot.
        let sensors: Vec<Sensor> = sensors
            .into_iter()
            .map(|s| s.expect("ids are unique and in range"))
            .collect();
        let usb = match table.get("usb") {
            None => None,
            Some(v) => Some(parse_usb(v).map_err(|(place, m)| err(place, m))?),
        };
        check_usb_serials(&sensors).map_err(|(place, m)| err(place, m))?;
        Ok(Rig {
            name,
            sensors,
            usb,
            control,
        })
    }

    /// Pixels of the rig's largest sensor image (0 without sensors): what a buffer that any of
    /// its images may pass through is sized for.
    pub fn max_pixels(&self) -> usize {
        self.sensors
            .iter()
            .map(|s| s.width as usize * s.height as usize)
            .max()
            .unwrap_or(0)
    }

    /// The rig as TOML in the format of docs/interfaces.md ("Rig file"), with every number written
    /// so that it reads back bit-for-bit.
    pub fn to_toml_string(&self) -> String {
        let mut out = String::new();
        let _ = writeln!(out, "name = {}", Value::String(self.name.clone()));
        if let Some(usb) = &self.usb {
            let _ = writeln!(
                out,
                "\n[usb]\nvendor_id = 0x{:04x}\nproduct_id = 0x{:04x}",
                usb.vendor_id, usb.product_id
            );
        }
        if !self.control.is_empty() {
            let _ = write!(
                out,
                "\n[control]\n{}",
                self.control.toml_lines(&CameraControl::default())
            );
        }
        for s in &self.sensors {
            let _ = writeln!(out, "\n[[sensors]]\nid = {}", s.id);
            let _ = writeln!(out, "resolution = [{}, {}]", s.width, s.height);
            let dist = s.lens.parameters();
            let c = s.lens.principal_point();
            let intr = [s.lens.fx(), s.lens.fy(), c.x, c.y];
            let _ = writeln!(out, "model = \"{}\"", s.lens.model_name());
            let _ = writeln!(out, "intrinsics = {}", float_list(&intr));
            if let Some(k) = dist {
                let _ = writeln!(out, "distortion = {}", float_list(&k));
            }
            let _ = writeln!(
                out,
                "rotation_wxyz = {}",
                float_list(&rotation_to_wxyz(&s.t_rig_sensor.rotation))
            );
            let _ = writeln!(
                out,
                "translation_m = {}",
                float_list(s.t_rig_sensor.translation.vector.as_slice())
            );
            if let Some(d) = &s.device {
                let _ = writeln!(out, "device = {}", Value::String(d.clone()));
            }
            if let Some([x, y, w, h]) = s.crop {
                let _ = writeln!(out, "crop = [{x}, {y}, {w}, {h}]");
            }
            if let Some(serial) = &s.usb_serial {
                let _ = writeln!(out, "usb_serial = {}", Value::String(serial.clone()));
            }
            let own = s.control.toml_lines(&self.control);
            if !own.is_empty() {
                let _ = write!(out, "\n[sensors.control]\n{own}");
            }
        }
        out
    }
}

fn float_list(v: &[f64]) -> String {
    let items: Vec<String> = v.iter().map(|x| format!("{x:?}")).collect();
    format!("[{}]", items.join(", "))
}

/// TOML parser messages span several lines (source excerpt, caret); keep them to one.
pub fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

type PlaceError = (String, String);

fn parse_sensor(entry: &Value, index: usize, count: usize, rig_control: &CameraControl) -> Result<Sensor, PlaceError> {
    let at_entry = |m: &str| (format!("sensor entry {} (of {count}): ", index + 1), m.to_string());
    let Value::Table(t) = entry else {
        return Err(at_entry("must be a table ([[sensors]])"));
    };
    let id = match t.get("id") {
        Some(Value::Integer(i)) if (0..count as i64).contains(i) => *i as usize,
        Some(Value::Integer(i)) => {
            return Err((
                format!("sensor {i}, key 'id': "),
                format!("ids must be 0..{} for {count} sensors", count - 1),
            ))
        }
        Some(_) => return Err(at_entry("key 'id' must be an integer")),
        None => return Err(at_entry("key 'id' is missing")),
    };
    let place = |key: &str| format!("sensor {id}, key '{key}': ");
    let fail = |key: &str, m: String| (place(key), m);
    if let Some(key) = t.keys().find(|k| !SENSOR_KEYS.contains(&k.as_str())) {
        return Err(fail(key, format!("unknown key (allowed: {})", SENSOR_KEYS.join(", "))));
    }
    let numbers = |key: &str, n: usize| -> Result<Vec<f64>, PlaceError> {
        let v = t.get(key).ok_or_else(|| fail(key, "missing".into()))?;
        let Value::Array(a) = v else {
            return Err(fail(key, format!("must be an array of {n} numbers")));
        };
        if a.len() != n {
            return Err(fail(key, format!("must have {n} numbers, found {}", a.len())));
        }
        a.iter()
            .map(|x| match x {
                Value::Float(f) if f.is_finite() => Ok(*f),
                Value::Integer(i) => Ok(*i as f64),
                Value::Float(f) => Err(fail(key, format!("non-finite number {f}"))),
                other => Err(fail(key, format!("expected a number, found {}", other.type_str()))),
            })
            .collect()
    };
    let resolution = numbers("resolution", 2)?;
    if resolution
        .iter()
        .any(|&r| !(1.0..=65535.0).contains(&r) || r.fract() != 0.0)
    {
        return Err(fail(
            "resolution",
            format!("must be two positive whole pixel counts, found {resolution:?}"),
        ));
    }
    // Every stage sizes its buffers by the sensors' pixels (the edge stage about a dozen bytes a
    // pixel): a sensor larger than any camera makes is refused here, before a run allocates for
    // it and aborts.
    let pixels = resolution[0] * resolution[1];
    if pixels > MAX_SENSOR_PIXELS as f64 {
        return Err(fail(
            "resolution",
            format!(
                "{}×{} is {pixels} pixels, more than a sensor can have here ({MAX_SENSOR_PIXELS}, 8192×8192)",
                resolution[0], resolution[1]
            ),
        ));
    }
    let model = match t.get("model") {
        Some(Value::String(s)) => s.as_str(),
        Some(_) => return Err(fail("model", format!("must be a string: {LENS_MODELS}"))),
        None => return Err(fail("model", format!("missing ({LENS_MODELS})"))),
    };
    let i = numbers("intrinsics", 4)?;
    // A sphere model's parameters, the error naming the model and what it takes.
    let params = |n: usize, names: &str| {
        numbers("distortion", n).map_err(|(p, m)| (p, format!("{m} (model \"{model}\" takes [{names}])")))
    };
    let lens = match model {
        "kb4" => {
            let k = numbers("distortion", 4)?;
            Kb4::new(i[0], i[1], i[2], i[3], [k[0], k[1], k[2], k[3]]).map(Lens::Kb4)
        }
        "radtan" => {
            let n = match t.get("distortion") {
                Some(Value::Array(a)) if a.len() == 4 || a.len() == 5 => a.len(),
                Some(Value::Array(a)) => {
                    return Err(fail(
                        "distortion",
                        format!("must have 4 or 5 numbers (k1, k2, p1, p2[, k3]), found {}", a.len()),
                    ))
                }
                _ => 4,
            };
            let d = numbers("distortion", n)?;
            Radtan::new(i[0], i[1], i[2], i[3], &d).map(Lens::Radtan)
        }
        "ds" => {
            let d = params(2, "ξ, α")?;
            DoubleSphere::new(i[0], i[1], i[2], i[3], d[0], d[1]).map(Lens::DoubleSphere)
        }
        "eucm" => {
            let d = params(2, "α, β")?;
            Eucm::new(i[0], i[1], i[2], i[3], d[0], d[1]).map(Lens::Eucm)
        }
        "omni" => {
            let d = params(5, "ξ, k1, k2, p1, p2")?;
            Omni::new(i[0], i[1], i[2], i[3], d[0], [d[1], d[2], d[3], d[4]]).map(Lens::Omni)
        }
        "pinhole" | "equirectangular" => {
            if t.contains_key("distortion") {
                return Err(fail("distortion", format!("not allowed for model \"{model}\"")));
            }
            if model == "pinhole" {
                Pinhole::new(i[0], i[1], i[2], i[3]).map(Lens::Pinhole)
            } else {
                Equirectangular::new(i[0], i[1], i[2], i[3]).map(Lens::Equirectangular)
            }
        }
        other => {
            return Err(fail(
                "model",
                format!("unknown lens model \"{other}\" (expected {LENS_MODELS})"),
            ))
        }
    };
    let lens = lens.map_err(|e| {
        let key = if matches!(
            e,
            crate::geometry::LensError::BadDistortion { .. }
                | crate::geometry::LensError::Folds { .. }
                | crate::geometry::LensError::BadParameter(_)
        ) {
            "distortion"
        } else {
            "intrinsics"
        };
        fail(key, e.to_string())
    })?;
    let q = numbers("rotation_wxyz", 4)?;
    let tr = numbers("translation_m", 3)?;
    let t_rig_sensor = pose_from_parts([tr[0], tr[1], tr[2]], [q[0], q[1], q[2], q[3]])
        .map_err(|m| fail("rotation_wxyz", m.to_string()))?;
    let device = match t.get("device") {
        None => None,
        Some(Value::String(s)) if !s.is_empty() => Some(s.clone()),
        Some(_) => {
            return Err(fail(
                "device",
                "must be a non-empty string such as \"/dev/video0\"".into(),
            ))
        }
    };
    let usb_serial = match t.get("usb_serial") {
        None => None,
        Some(Value::String(s)) if !s.trim().is_empty() => Some(s.clone()),
        Some(_) => {
            return Err(fail(
                "usb_serial",
                "must be a non-empty string (the camera's USB serial number)".into(),
            ))
        }
    };
    let crop = match t.get("crop") {
        None => None,
        Some(_) => {
            let c = numbers("crop", 4)?;
            if c.iter().any(|&v| !(0.0..=65535.0).contains(&v) || v.fract() != 0.0) {
                return Err(fail(
                    "crop",
                    format!("must be four whole pixel counts [x, y, width, height], found {c:?}"),
                ));
            }
            if (c[2], c[3]) != (resolution[0], resolution[1]) {
                return Err(fail(
                    "crop",
                    format!(
                        "its width and height {}×{} must be the sensor's resolution {}×{}",
                        c[2], c[3], resolution[0], resolution[1]
                    ),
                ));
            }
            Some([c[0] as u32, c[1] as u32, c[2] as u32, c[3] as u32])
        }
    };
    let own = match t.get("control") {
        None => CameraControl::default(),
        Some(v) => control::parse_control(v).map_err(|(key, m)| fail(&key, m))?,
    };
    let control = rig_control.overridden_by(&own);
    if let Some((key, m)) = control.contradiction() {
        return Err(fail(&key, m));
    }
    Ok(Sensor {
        id,
        width: resolution[0] as u32,
        height: resolution[1] as u32,
        lens,
        t_rig_sensor,
        device,
        usb_serial,
        crop,
        control,
    })
}

const USB_KEYS: [&str; 2] = ["vendor_id", "product_id"];

/// The optional `[usb]` table: `vendor_id` and `product_id`, integers 0..=0xFFFF (hex allowed).
fn parse_usb(v: &Value) -> Result<UsbRig, PlaceError> {
    let Value::Table(t) = v else {
        return Err((
            "key 'usb': ".into(),
            "must be a table ([usb] with vendor_id and product_id)".into(),
        ));
    };
    if let Some(key) = t.keys().find(|k| !USB_KEYS.contains(&k.as_str())) {
        return Err((
            format!("[usb], key '{key}': "),
            format!("unknown key (allowed: {})", USB_KEYS.join(", ")),
        ));
    }
    let id = |key: &str| -> Result<u16, PlaceError> {
        let place = format!("[usb], key '{key}': ");
        match t.get(key) {
            Some(Value::Integer(i)) => {
                u16::try_from(*i).map_err(|_| (place, format!("must be a USB id 0..=0xFFFF, found {i}")))
            }
            Some(_) => Err((place, "must be an integer such as 0x1e10".into())),
            None => Err((place, "missing".into())),
        }
    };
    Ok(UsbRig {
        vendor_id: id("vendor_id")?,
        product_id: id("product_id")?,
    })
}

/// Either every sensor names its `usb_serial` or none does, and no two name the same one.
fn check_usb_serials(sensors: &[Sensor]) -> Result<(), PlaceError> {
    let named = sensors.iter().filter(|s| s.usb_serial.is_some()).count();
    if named == 0 {
        return Ok(());
    }
    if let Some(s) = sensors.iter().find(|s| s.usb_serial.is_none()) {
        return Err((
            format!("sensor {}, key 'usb_serial': ", s.id),
            format!(
                "missing, while {named} other sensor(s) have one: name it for every sensor or for none \
                 (then the cameras are taken in USB port order)"
            ),
        ));
    }
    for (i, a) in sensors.iter().enumerate() {
        // Sensors cropped from one camera's frame share its serial (a dual-fisheye camera).
        if let Some(b) = sensors[..i]
            .iter()
            .find(|b| b.usb_serial == a.usb_serial && (a.crop.is_none() || b.crop.is_none()))
        {
            return Err((
                format!("sensor {}, key 'usb_serial': ", a.id),
                format!(
                    "duplicate serial '{}' (also sensor {}); sensors sharing one camera each need a crop",
                    a.usb_serial.as_deref().unwrap_or_default(),
                    b.id
                ),
            ));
        }
    }
    Ok(())
}
