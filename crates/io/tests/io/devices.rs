//! A rig's sensors as capture devices: two sensors that name one device (cropped out of one
//! image) become one capture device of two windows.

use omnitrack_core::rig::Rig;

/// `crop` (docs/interfaces.md): read, checked against the sensor's resolution, written back;
/// the two sensors naming one device become one capture device of two windows.
#[test]
fn a_crop_is_read_checked_written_back_and_makes_one_capture_device() {
    let two = |crop1: &str| {
        format!(
            "name = \"dual\"\n\
             [[sensors]]\nid = 0\nresolution = [640, 640]\nmodel = \"kb4\"\nintrinsics = [180.0, 180.0, 319.5, 319.5]\n\
             distortion = [0.0, 0.0, 0.0, 0.0]\nrotation_wxyz = [0.5, -0.5, 0.5, -0.5]\ntranslation_m = [0.03, 0.0, 0.0]\n\
             device = \"/dev/video0\"\ncrop = [0, 0, 640, 640]\n\
             [[sensors]]\nid = 1\nresolution = [640, 640]\nmodel = \"kb4\"\nintrinsics = [180.0, 180.0, 319.5, 319.5]\n\
             distortion = [0.0, 0.0, 0.0, 0.0]\nrotation_wxyz = [0.5, 0.5, 0.5, 0.5]\ntranslation_m = [-0.03, 0.0, 0.0]\n\
             device = \"/dev/video0\"\ncrop = {crop1}\n"
        )
    };
    let rig = Rig::from_toml_str(&two("[640, 0, 640, 640]"), "dual.toml").unwrap();
    assert_eq!(rig.sensors[1].crop, Some([640, 0, 640, 640]));
    assert_eq!(Rig::from_toml_str(&rig.to_toml_string(), "again.toml").unwrap(), rig);
    for (crop, expected) in [
        (
            "[640, 0, 600, 640]",
            "sensor 1, key 'crop': its width and height 600×640 must be the sensor's resolution",
        ),
        ("[640, 0, 640]", "sensor 1, key 'crop': must have 4 numbers, found 3"),
        (
            "[-1, 0, 640, 640]",
            "sensor 1, key 'crop': must be four whole pixel counts",
        ),
    ] {
        let e = Rig::from_toml_str(&two(crop), "dual.toml").unwrap_err().to_string();
        assert!(e.contains(expected), "{e:?} should contain {expected:?}");
    }
    let devices = omnitrack_io::capture::device::capture_devices(&rig).unwrap();
    assert_eq!(devices.len(), 1);
    assert_eq!(devices[0].label, "sensors 0 and 1");
    assert_eq!((devices[0].width, devices[0].height), (1280, 640));
}
