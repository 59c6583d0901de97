//! `omnitrack run` as a black box: bad arguments and inputs are one line and a non-zero exit,
//! and a short replay writes a TUM trajectory (docs/interfaces.md, "Command line").

use crate::common::omnitrack;

fn last_line(s: &str) -> &str {
    s.trim_end().lines().last().unwrap_or("")
}

#[test]
fn bad_arguments_and_inputs_are_one_line_errors() {
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("room.obj");
    std::fs::write(&model, "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\n").unwrap();
    let model = model.to_str().unwrap();
    let missing = dir.path().join("nope");
    let replay = format!("replay:{}", missing.display());
    for (args, expected) in [
        (vec!["--source", "bogus"], "unknown source"),
        (vec!["--source", "replay:"], "recording directory"),
        (vec!["--source", &replay], "nope"),
        (vec!["--source", &replay, "--init", "1,2"], "x,y,z"),
        (
            vec!["--source", &replay, "--init", "1,2,3,-1"],
            "radius must be positive",
        ),
        (vec!["--source", &replay, "--init", "a,b,c"], "numbers"),
        (
            vec!["--source", &replay, "--trajectory", model],
            "refusing to overwrite",
        ),
        (
            vec!["--source", &replay, "--services", "/rig 2"],
            "--services \"/rig 2\": a prefix is",
        ),
    ] {
        let mut full = vec!["run", "--model", model, "--no-publish"];
        full.extend(args.iter().copied());
        let (code, stdout, stderr) = omnitrack(&full);
        assert_ne!(code, 0, "{full:?} should fail");
        assert!(stdout.is_empty(), "{full:?} printed on stdout: {stdout}");
        let line = last_line(&stderr);
        assert!(
            line.contains(expected),
            "{full:?}: {line:?} should mention {expected:?}"
        );
        assert!(!stderr.contains("panicked"), "{full:?} panicked: {stderr}");
    }
    // A model with nothing to match is refused before the source is opened.
    let empty = dir.path().join("empty.obj");
    std::fs::write(&empty, "v 0 0 0\n").unwrap();
    let (code, _, stderr) = omnitrack(&["run", "--model", empty.to_str().unwrap(), "--source", &replay]);
    assert_eq!(code, 2);
    assert!(last_line(&stderr).contains("the model has no segments"), "{stderr}");
}

/// clap's usage errors are one line too (its own report spans the problem, a tip and the usage);
/// `--help` still prints the whole help on stdout.
#[test]
fn usage_errors_are_one_line() {
    for (args, expected) in [
        (vec!["run", "--bogus"], "'--bogus'"),
        (vec!["run"], "--model"),
        (vec!["pose"], "--lines"),
        (vec!["visibility"], "build, query"),
        (
            vec!["run", "--model", "m.obj", "--source", "webcam"],
            "invalid value 'webcam' for '--source <replay:DIR|v4l|usb>': unknown source (expected replay:DIR, v4l or usb) (see omnitrack --help)",
        ),
        (vec![], "no command given"),
    ] {
        let (code, stdout, stderr) = omnitrack(&args);
        assert_eq!(code, 2, "{args:?}: {stderr}");
        assert!(stdout.is_empty(), "{args:?} printed on stdout: {stdout}");
        assert_eq!(stderr.trim_end().lines().count(), 1, "{args:?}: {stderr}");
        assert!(
            stderr.contains(expected),
            "{args:?}: {stderr:?} should mention {expected:?}"
        );
    }
    let (code, stdout, _) = omnitrack(&["run", "--help"]);
    assert_eq!(code, 0);
    assert!(stdout.contains("--trajectory"), "{stdout}");
}

#[cfg(feature = "desk")]
#[test]
fn a_short_replay_writes_a_tum_trajectory_near_the_truth() {
    use omnitrack::trajectory::load_tum;
    let lab = crate::common::lab_recording(6);
    let (dir, rec, truth) = (&lab.dir, &lab.rec, &lab.truth);
    let t0 = truth[0].pose.translation.vector;
    // A 1.5 m radius around a point 0.8 m from the true start.
    let init = format!("{},{},{},1.5", t0.x + 0.8, t0.y, t0.z);
    let (model, source) = (rec.join("model.obj"), format!("replay:{}", rec.display()));
    let run_to = |trajectory: &std::path::Path| {
        let model = model.to_str().unwrap();
        let trajectory = trajectory.to_str().unwrap().to_string();
        [
            "run",
            "--model",
            model,
            "--source",
            &source,
            "--init",
            &init,
            "--trajectory",
        ]
        .map(str::to_string)
        .into_iter()
        .chain([trajectory, "--no-publish".to_string()])
        .collect::<Vec<String>>()
    };
    let out = dir.path().join("est.tum");
    let args = run_to(&out);
    let (code, stdout, stderr) = omnitrack(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.is_empty());
    // The search's result is taken up a budget later on the recording's clock (frame 5 of 6),
    // and the frames kept meanwhile are tracked at the end, their poses in the file too.
    let est = load_tum(&out).unwrap();
    assert!(est.len() >= 5, "{} poses: {stderr}", est.len());
    for e in &est {
        let g = truth.iter().find(|g| g.timestamp_ns == e.timestamp_ns).unwrap();
        let d = (e.pose.translation.vector - g.pose.translation.vector).norm();
        assert!(d < 0.15, "{d} m off at {}", e.timestamp_ns);
    }

    // The disk fills up mid-run (a file size limit, its signal ignored as a full disk sends
    // none): the trajectory ends at its last whole line, the run goes on and says so.
    let cut = dir.path().join("cut.tum");
    let limit = std::fs::metadata(&out).unwrap().len() / 2;
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_omnitrack"));
    child.args(run_to(&cut));
    // SAFETY: between fork and exec the closure only makes two async-signal-safe system calls.
    unsafe {
        use std::os::unix::process::CommandExt;
        child.pre_exec(move || {
            let most = libc::rlimit {
                rlim_cur: limit,
                rlim_max: limit,
            };
            libc::setrlimit(libc::RLIMIT_FSIZE, &most);
            libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
            Ok(())
        });
    }
    let run = child.output().unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(0), "{stderr}");
    let text = std::fs::read_to_string(&cut).unwrap();
    assert!(text.ends_with('\n') && text.len() as u64 <= limit, "{text:?}");
    let kept = load_tum(&cut).unwrap();
    assert!(
        !kept.is_empty() && kept.len() < est.len(),
        "{} of {}",
        kept.len(),
        est.len()
    );
    assert!(
        stderr.contains(&format!("the trajectory stops at its {} poses", kept.len())),
        "{stderr}"
    );
}

/// A hint whose volume holds no valid node (20 m above the lab) is searched out to the nearest
/// nodes and says so; a run that gives no pose ends with one line saying why, and exit code 3
/// (docs/interfaces.md, "Exit codes"; it was 0, issue 49), its JSON summary saying the same.
/// The acceptance test asks more inliers than a frame has edges, so no candidate is committed
/// (a search's clear and only candidate would commit on its own frame).
#[cfg(feature = "desk")]
#[test]
fn a_hint_with_no_valid_node_is_widened_and_a_run_without_a_pose_says_why() {
    let lab = crate::common::lab_recording(6);
    // The table beside the model, as `run` caches it (the test above has a run build one).
    lab.table.save(&lab.rec.join("model.vis")).unwrap();
    let t0 = lab.truth[0].pose.translation.vector;
    let init = format!("{},{},{},0.5", t0.x, t0.y, t0.z + 20.0);
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("accept-none.toml");
    std::fs::write(&config, "[maintenance]\nmin_inliers = 100000\n").unwrap();
    let (code, stdout, stderr) = omnitrack(&[
        "run",
        "--config",
        config.to_str().unwrap(),
        "--model",
        lab.rec.join("model.obj").to_str().unwrap(),
        "--source",
        &format!("replay:{}", lab.rec.display()),
        "--init",
        &init,
        "--frames",
        "1",
        "--no-publish",
        "--json",
    ]);
    assert_eq!(code, 3, "{stderr}");
    assert!(
        stderr.contains("no valid visibility node in the search volume; searched the nearest"),
        "{stderr}"
    );
    let last = last_line(&stderr);
    let reason = last
        .strip_prefix("omnitrack: no pose: ")
        .unwrap_or_else(|| panic!("{stderr}"));
    assert!(reason.contains("no valid visibility node"), "{reason}");
    assert_eq!(stdout.lines().count(), 1, "one JSON line: {stdout:?}");
    let summary: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(summary["exit_code"], 3);
    assert_eq!(summary["no_pose_reason"], reason);
    assert_eq!(summary["poses"]["total"], 0);
    assert!(summary["poses"]["first_timestamp_ns"].is_null());
    assert_eq!(summary["end"], "max_frames");
}

/// A reader that goes away (`omnitrack … | head -c1`) ends the command quietly: no panic, no
/// error line, exit 0.
#[test]
fn a_closed_standard_output_ends_quietly() {
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("room.obj");
    std::fs::write(&model, "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\n").unwrap();
    for args in [
        vec!["manpage"],
        vec!["completions", "bash"],
        vec!["segments", "--model", model.to_str().unwrap()],
    ] {
        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_omnitrack"))
            .args(&args)
            .stdout(writer)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{args:?}: {:?} {stderr}", out.status);
        assert!(stderr.is_empty(), "{args:?}: {stderr}");
    }
}

/// A device or a FIFO given as an input file of any command is refused at once: `/dev/zero`
/// used to fill the memory and a FIFO to wait for a writer for ever (`pose --lines` and `edges`
/// too, until 2026-11-29).
#[test]
fn devices_and_fifos_are_refused_as_input_files() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("fifo.toml");
    assert!(std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap()
        .success());
    let fifo = fifo.to_str().unwrap();
    let rig = crate::common::SHIPPED_RIG;
    let args: [&[&str]; 8] = [
        &["check", "--rig", "/dev/zero"],
        &["check", "--model", "/dev/zero"],
        &["check", "--config", fifo],
        &["check", "--rig", fifo],
        &["pose", "--rig", rig, "--lines", fifo],
        &["pose", "--rig", rig, "--lines", "/dev/zero"],
        &["edges", "--rig", rig, "--sensor", "0", fifo],
        &["edges", "--rig", rig, "--sensor", "0", "/dev/zero"],
    ];
    for args in args {
        let (code, _, stderr) = omnitrack(args);
        assert_eq!(code, 2, "{args:?}: {stderr}");
        assert!(stderr.trim_end().ends_with("not a regular file"), "{args:?}: {stderr}");
    }
}

/// `check` refuses what `run` would refuse about a model: one without segments, and one whose
/// visibility grid is too large to build at the config's spacing.
#[test]
fn check_refuses_a_model_run_could_not_use() {
    let dir = tempfile::tempdir().unwrap();
    let empty = dir.path().join("empty.obj");
    std::fs::write(&empty, "v 0 0 0\n").unwrap();
    let wide = dir.path().join("wide.obj");
    std::fs::write(&wide, "v 0 0 0\nv 1e5 0 0\nv 1e5 1e5 0\nv 0 1e5 0\nf 1 2 3 4\n").unwrap();
    for (model, expected) in [(&empty, "no segments"), (&wide, "grid cells, more than")] {
        let (code, _, stderr) = omnitrack(&["check", "--model", model.to_str().unwrap()]);
        assert_eq!(code, 2, "{stderr}");
        assert!(stderr.contains(expected), "{stderr}");
    }
}

/// `check` says how live capture will open a rig of cropped sensors, and refuses two sensors on
/// one device without crops (live capture could not tell their images apart).
#[test]
fn check_shows_shared_devices_and_refuses_one_without_crops() {
    let root = env!("CARGO_MANIFEST_DIR");
    let rig = format!("{root}/tools/rigs/dual_fisheye_one_frame.toml");
    let (code, _, stderr) = omnitrack(&["check", "--rig", &rig]);
    assert_eq!(code, 0, "{stderr}");
    assert!(
        stderr.contains("sensors 0 and 1: windows of one device's frame (/dev/video0), at least 2048×1024"),
        "{stderr}"
    );
    let dir = tempfile::tempdir().unwrap();
    let no_crop = dir.path().join("no_crop.toml");
    let text = std::fs::read_to_string(&rig)
        .unwrap()
        .replace("crop = [1024, 0, 1024, 1024]\n", "");
    std::fs::write(&no_crop, text).unwrap();
    let (code, _, stderr) = omnitrack(&["check", "--rig", no_crop.to_str().unwrap()]);
    assert_eq!(code, 2, "{stderr}");
    assert!(
        last_line(&stderr).ends_with("sensors 0 and 1 share '/dev/video0', but sensor 1 has no crop: each sensor of a shared device needs crop = [x, y, width, height], its window of the device's frame"),
        "{stderr}"
    );
}

/// SIGKILL at a random moment of a run (the OOM killer, a pulled plug of the process): of the
/// poses it published, the trajectory lacks at most one, every line of it is whole, and the next
/// run on the same services starts and publishes normally.
#[cfg(feature = "desk")]
#[test]
fn a_killed_run_keeps_the_poses_it_published_and_the_next_run_publishes() {
    use omnitrack::publish::{PoseSubscriber, TrackerState};
    use std::process::{Command, Stdio};
    use std::time::{Duration, Instant};

    let lab = crate::common::lab_recording(40);
    lab.table.save(&lab.rec.join("model.vis")).unwrap();
    let prefix = format!("omnitrack-test/kill-{}", std::process::id());
    let model = lab.rec.join("model.obj");
    let model = model.to_str().unwrap();
    let t0 = lab.truth[0].pose.translation.vector;
    let init = format!("{},{},{},1.5", t0.x, t0.y, t0.z);
    let replay = format!("replay:{}", lab.rec.display());
    let killed = lab.dir.path().join("killed.tum");
    let killed_str: &'static str = Box::leak(killed.to_str().unwrap().to_string().into_boxed_str());
    let args = |tum: &'static str| -> Vec<&str> {
        vec![
            "run",
            "--model",
            model,
            "--source",
            &replay,
            "--init",
            &init,
            "--trajectory",
            tum,
            "--services",
            &prefix,
        ]
    };
    let subscriber = PoseSubscriber::create(&format!("{prefix}/pose")).unwrap();
    // "A random moment": after 3 to 25 tracked poses, chosen by the clock.
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .subsec_nanos();
    let kill_after = 3 + (nanos % 23) as usize;
    let mut child = Command::new(env!("CARGO_BIN_EXE_omnitrack"))
        .args(args(killed_str))
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut published = Vec::new();
    let start = Instant::now();
    while published.len() < kill_after {
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "{} poses in 2 minutes",
            published.len()
        );
        if let Some(s) = subscriber.wait(Duration::from_millis(100)).unwrap() {
            if s.status == TrackerState::Tracking as u8 {
                published.push(s.timestamp_ns);
            }
        }
    }
    child.kill().unwrap();
    child.wait().unwrap();
    // The poses published before the kill that the subscriber had not taken yet.
    while let Some(s) = subscriber.receive().unwrap() {
        if s.status == TrackerState::Tracking as u8 {
            published.push(s.timestamp_ns);
        }
    }
    let text = std::fs::read_to_string(&killed).unwrap();
    assert!(text.is_empty() || text.ends_with('\n'), "a partial last line: {text:?}");
    let written = omnitrack::trajectory::parse_tum(&text, "killed.tum").unwrap();
    assert!(
        written.windows(2).all(|w| w[0].timestamp_ns < w[1].timestamp_ns),
        "in time order"
    );
    let lost = published
        .iter()
        .filter(|t| !written.iter().any(|w| w.timestamp_ns == **t))
        .count();
    eprintln!(
        "killed after {kill_after} tracked poses: {} published, {} written, {lost} lost",
        published.len(),
        written.len()
    );
    assert!(
        lost <= 1,
        "{lost} of {} published poses missing from the trajectory",
        published.len()
    );

    // The next start cleans up after the killed one and publishes.
    let again = lab.dir.path().join("again.tum");
    let mut next = args(Box::leak(again.to_str().unwrap().to_string().into_boxed_str()));
    next.extend(["--frames", "3"]);
    let mut run = Command::new(env!("CARGO_BIN_EXE_omnitrack"))
        .args(&next)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The surviving subscriber (a navigation process outliving the tracker) receives from it.
    let mut after = 0;
    let status = loop {
        if let Some(s) = subscriber.wait(Duration::from_millis(20)).unwrap() {
            after += 1;
            assert!(s.sequence < 3, "{s:?}");
        }
        if let Some(status) = run.try_wait().unwrap() {
            break status;
        }
    };
    let mut stderr = String::new();
    std::io::Read::read_to_string(run.stderr.as_mut().unwrap(), &mut stderr).unwrap();
    assert!(status.success(), "{stderr}");
    assert!(after > 0, "the next run published nothing: {stderr}");
}
