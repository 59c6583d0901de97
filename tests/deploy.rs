//! The deployment files (tools/deploy/), read as files: the udev rule takes cameras, not every
//! composite device.

use std::path::PathBuf;

fn read(path: &str) -> String {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(path);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The lines that are not comments or blank.
fn rules(text: &str) -> Vec<&str> {
    text.lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .collect()
}

/// USB3 Vision declares device class 0xEF, as every composite device does (webcams, headsets):
/// the rule matched them all. Cameras are matched by vendor id (product id optional), V4L2
/// devices by their subsystem, and the comment lists every vendor a rule takes.
#[test]
fn the_udev_rule_takes_cameras_by_vendor_never_by_class() {
    let text = read("tools/deploy/99-omnitrack.rules");
    let lines = rules(&text);
    assert!(
        lines.iter().any(|l| l.starts_with(r#"SUBSYSTEM=="video4linux""#)),
        "no V4L2 rule"
    );
    let mut vendors = Vec::new();
    for line in &lines {
        assert!(!line.contains("Class}"), "a class match: {line}");
        if line.contains(r#"SUBSYSTEM=="usb""#) {
            let vendor = line
                .split(r#"ATTR{idVendor}==""#)
                .nth(1)
                .and_then(|rest| rest.get(..4))
                .unwrap_or_else(|| panic!("a USB rule without a vendor id: {line}"));
            assert!(vendor.chars().all(|c| c.is_ascii_hexdigit()), "{line}");
            assert!(line.contains(r#"GROUP="omnitrack""#), "{line}");
            vendors.push(vendor);
        }
    }
    assert!(vendors.len() >= 5, "{vendors:?}");
    for vendor in vendors {
        assert!(text.contains(&format!("#   {vendor}  ")), "vendor {vendor} is not named in the comment");
    }
    assert!(text.contains("To add a camera"), "no word on adding a camera");
}
