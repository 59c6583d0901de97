//! The rig file's `[control]` tables: absent means nothing asked, a sensor's keys override the
//! rig's, the merged tables round-trip, and every bad value is one line naming the file, the
//! sensor and the key.

use omnitrack_core::rig::{CameraControl, Rig, Setting, Trigger};

fn sensor(id: usize, extra: &str) -> String {
    format!(
        "[[sensors]]\nid = {id}\nresolution = [64, 48]\nmodel = \"pinhole\"\nintrinsics = [50.0, 50.0, 31.5, 23.5]\n\
         rotation_wxyz = [1.0, 0.0, 0.0, 0.0]\ntranslation_m = [0.0, 0.0, 0.0]\n{extra}\n"
    )
}

fn rig(top: &str, s0: &str, s1: &str) -> Result<Rig, String> {
    let text = format!("name = \"c\"\n{top}\n{}{}", sensor(0, s0), sensor(1, s1));
    Rig::from_toml_str(&text, "cam.toml").map_err(|e| e.to_string())
}

#[test]
fn no_table_asks_nothing_and_sensor_keys_override_the_rigs() {
    let plain = rig("", "", "").unwrap();
    assert!(plain.control.is_empty() && plain.sensors.iter().all(|s| s.control.is_empty()));
    let r = rig(
        "[control]\nexposure_us = 5000\ngain = \"auto\"\nwhite_balance = \"off\"\nframe_rate_hz = 30",
        "",
        "[sensors.control]\nexposure_us = \"auto\"\ngain = 6.5",
    )
    .unwrap();
    let c0 = &r.sensors[0].control;
    assert_eq!(c0.exposure_us, Some(Setting::Fixed(5000.0)));
    assert_eq!(c0.gain, Some(Setting::Auto));
    assert_eq!(c0.white_balance_auto, Some(false));
    assert_eq!(c0.frame_rate_hz, Some(30.0));
    assert_eq!(c0.trigger, None);
    let c1 = &r.sensors[1].control;
    assert_eq!(c1.exposure_us, Some(Setting::Auto));
    assert_eq!(c1.gain, Some(Setting::Fixed(6.5)));
    assert_eq!(c1.frame_rate_hz, Some(30.0), "kept from the rig's table");
    assert_eq!(c0.differing_keys(c1), vec!["exposure_us", "gain"]);
    // Written and read back: the same merged tables.
    let again = Rig::from_toml_str(&r.to_toml_string(), "again.toml").unwrap();
    assert_eq!(again, r);
    let triggered = rig(
        "[control]\ntrigger = \"Line1\"",
        "[sensors.control]\ntrigger = \"off\"",
        "",
    )
    .unwrap();
    assert_eq!(triggered.sensors[0].control.trigger, Some(Trigger::Off));
    assert_eq!(
        triggered.sensors[1].control.trigger,
        Some(Trigger::Line("Line1".into()))
    );
    assert_eq!(Rig::from_toml_str(&triggered.to_toml_string(), "t").unwrap(), triggered);
    assert_eq!(
        CameraControl::default().overridden_by(&c1.clone()),
        c1.clone(),
        "an empty base takes the override whole"
    );
}

#[test]
fn bad_control_values_name_the_file_the_sensor_and_the_key() {
    let cases: [(&str, &str, &str); 10] = [
        ("[control]\nexposure = 5", "", "cam.toml: key 'control.exposure': unknown key (allowed: exposure_us, gain, frame_rate_hz, white_balance, trigger)"),
        ("", "[sensors.control]\nexposure_us = -3", "cam.toml: sensor 0, key 'control.exposure_us': must lie in (0, 10000000] µs, found -3"),
        ("", "[sensors.control]\nexposure_us = \"long\"", "cam.toml: sensor 0, key 'control.exposure_us': must be a time in microseconds or \"auto\", found \"long\""),
        ("", "[sensors.control]\ngain = true", "cam.toml: sensor 0, key 'control.gain': expected a number, found boolean"),
        ("", "[sensors.control]\nframe_rate_hz = 0", "cam.toml: sensor 0, key 'control.frame_rate_hz': must lie in (0, 10000] Hz, found 0"),
        ("", "[sensors.control]\nframe_rate_hz = nan", "cam.toml: sensor 0, key 'control.frame_rate_hz': non-finite number NaN"),
        ("", "[sensors.control]\nwhite_balance = false", "cam.toml: sensor 0, key 'control.white_balance': must be \"off\" or \"auto\""),
        ("", "[sensors.control]\ntrigger = \"Line 0\"", "cam.toml: sensor 0, key 'control.trigger': must be \"off\" or the trigger input's name, e.g. \"Line0\" (letters, digits, '_')"),
        ("[control]\nframe_rate_hz = 20", "[sensors.control]\ntrigger = \"Line0\"", "cam.toml: sensor 0, key 'control.frame_rate_hz': cannot be set with a hardware trigger (the trigger's pulses set the rate)"),
        ("control = 3", "", "cam.toml: key 'control': must be a table ([control] or [sensors.control])"),
    ];
    for (top, s0, want) in cases {
        let got = rig(top, s0, "").unwrap_err();
        assert_eq!(got, want);
        assert!(!got.contains('\n'));
    }
}
