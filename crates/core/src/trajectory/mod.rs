//! Trajectories: timestamped `T_world_rig` poses and the TUM text format
//! (`timestamp_s tx ty tz qx qy qz qw`, `#` comments), as `evo_ape tum` reads it.
//!
//! In: TUM text. Out: [`Trajectory`]; and back. Timestamps are nanoseconds inside, seconds with
//! nine decimals in the file, so a round trip is exact.

use crate::geometry::{pose_from_parts, Pose};
use std::fmt::Write as _;
use std::path::Path;

/// One pose of a trajectory.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stamped {
    pub timestamp_ns: u64,
    /// `T_world_rig`.
    pub pose: Pose,
}

/// Poses in time order.
pub type Trajectory = Vec<Stamped>;

/// A TUM file that cannot be read: `file:line: what is wrong`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{file}{}: {message}", line.map(|l| format!(":{l}")).unwrap_or_default())]
pub struct TumError {
    pub file: String,
    pub line: Option<usize>,
    pub message: String,
}

/// Parses TUM text; `file` names it in errors. Timestamps must not go backwards.
pub fn parse_tum(text: &str, file: &str) -> Result<Trajectory, TumError> {
    let err = |line: usize, message: String| TumError {
        file: file.to_string(),
        line: Some(line),
        message,
    };
    let mut out = Trajectory::new();
    for (i, line) in text.lines().enumerate() {
        let n = i + 1;
        let content = line.split('#').next().unwrap_or("").trim();
        if content.is_empty() {
            continue;
        }
        let fields: Vec<&str> = content.split_ascii_whitespace().collect();
        if fields.len() != 8 {
            return Err(err(
                n,
                format!(
                    "expected 8 fields (timestamp tx ty tz qx qy qz qw), found {}",
                    fields.len()
                ),
            ));
        }
        let timestamp_ns = parse_seconds(fields[0]).ok_or_else(|| err(n, format!("bad timestamp '{}'", fields[0])))?;
        let mut v = [0.0; 7];
        for (k, f) in fields[1..].iter().enumerate() {
            v[k] = f
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| err(n, format!("'{f}' is not a finite number")))?;
        }
        // TUM order is qx qy qz qw.
        let pose = pose_from_parts([v[0], v[1], v[2]], [v[6], v[3], v[4], v[5]]).map_err(|m| err(n, m.to_string()))?;
        if let Some(last) = out.last() {
            if timestamp_ns < last.timestamp_ns {
                return Err(err(n, "timestamp goes backwards".into()));
            }
        }
        out.push(Stamped { timestamp_ns, pose });
    }
    Ok(out)
}

/// Reads a TUM file.
pub fn load_tum(path: &Path) -> Result<Trajectory, TumError> {
    let (text, file) = read_tum_text(path)?;
    parse_tum(&text, &file)
}

/// The text of a TUM file and its name for messages.
fn read_tum_text(path: &Path) -> Result<(String, String), TumError> {
    let file = path.display().to_string();
    let text = crate::text_file::read_text(path, crate::text_file::LARGE_FILE_LIMIT).map_err(|e| TumError {
        file: file.clone(),
        line: None,
        message: format!("cannot read trajectory: {e}"),
    })?;
    Ok((text, file))
}

/// Reads a TUM file that its writer may have cut short (a full disk, a killed process): a last
/// line without its newline that does not parse is left out and returned as the note saying so.
/// Every other line must parse, as in [`load_tum`]: a bad line in the middle is a wrong file, not
/// a cut one.
pub fn load_tum_whole_lines(path: &Path) -> Result<(Trajectory, Option<TumError>), TumError> {
    let (text, file) = read_tum_text(path)?;
    match parse_tum(&text, &file) {
        Ok(t) => Ok((t, None)),
        Err(e) if !text.ends_with('\n') && e.line == Some(text.lines().count()) => {
            let whole = &text[..text.rfind('\n').map_or(0, |i| i + 1)];
            let t = parse_tum(whole, &file)?;
            let note = TumError {
                message: format!("the last line is cut off (no newline: {}); left out", e.message),
                ..e
            };
            Ok((t, Some(note)))
        }
        Err(e) => Err(e),
    }
}

/// Seconds written as a decimal (up to 9 places kept exactly) to nanoseconds.
fn parse_seconds(s: &str) -> Option<u64> {
    let (whole, frac) = s.split_once('.').unwrap_or((s, ""));
    if whole.is_empty() && frac.is_empty()
        || !whole.bytes().all(|b| b.is_ascii_digit())
        || !frac.bytes().all(|b| b.is_ascii_digit())
    {
        // Exponent forms and other spellings: fall back to floating point.
        let x: f64 = s.parse().ok()?;
        return (0.0..1.8e10).contains(&x).then(|| (x * 1e9).round() as u64);
    }
    let whole: u64 = if whole.is_empty() { 0 } else { whole.parse().ok()? };
    let mut nanos = 0u64;
    for (k, b) in frac.bytes().take(9).enumerate() {
        nanos += u64::from(b - b'0') * 10u64.pow(8 - k as u32);
    }
    whole.checked_mul(1_000_000_000)?.checked_add(nanos)
}

/// One TUM line (no newline) for a pose.
pub fn tum_line(s: &Stamped) -> String {
    let mut line = Vec::with_capacity(96);
    write_tum_line(&mut line, s).expect("writing to a Vec cannot fail");
    String::from_utf8(line).expect("the line is ASCII")
}

/// [`tum_line`], written straight into `out` (the device path's trajectory
/// file, where a String per frame would allocate).
pub fn write_tum_line<W: std::io::Write>(out: &mut W, s: &Stamped) -> std::io::Result<()> {
    let t = s.pose.translation.vector;
    let q = s.pose.rotation.quaternion();
    write!(
        out,
        "{}.{:09} {:.9} {:.9} {:.9} {:.12} {:.12} {:.12} {:.12}",
        s.timestamp_ns / 1_000_000_000,
        s.timestamp_ns % 1_000_000_000,
        t.x,
        t.y,
        t.z,
        q.i,
        q.j,
        q.k,
        q.w
    )
}

/// The whole trajectory as TUM text with a header comment.
pub fn to_tum_string(trajectory: &[Stamped]) -> String {
    let mut out = String::from("# timestamp_s tx ty tz qx qy qz qw (T_world_rig)\n");
    for s in trajectory {
        let _ = writeln!(out, "{}", tum_line(s));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Isometry3, Vector3};

    /// A last line cut off by its writer (no newline, does not parse) is left out and noted; a
    /// bad line anywhere else, or a last line that is whole, is still an error.
    #[test]
    fn a_cut_off_last_line_is_left_out_and_said() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.tum");
        let line = |k: u64| format!("{k}.5 1 2 3 0 0 0 1\n");
        let whole: String = (0..3).map(line).collect();
        for (text, poses, noted) in [
            (whole.clone(), Some(3), false),
            (format!("{whole}3.5 1 2"), Some(3), true),
            (format!("{whole}3.5 1 2\n"), None, false),
            (format!("{}x\n{}", line(0), line(1)), None, false),
        ] {
            std::fs::write(&path, &text).unwrap();
            match load_tum_whole_lines(&path) {
                Ok((t, note)) => {
                    assert_eq!((Some(t.len()), note.is_some()), (poses, noted), "{text:?}");
                    if let Some(n) = note {
                        assert_eq!(n.line, Some(4));
                        assert!(n.to_string().contains("cut off"), "{n}");
                    }
                }
                Err(e) => assert_eq!(poses, None, "{text:?}: {e}"),
            }
        }
    }

    #[test]
    fn round_trip_keeps_nanoseconds_and_poses() {
        let traj: Trajectory = (0..5)
            .map(|k| Stamped {
                timestamp_ns: 1_700_000_000_123_456_789 + k * 66_666_667,
                pose: Isometry3::new(Vector3::new(-1.5, 2.0 * k as f64, 1.6), Vector3::new(0.1, -0.2, 3.0)),
            })
            .collect();
        let back = parse_tum(&to_tum_string(&traj), "t.tum").unwrap();
        assert_eq!(back.len(), 5);
        for (a, b) in traj.iter().zip(&back) {
            assert_eq!(a.timestamp_ns, b.timestamp_ns);
            assert!((a.pose.translation.vector - b.pose.translation.vector).norm() < 1e-9);
            assert!(a.pose.rotation.angle_to(&b.pose.rotation) < 1e-11);
        }
    }

    #[test]
    fn bad_lines_name_the_line() {
        let e = parse_tum("# c\n0.1 0 0 0 0 0 0 1\n0.2 0 0 0 0 0 1\n", "g.tum")
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "g.tum:3: expected 8 fields (timestamp tx ty tz qx qy qz qw), found 7"
        );
        let e = parse_tum("0.1 0 0 x 0 0 0 1\n", "g.tum").unwrap_err().to_string();
        assert_eq!(e, "g.tum:1: 'x' is not a finite number");
        let e = parse_tum("0.2 0 0 0 0 0 0 1\n0.1 0 0 0 0 0 0 1\n", "g.tum")
            .unwrap_err()
            .to_string();
        assert_eq!(e, "g.tum:2: timestamp goes backwards");
        let e = parse_tum("0.1 0 0 0 0 0 0 2\n", "g.tum").unwrap_err().to_string();
        assert!(e.starts_with("g.tum:1: quaternion"), "{e}");
        assert_eq!(
            parse_tum("1e-3 0 0 0 0 0 0 1\n", "g.tum").unwrap()[0].timestamp_ns,
            1_000_000
        );
    }
}
