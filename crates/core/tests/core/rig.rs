//! The rig file: the shipped Ladybug2-like rig is what its comments claim, files round-trip, and
//! every bad file is refused with a message naming the file, the sensor and the key.

use nalgebra::{Point3, Vector3};
use omnitrack_core::rig::{Rig, Sensor};
use std::path::Path;

fn ladybug() -> Rig {
    omnitrack_testkit::shipped_rig()
}

/// Whether a sensor images the direction `d` (rig frame) of a point far away.
fn sees(s: &Sensor, d: Vector3<f64>) -> bool {
    s.project_from_rig(&(Point3::from(s.t_rig_sensor.translation.vector) + d * 1e3))
        .is_some()
}

fn dir(azimuth_deg: f64, elevation_deg: f64) -> Vector3<f64> {
    let (a, e) = (azimuth_deg.to_radians(), elevation_deg.to_radians());
    Vector3::new(a.cos() * e.cos(), a.sin() * e.cos(), e.sin())
}

#[test]
fn ladybug2_is_five_side_sensors_72_degrees_apart_and_one_looking_up() {
    let rig = ladybug();
    assert_eq!(rig.name, "ladybug2");
    assert_eq!(rig.sensors.len(), 6);
    for (i, s) in rig.sensors.iter().enumerate() {
        assert_eq!(s.id, i);
        assert_eq!((s.width, s.height), (384, 512), "portrait 512×384 sensors");
        assert!(matches!(s.lens, omnitrack_core::geometry::Lens::Kb4(_)));
        let axis = s.t_rig_sensor.rotation * Vector3::z();
        let centre = s.centre().coords;
        assert!(
            centre.norm() > 0.02 && centre.norm() < 0.08,
            "centre a few cm from the rig centre"
        );
        if i < 5 {
            let expected = dir(72.0 * i as f64, 0.0);
            assert!((axis - expected).norm() < 1e-12, "sensor {i} axis {axis:?}");
            let up_in_image = s.t_rig_sensor.rotation * -Vector3::y();
            assert!((up_in_image - Vector3::z()).norm() < 1e-12, "sensor {i} is upright");
        } else {
            assert!((axis - Vector3::z()).norm() < 1e-12);
        }
    }
}

#[test]
fn ladybug2_fields_of_view_overlap_by_a_few_degrees() {
    let rig = ladybug();
    // Neighbouring side sensors at the horizon.
    for i in 0..5 {
        let (a, b) = (&rig.sensors[i], &rig.sensors[(i + 1) % 5]);
        let shared = (0..36_000)
            .map(|k| k as f64 * 0.01)
            .filter(|&az| sees(a, dir(az, 0.0)) && sees(b, dir(az, 0.0)))
            .count() as f64
            * 0.01;
        assert!(
            (3.0..10.0).contains(&shared),
            "sensors {i}/{} share {shared}°",
            (i + 1) % 5
        );
    }
    // The top sensor meets every side sensor with room to spare, at every azimuth.
    let top = &rig.sensors[5];
    for az in (0..180).map(|k| 2.0 * k as f64) {
        let elevations: Vec<f64> = (0..=1800).map(|k| k as f64 * 0.05).collect();
        let side_max = elevations
            .iter()
            .copied()
            .filter(|&e| rig.sensors[..5].iter().any(|s| sees(s, dir(az, e))))
            .fold(f64::MIN, f64::max);
        let top_min = elevations
            .iter()
            .copied()
            .filter(|&e| sees(top, dir(az, e)))
            .fold(f64::MAX, f64::min);
        assert!(
            side_max - top_min >= 2.0,
            "azimuth {az}: sides reach {side_max}°, top starts at {top_min}°"
        );
    }
    // Below the horizon the side sensors reach at least 45° down.
    for az in (0..360).map(f64::from) {
        assert!(rig.sensors[..5].iter().any(|s| sees(s, dir(az, -45.0))), "azimuth {az}");
    }
}

#[test]
fn rig_round_trips_through_its_toml_bit_for_bit() {
    let rig = ladybug();
    let again = Rig::from_toml_str(&rig.to_toml_string(), "round-trip").unwrap();
    assert_eq!(rig, again);
}

const GOOD_SENSOR: &str = r#"
[[sensors]]
id = 0
resolution = [512, 384]
model = "pinhole"
intrinsics = [400.0, 400.0, 255.5, 191.5]
rotation_wxyz = [1.0, 0.0, 0.0, 0.0]
translation_m = [0.0, 0.0, 0.0]
"#;

fn with_second_sensor(body: &str) -> String {
    format!("name = \"t\"\n{GOOD_SENSOR}\n[[sensors]]\n{body}")
}

const KB4_SENSOR: &str = r#"id = 1
resolution = [512, 384]
model = "kb4"
intrinsics = [285.0, 285.0, 255.5, 191.5]
distortion = [0.0, 0.0, 0.0, 0.0]
rotation_wxyz = [1.0, 0.0, 0.0, 0.0]
translation_m = [0.0, 0.0, 0.1]
device = "/dev/video1""#;

fn error_of(text: &str) -> String {
    Rig::from_toml_str(text, "rig.toml").unwrap_err().to_string()
}

/// The most sensors a rig may have load; one more is refused (in the errors test below).
#[test]
fn a_rig_of_the_most_sensors_loads() {
    let text = format!(
        "name = \"t\"\n{}",
        (0..omnitrack_core::rig::MAX_SENSORS)
            .map(|i| GOOD_SENSOR.replace("id = 0", &format!("id = {i}")))
            .collect::<String>()
    );
    let rig = Rig::from_toml_str(&text, "rig.toml").unwrap();
    assert_eq!(rig.sensors.len(), omnitrack_core::rig::MAX_SENSORS);
}

#[test]
fn a_two_sensor_mixed_rig_loads() {
    let rig = Rig::from_toml_str(&with_second_sensor(KB4_SENSOR), "rig.toml").unwrap();
    assert_eq!(rig.sensors[1].device.as_deref(), Some("/dev/video1"));
    assert!((rig.sensors[1].centre().z - 0.1).abs() < 1e-15);
}

#[test]
fn bad_rig_files_name_the_file_the_sensor_and_the_key() {
    let edit = |from: &str, to: &str| with_second_sensor(&KB4_SENSOR.replace(from, to));
    let cases: Vec<(String, &str)> = vec![
        (
            edit("device", "colour"),
            "rig.toml: sensor 1, key 'colour': unknown key",
        ),
        (
            edit("[285.0, 285.0, 255.5, 191.5]", "[285.0, 255.5, 191.5]"),
            "rig.toml: sensor 1, key 'intrinsics': must have 4 numbers, found 3",
        ),
        (
            edit("[285.0, 285.0,", "[nan, 285.0,"),
            "rig.toml: sensor 1, key 'intrinsics': non-finite number",
        ),
        (
            edit("[285.0, 285.0,", "[-285.0, 285.0,"),
            "rig.toml: sensor 1, key 'intrinsics': focal lengths must be finite and positive",
        ),
        (
            edit("[1.0, 0.0, 0.0, 0.0]", "[1.0, 0.1, 0.0, 0.0]"),
            "rig.toml: sensor 1, key 'rotation_wxyz': quaternion [1.0, 0.1, 0.0, 0.0] is not unit",
        ),
        (
            edit("[0.0, 0.0, 0.1]", "[0.0, \"a\", 0.1]"),
            "rig.toml: sensor 1, key 'translation_m': expected a number, found string",
        ),
        (edit("id = 1", "id = 0"), "rig.toml: sensor 0, key 'id': duplicate id"),
        (
            edit("id = 1", "id = 7"),
            "rig.toml: sensor 7, key 'id': ids must be 0..1 for 2 sensors",
        ),
        (
            edit("model = \"kb4\"", "model = \"fisheye\""),
            "rig.toml: sensor 1, key 'model': unknown lens model \"fisheye\"",
        ),
        (
            edit("distortion = [0.0, 0.0, 0.0, 0.0]\n", ""),
            "rig.toml: sensor 1, key 'distortion': missing",
        ),
        (
            edit("[0.0, 0.0, 0.0, 0.0]", "[-3.0, 0.0, 0.0, 0.0]"),
            "rig.toml: sensor 1, key 'distortion': distortion [-3.0, 0.0, 0.0, 0.0] folds the image",
        ),
        (
            edit("[512, 384]", "[512.5, 384]"),
            "rig.toml: sensor 1, key 'resolution': must be two positive whole pixel counts",
        ),
        (
            // `check` passed it and `run` aborted allocating 51 GB for its edge stage.
            edit("[512, 384]", "[65535, 65535]"),
            "rig.toml: sensor 1, key 'resolution': 65535×65535 is 4294836225 pixels, more than a sensor can have",
        ),
        (
            edit("model = \"kb4\"\n", ""),
            "rig.toml: sensor 1, key 'model': missing",
        ),
        (
            edit("id = 1\n", ""),
            "rig.toml: sensor entry 2 (of 2): key 'id' is missing",
        ),
        (
            with_second_sensor(&KB4_SENSOR.replace("model = \"kb4\"", "model = \"pinhole\"")),
            "rig.toml: sensor 1, key 'distortion': not allowed for model \"pinhole\"",
        ),
        (
            format!("name = \"t\"\nextra = 1\n{GOOD_SENSOR}"),
            "rig.toml: key 'extra': unknown key",
        ),
        (
            "name = \"t\"\n".to_string(),
            "rig.toml: key 'sensors': no [[sensors]] entries",
        ),
        ("name = [\n".to_string(), "rig.toml: not valid TOML:"),
        (
            format!(
                "name = \"t\"\n{}",
                (0..17)
                    .map(|i| GOOD_SENSOR.replace("id = 0", &format!("id = {i}")))
                    .collect::<String>()
            ),
            "rig.toml: key 'sensors': 17 sensors; a rig may have at most 16",
        ),
    ];
    for (text, expected) in cases {
        let e = error_of(&text);
        assert!(e.starts_with(expected), "{e:?}\nshould start with {expected:?}");
        assert!(!e.contains('\n'), "one line: {e:?}");
    }
    let missing = Rig::load(Path::new("/no/rig.toml")).unwrap_err().to_string();
    assert!(missing.starts_with("/no/rig.toml: cannot read rig file"), "{missing}");
}

/// The sphere lens models in a rig file (issue 49): `ds` [ξ, α], `eucm` [α, β] and `omni`
/// [ξ, k1, k2, p1, p2] in `distortion`, read, written back bit for bit, and refused in one line
/// naming the model's parameters when they are wrong.
#[test]
fn sphere_lens_models_read_write_and_refuse_by_name() {
    let sensor = |model: &str, distortion: &str| {
        KB4_SENSOR
            .replace("model = \"kb4\"", &format!("model = \"{model}\""))
            .replace(
                "distortion = [0.0, 0.0, 0.0, 0.0]",
                &format!("distortion = {distortion}"),
            )
    };
    for (model, distortion) in [
        ("ds", "[-0.2, 0.5]"),
        ("eucm", "[0.63, 1.04]"),
        ("omni", "[0.92, -0.26, 0.07, 0.0002, 1.8e-5]"),
    ] {
        let text = with_second_sensor(&sensor(model, distortion));
        let rig = Rig::from_toml_str(&text, "rig.toml").unwrap();
        assert_eq!(rig.sensors[1].lens.model_name(), model);
        assert_eq!(Rig::from_toml_str(&rig.to_toml_string(), "again.toml").unwrap(), rig);
    }
    for (model, distortion, says) in [
        (
            "ds",
            "[-0.2, 0.5, 0.1]",
            "rig.toml: sensor 1, key 'distortion': must have 2 numbers, found 3 (model \"ds\" takes [ξ, α])",
        ),
        (
            "omni",
            "[0.9, 0.0, 0.0, 0.0]",
            "sensor 1, key 'distortion': must have 5 numbers, found 4 (model \"omni\" takes [ξ, k1, k2, p1, p2])",
        ),
        ("eucm", "[0.6, -1.0]", "sensor 1, key 'distortion': eucm: β must be positive, found -1"),
        ("ds", "[2.0, 0.5]", "sensor 1, key 'distortion': ds: ξ must be in [−1, 1], found 2"),
        ("fov", "[0.9]", "unknown lens model \"fov\" (expected \"kb4\", \"pinhole\", \"radtan\", \"equirectangular\", \"ds\", \"eucm\" or \"omni\")"),
    ] {
        let e = error_of(&with_second_sensor(&sensor(model, distortion)));
        assert!(e.contains(says), "{e:?} should say {says:?}");
        assert!(!e.contains('\n'));
    }
}
