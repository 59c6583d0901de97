//! Reports a script can trust (issue 49, item 5): `run`'s summary counts every pose (late ones
//! included) and exactly the frames it read; a search of seconds says how far it has got; and
//! `run`, `check` and `listen` give `--json` with the fields docs/interfaces.md ("JSON output")
//! documents, each checked here.

use crate::common::omnitrack;
use serde_json::Value;

/// The keys of a JSON object, in the order they are written in `line` (serde_json's map sorts
/// them): each key's first `"key":` in the text.
fn keys_in_order(line: &str, object: &Value) -> Vec<String> {
    let mut keys: Vec<(usize, String)> = object
        .as_object()
        .unwrap_or_else(|| panic!("not an object: {object}"))
        .keys()
        .map(|k| (line.find(&format!("\"{k}\":")).unwrap_or(usize::MAX), k.clone()))
        .collect();
    keys.sort();
    keys.into_iter().map(|(_, k)| k).collect()
}

/// The key names of `object`, sorted.
fn keys(object: &Value) -> Vec<&str> {
    let mut k: Vec<&str> = object
        .as_object()
        .unwrap_or_else(|| panic!("not an object: {object}"))
        .keys()
        .map(String::as_str)
        .collect();
    k.sort_unstable();
    k
}

fn sorted<'a>(names: &[&'a str]) -> Vec<&'a str> {
    let mut v = names.to_vec();
    v.sort_unstable();
    v
}

fn u(v: &Value) -> u64 {
    v.as_u64().unwrap_or_else(|| panic!("not a whole number: {v}"))
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

/// The lab recording of `frames` frames with its visibility table beside the model (so that
/// `run` does not build one), and an `--init` hint 0.8 m from the true start.
#[cfg(feature = "desk")]
struct Lab {
    lab: crate::common::LabRecording,
    init: String,
}

#[cfg(feature = "desk")]
impl Lab {
    fn new(frames: usize) -> Lab {
        let lab = crate::common::lab_recording(frames);
        lab.table.save(&lab.rec.join("model.vis")).unwrap();
        let t0 = lab.truth[0].pose.translation.vector;
        let init = format!("{},{},{},1.5", t0.x + 0.8, t0.y, t0.z);
        Lab { lab, init }
    }

    /// `omnitrack run --model M --source replay:REC` and `args`: (exit code, stdout, stderr).
    fn run(&self, args: &[&str]) -> (i32, String, String) {
        let model = self.lab.rec.join("model.obj");
        let source = format!("replay:{}", self.lab.rec.display());
        let mut all = vec!["run", "--model", model.to_str().unwrap(), "--source", &source];
        all.extend_from_slice(args);
        omnitrack(&all)
    }
}

/// A lossless replay stopped by `--frames 3` reads exactly 3 frames (it read 5, one of them
/// "dropped"), and the summary counts the poses worked out late, after the search (it said "0
/// tracked (0.0 %)" and "no pose: no search finished" over a trajectory of good poses): the
/// count is the trajectory's, and the run exits 0.
#[cfg(feature = "desk")]
#[test]
fn a_run_counts_its_late_poses_and_exactly_the_frames_it_read() {
    let lab = Lab::new(6);
    let tum = lab.lab.dir.path().join("est.tum");
    let (code, stdout, stderr) = lab.run(&[
        "--init",
        &lab.init,
        "--frames",
        "3",
        "--no-publish",
        "--trajectory",
        tum.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.is_empty(), "{stdout}");
    let written = omnitrack::trajectory::load_tum(&tum).unwrap().len();
    assert!(written >= 1, "{stderr}");
    assert!(
        stderr.contains("omnitrack: 3 frames processed of 3 captured (") && stderr.contains(" frames/s), 0 dropped; "),
        "{stderr}"
    );
    assert!(!stderr.contains("left unprocessed"), "{stderr}");
    let poses = stderr
        .lines()
        .find_map(|l| l.strip_prefix("omnitrack: 3 frames, "))
        .and_then(|rest| rest.split(" with a pose").next())
        .unwrap_or_else(|| panic!("no pose count: {stderr}"));
    assert_eq!(poses, written.to_string(), "{stderr}");
    assert!(!stderr.contains("no pose"), "{stderr}");
}

/// `run --json`: one line on standard output, one object with every documented field, in the
/// documented order, each consistent with the run (the trajectory, standard error, the frames
/// of the recording); `listen --json` and `listen --status --json` beside it print one object
/// per sample with every documented field.
#[cfg(feature = "desk")]
#[test]
fn run_and_listen_json_have_every_documented_field() {
    use std::process::{Command, Stdio};
    use std::time::{Duration, Instant};
    let lab = Lab::new(6);
    let tum = lab.lab.dir.path().join("est.tum");
    let prefix = format!("omnitrack-test/json-{}", std::process::id());
    let listen = |extra: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_omnitrack"))
            .args(["listen", "--json", "--services", &prefix])
            .args(extra)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    // Subscribed before the tracker publishes: every pose sample reaches them.
    let poses_listener = listen(&["--count", "6"]);
    let status_listener = listen(&["--status", "--count", "2"]);
    // And one whose reader has gone away (`listen --json | head -c0`): it ends quietly, 0.
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    let closed_listener = Command::new(env!("CARGO_BIN_EXE_omnitrack"))
        .args(["listen", "--json", "--services", &prefix])
        .stdout(writer)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_secs(1));
    let (code, stdout, stderr) = lab.run(&[
        "--init",
        &lab.init,
        "--trajectory",
        tum.to_str().unwrap(),
        "--services",
        &prefix,
        "--json",
    ]);
    assert_eq!(code, 0, "{stderr}");
    assert_eq!(stdout.lines().count(), 1, "one line: {stdout:?}");
    let line = stdout.trim_end();
    let s: Value = serde_json::from_str(line).unwrap();
    assert_eq!(
        keys_in_order(line, &s),
        [
            "end",
            "exit_code",
            "no_pose_reason",
            "frames",
            "poses",
            "samples_published",
            "trajectory",
            "tracker",
            "elapsed_s",
            "frame_rate_hz",
            "latency_ms",
            "stages",
            "sensors",
            "scheduling"
        ]
    );
    assert_eq!(s["end"], "end_of_stream");
    assert_eq!(s["exit_code"], 0);
    assert!(s["no_pose_reason"].is_null());

    let frames = &s["frames"];
    assert_eq!(keys(frames), sorted(&["captured", "processed", "dropped", "left"]));
    assert_eq!(
        [
            &frames["captured"],
            &frames["processed"],
            &frames["dropped"],
            &frames["left"]
        ]
        .map(u),
        [6, 6, 0, 0]
    );

    let written = omnitrack::trajectory::load_tum(&tum).unwrap();
    let p = &s["poses"];
    assert_eq!(
        keys(p),
        sorted(&[
            "total",
            "on_time",
            "late",
            "fraction",
            "first_timestamp_ns",
            "first_after_s"
        ])
    );
    assert_eq!(u(&p["total"]), written.len() as u64);
    assert_eq!(u(&p["on_time"]) + u(&p["late"]), u(&p["total"]));
    assert!((f(&p["fraction"]) - written.len() as f64 / 6.0).abs() < 1e-12);
    assert_eq!(u(&p["first_timestamp_ns"]), written[0].timestamp_ns);
    let first_frame_ns = lab.lab.truth[0].timestamp_ns.min(written[0].timestamp_ns);
    let after = f(&p["first_after_s"]);
    assert!(
        after >= 0.0 && (after - (written[0].timestamp_ns - first_frame_ns) as f64 * 1e-9).abs() < 0.01,
        "{after}"
    );
    assert!(
        stderr.contains(&format!(
            "omnitrack: 6 frames, {} with a pose ({:.1} %): {} on time, {} late",
            written.len(),
            100.0 * written.len() as f64 / 6.0,
            p["on_time"],
            p["late"]
        )),
        "{stderr}"
    );

    let published = &s["samples_published"];
    assert_eq!(keys(published), sorted(&["pose", "status", "errors"]));
    assert_eq!(u(&published["pose"]), 6, "a pose sample per frame");
    assert!(u(&published["status"]) >= 2);
    assert_eq!(u(&published["errors"]), 0);

    let t = &s["trajectory"];
    assert_eq!(keys(t), sorted(&["path", "poses_written", "out_of_order", "failed"]));
    assert_eq!(t["path"], tum.to_str().unwrap());
    assert_eq!(u(&t["poses_written"]), written.len() as u64);
    assert_eq!(u(&t["out_of_order"]), 0);
    assert_eq!(t["failed"], false);

    let tracker = &s["tracker"];
    assert_eq!(
        keys(tracker),
        sorted(&[
            "searches",
            "searches_cancelled",
            "losses",
            "reinitialisations",
            "relocalisations",
            "relocalisations_withdrawn",
            "reinitialisations_withdrawn",
            "commits_withdrawn",
            "first_search_s",
            "search_time_s"
        ])
    );
    assert!(u(&tracker["searches"]) >= 1);
    for k in [
        "searches_cancelled",
        "losses",
        "reinitialisations",
        "relocalisations_withdrawn",
        "reinitialisations_withdrawn",
    ] {
        assert_eq!(u(&tracker[k]), 0, "{k}");
    }
    let _ = u(&tracker["relocalisations"]);
    let first = f(&tracker["first_search_s"]);
    assert!(first > 0.0 && f(&tracker["search_time_s"]) >= first, "{tracker}");

    assert!(f(&s["elapsed_s"]) > 0.0);
    assert!(f(&s["frame_rate_hz"]) > 0.0);
    let latency = &s["latency_ms"];
    assert_eq!(keys(latency), sorted(&["p50", "p99", "max"]));
    assert!(0.0 < f(&latency["p50"]) && f(&latency["p50"]) <= f(&latency["p99"]));
    assert!(f(&latency["p99"]) <= f(&latency["max"]));

    let stages = &s["stages"];
    let names = ["capture", "edges", "match", "solve", "publish", "frame", "track"];
    let stages_text = &line[line.find("\"stages\":").unwrap()..];
    assert_eq!(keys_in_order(stages_text, stages), names);
    for name in names {
        let st = &stages[name];
        assert_eq!(
            keys(st),
            sorted(&[
                "count",
                "p50_ms",
                "p99_ms",
                "max_ms",
                "mean_ms",
                "budget_ms",
                "overruns"
            ]),
            "{name}"
        );
        let count = u(&st["count"]);
        assert!(count >= 6, "{name}: {st}");
        assert!(
            f(&st["p50_ms"]) <= f(&st["p99_ms"]) && f(&st["p99_ms"]) <= f(&st["max_ms"]),
            "{name}: {st}"
        );
        assert!(f(&st["mean_ms"]) >= 0.0);
        let budgeted = !matches!(name, "match" | "solve");
        assert_eq!(st["budget_ms"].is_number(), budgeted, "{name}: {st}");
        assert!(u(&st["overruns"]) <= count);
    }
    assert_eq!(f(&stages["frame"]["p50_ms"]), f(&latency["p50"]));

    let sensors = s["sensors"].as_array().unwrap();
    assert_eq!(sensors.len(), 6);
    for (k, sensor) in sensors.iter().enumerate() {
        assert_eq!(
            keys(sensor),
            sorted(&["id", "delivered", "overwritten", "faults", "sync_missed", "left"])
        );
        assert_eq!(u(&sensor["id"]), k as u64);
        assert_eq!(u(&sensor["delivered"]), 6);
        for key in ["overwritten", "faults", "sync_missed", "left"] {
            assert_eq!(u(&sensor[key]), 0, "sensor {k} {key}");
        }
    }
    let scheduling = &s["scheduling"];
    assert_eq!(keys(scheduling), sorted(&["mode", "priority", "reason"]));
    assert_eq!(scheduling["mode"], "lossless");
    assert!(scheduling["priority"].is_null() && scheduling["reason"].is_null());

    // The listeners: every documented field of every line.
    let finish = |child: std::process::Child, what: &str| -> String {
        let mut child = child;
        let deadline = Instant::now() + Duration::from_secs(20);
        while child.try_wait().unwrap().is_none() {
            if Instant::now() > deadline {
                let _ = child.kill();
                panic!("{what} did not end");
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let out = child.wait_with_output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            out.status.success() && stderr.is_empty(),
            "{what}: {:?} {stderr}",
            out.status
        );
        String::from_utf8(out.stdout).unwrap()
    };
    let pose_lines = finish(poses_listener, "listen --json");
    assert_eq!(pose_lines.lines().count(), 6, "{pose_lines}");
    let mut tracked = 0;
    for (i, l) in pose_lines.lines().enumerate() {
        let v: Value = serde_json::from_str(l).unwrap();
        assert_eq!(
            keys_in_order(l, &v),
            [
                "sequence",
                "timestamp_ns",
                "status",
                "position_m",
                "rotation_wxyz",
                "covariance",
                "inliers",
                "xi_rad2"
            ]
        );
        assert_eq!(u(&v["sequence"]), i as u64, "{l}");
        let ts = u(&v["timestamp_ns"]);
        assert!(
            lab.lab.truth.iter().any(|g| g.timestamp_ns.abs_diff(ts) < 5_000_000),
            "{l}"
        );
        let status = v["status"].as_str().unwrap();
        assert!(["initializing", "tracking", "lost"].contains(&status), "{l}");
        assert_eq!(v["position_m"].as_array().unwrap().len(), 3);
        assert_eq!(v["rotation_wxyz"].as_array().unwrap().len(), 4);
        let cov = v["covariance"].as_array().unwrap();
        assert_eq!(cov.len(), 36);
        let _ = u(&v["inliers"]);
        if status == "tracking" {
            tracked += 1;
            // The pose is a trajectory pose, the covariance finite.
            let w = written
                .iter()
                .find(|w| w.timestamp_ns == ts)
                .expect("a published pose is in the trajectory");
            let pos = w.pose.translation.vector;
            for k in 0..3 {
                assert!((f(&v["position_m"][k]) - pos[k]).abs() < 1e-6, "{l}");
            }
            assert!(cov.iter().all(Value::is_number), "{l}");
            assert!(f(&v["xi_rad2"]) >= 0.0);
        } else if status == "initializing" {
            // Nothing known yet: an infinite covariance, written null.
            assert!(cov[0].is_null(), "{l}");
        }
    }
    assert_eq!(tracked, u(&p["on_time"]), "tracking samples are the on-time poses");

    let closed = finish(closed_listener, "listen --json into a closed pipe");
    assert!(closed.is_empty());
    let status_lines = finish(status_listener, "listen --status --json");
    assert_eq!(status_lines.lines().count(), 2, "{status_lines}");
    for l in status_lines.lines() {
        let v: Value = serde_json::from_str(l).unwrap();
        assert_eq!(
            keys_in_order(l, &v),
            [
                "sequence",
                "timestamp_ns",
                "source",
                "pid",
                "state",
                "searching",
                "search",
                "search_widened_to_m",
                "sensors",
                "stage_p50_us",
                "stage_p99_us"
            ]
        );
        let _ = (u(&v["sequence"]), u(&v["timestamp_ns"]), u(&v["pid"]));
        assert_eq!(v["source"], "ladybug2", "{l}");
        assert!(
            ["initializing", "tracking", "lost"].contains(&v["state"].as_str().unwrap()),
            "{l}"
        );
        assert!(
            ["none", "initialising", "relocalising", "reinitialising"].contains(&v["searching"].as_str().unwrap()),
            "{l}"
        );
        assert!(
            ["none", "as_given", "widened", "no_cells"].contains(&v["search"].as_str().unwrap()),
            "{l}"
        );
        assert_eq!(f(&v["search_widened_to_m"]), 0.0);
        let sensors = v["sensors"].as_array().unwrap();
        assert_eq!(sensors.len(), 6);
        for sensor in sensors {
            assert_eq!(keys(sensor), sorted(&["frame_rate_hz", "frames_dropped"]));
            assert!(f(&sensor["frame_rate_hz"]) >= 0.0);
            assert_eq!(u(&sensor["frames_dropped"]), 0);
        }
        for key in ["stage_p50_us", "stage_p99_us"] {
            let text = &l[l.find(&format!("\"{key}\":")).unwrap()..];
            assert_eq!(keys_in_order(text, &v[key]), names, "{l}");
            for name in names {
                let _ = u(&v[key][name]);
            }
        }
    }
}

/// A search of more than a second (the whole model's, here cut to 3 s of the reference
/// machine's time, 6 s of one core's work: half that took 1.15 s of the debug build's time once
/// the grid's merit skipped sensors, too short) says how far it
/// has got, about once a second, on standard error: the share of its work growing, the time
/// since it started at least a second apart. A run that then ends without a pose exits 3.
#[cfg(feature = "desk")]
#[test]
fn a_long_search_prints_its_progress_about_once_a_second() {
    let lab = Lab::new(6);
    let config = lab.lab.dir.path().join("short_search.toml");
    std::fs::write(&config, "[initialisation]\nwhole_model_time_budget_ms = 3000\n").unwrap();
    let (code, stdout, stderr) = lab.run(&[
        "--frames",
        "1",
        "--no-publish",
        "--config",
        config.to_str().unwrap(),
        "--json",
    ]);
    let summary: Value = serde_json::from_str(stdout.trim_end()).unwrap_or_else(|e| panic!("{e}: {stdout}"));
    let poses = u(&summary["poses"]["total"]);
    assert_eq!(code, if poses == 0 { 3 } else { 0 }, "{stderr}");
    assert_eq!(u(&summary["exit_code"]), code as u64);
    let search_s = f(&summary["tracker"]["first_search_s"]);
    // (share %, seconds) of each progress line.
    let progress: Vec<(f64, f64)> = stderr
        .lines()
        .filter_map(|l| l.strip_prefix("omnitrack: initialisation search of the whole model: "))
        .map(|rest| {
            let (share, after) = rest
                .strip_suffix(" s")
                .and_then(|r| r.split_once(" % of its work after "))
                .unwrap_or_else(|| panic!("{rest:?}"));
            (share.parse().unwrap(), after.parse().unwrap())
        })
        .collect();
    eprintln!("{search_s:.1} s search: {progress:?}");
    assert!(search_s > 1.2, "{search_s} s: too short to test: {stderr}");
    assert!(
        !progress.is_empty(),
        "nothing said during a {search_s:.1} s search: {stderr}"
    );
    assert!(progress.len() as f64 <= search_s + 1.0, "{progress:?}");
    assert!(progress[0].1 >= 1.0, "{progress:?}");
    for w in progress.windows(2) {
        // A second apart, give or take the tenth the seconds are written to.
        assert!(w[1].1 - w[0].1 >= 0.9, "{progress:?}");
        assert!(w[1].0 >= w[0].0, "{progress:?}");
    }
    assert!(
        progress.iter().all(|&(share, _)| (0.0..=100.0).contains(&share)),
        "{progress:?}"
    );
    // Written while the search ran: before its outcome's line.
    let outcome = stderr
        .find("in the whole model, looked at")
        .unwrap_or_else(|| panic!("{stderr}"));
    let last = stderr.rfind("search of the whole model: ").unwrap();
    assert!(last < outcome, "{stderr}");
}

/// `check --json`: one object per file given (rig, model, config), every documented field; a
/// file that is not valid is one object with its error, the others are still checked, and the
/// exit code is 2. Without `--json`, the same findings on standard error.
#[test]
fn check_json_reports_every_file_with_every_field() {
    let root = env!("CARGO_MANIFEST_DIR");
    let rig = format!("{root}/tools/rigs/dual_fisheye_one_frame.toml");
    let config = format!("{root}/firmware_config/tracker.toml");
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("room.obj");
    // A box room, a face with a repeated vertex (degenerate), an ignored record, a free segment.
    std::fs::write(
        &model,
        "vn 0 0 1\nv 0 0 0\nv 4 0 0\nv 4 3 0\nv 0 3 0\nv 0 0 2.5\nv 4 0 2.5\nv 4 3 2.5\nv 0 3 2.5\n\
         f 1 2 3 4\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\nf 1 1 2\nl 1 7\n",
    )
    .unwrap();
    let model = model.to_str().unwrap();
    let (code, stdout, stderr) = omnitrack(&["check", "--rig", &rig, "--model", model, "--config", &config, "--json"]);
    assert_eq!(code, 0, "{stderr}");
    assert!(stderr.is_empty(), "{stderr}");
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(lines.len(), 3, "{stdout}");
    let found: Vec<Value> = lines.iter().map(|l| serde_json::from_str(l).unwrap()).collect();
    let common = ["file", "kind", "ok", "error", "warnings"];

    let r = &found[0];
    assert_eq!(keys_in_order(lines[0], r), [&common[..], &["rig"]].concat());
    assert_eq!(
        (r["file"].as_str(), r["kind"].as_str(), &r["ok"]),
        (Some(rig.as_str()), Some("rig"), &Value::Bool(true))
    );
    assert!(r["error"].is_null() && r["warnings"].as_array().unwrap().is_empty());
    let rig_json = &r["rig"];
    assert_eq!(keys(rig_json), sorted(&["name", "sensors", "shared_devices"]));
    let loaded = omnitrack::Rig::load(std::path::Path::new(&rig)).unwrap();
    assert_eq!(rig_json["name"], loaded.name.as_str());
    let sensors = rig_json["sensors"].as_array().unwrap();
    assert_eq!(sensors.len(), loaded.sensors.len());
    for (s, json) in loaded.sensors.iter().zip(sensors) {
        assert_eq!(
            keys(json),
            sorted(&[
                "id",
                "width",
                "height",
                "lens",
                "max_off_axis_deg",
                "centre_m",
                "control"
            ])
        );
        assert_eq!(
            json["control"],
            serde_json::json!([]),
            "no [control]: the camera left as it is"
        );
        assert_eq!(u(&json["id"]), s.id as u64);
        assert_eq!(
            (u(&json["width"]), u(&json["height"])),
            (u64::from(s.width), u64::from(s.height))
        );
        assert_eq!(json["lens"], s.lens.model_name());
        assert!((f(&json["max_off_axis_deg"]) - s.max_off_axis().to_degrees()).abs() < 1e-9);
        let c = s.centre();
        for (k, v) in [c.x, c.y, c.z].iter().enumerate() {
            assert!((f(&json["centre_m"][k]) - v).abs() < 1e-12);
        }
    }
    let shared = rig_json["shared_devices"].as_array().unwrap();
    assert_eq!(shared.len(), 1, "{rig_json}");
    assert_eq!(
        keys(&shared[0]),
        sorted(&["sensors", "device", "min_width", "min_height"])
    );
    assert_eq!(shared[0]["sensors"], serde_json::json!([0, 1]));
    assert_eq!(shared[0]["device"], "/dev/video0");
    assert_eq!((u(&shared[0]["min_width"]), u(&shared[0]["min_height"])), (2048, 1024));

    let m = &found[1];
    assert_eq!(keys_in_order(lines[1], m), [&common[..], &["model"]].concat());
    assert_eq!((m["kind"].as_str(), &m["ok"]), (Some("model"), &Value::Bool(true)));
    assert_eq!(m["file"], model);
    assert!(m["error"].is_null() && m["warnings"].is_array());
    let loaded = omnitrack::Model::load(std::path::Path::new(model)).unwrap();
    let mj = &m["model"];
    assert_eq!(
        keys(mj),
        sorted(&[
            "vertices",
            "faces",
            "segments",
            "free_segments",
            "degenerate_faces",
            "nonplanar_faces",
            "welded_vertices",
            "ignored_records",
            "degenerate_lines"
        ])
    );
    assert_eq!(u(&mj["vertices"]), loaded.vertices.len() as u64);
    assert_eq!(u(&mj["faces"]), loaded.faces.len() as u64);
    assert_eq!(u(&mj["segments"]), loaded.segments.len() as u64);
    assert_eq!(u(&mj["free_segments"]), 1);
    assert_eq!(u(&mj["degenerate_faces"]), 1);
    assert_eq!(u(&mj["ignored_records"]), 1);
    assert_eq!(u(&mj["nonplanar_faces"]), 0);
    assert_eq!(u(&mj["welded_vertices"]), 0);
    assert_eq!(u(&mj["degenerate_lines"]), 0);

    let c = &found[2];
    assert_eq!(keys_in_order(lines[2], c), common);
    assert_eq!(
        (c["file"].as_str(), c["kind"].as_str(), &c["ok"]),
        (Some(config.as_str()), Some("config"), &Value::Bool(true))
    );
    assert!(c["error"].is_null() && c["warnings"].as_array().unwrap().is_empty());

    // A config out of range: its finding says why, the rig and model are still checked (the
    // model against the shipped values), exit 2; without --json the same on standard error.
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, "[initialisation]\nwhole_model_time_budget_ms = -1\n").unwrap();
    let bad = bad.to_str().unwrap();
    let (code, stdout, stderr) = omnitrack(&["check", "--rig", &rig, "--model", model, "--config", bad, "--json"]);
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.is_empty(), "{stderr}");
    let found: Vec<Value> = stdout.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(found.len(), 3, "{stdout}");
    assert_eq!(
        [&found[0]["ok"], &found[1]["ok"]],
        [&Value::Bool(true), &Value::Bool(true)]
    );
    assert_eq!(
        (&found[2]["kind"], &found[2]["ok"]),
        (&Value::from("config"), &Value::Bool(false))
    );
    let error = found[2]["error"].as_str().unwrap();
    assert!(error.contains("whole_model_time_budget_ms"), "{error}");
    assert_eq!(keys(&found[2]), sorted(&common));
    let (code, stdout, stderr) = omnitrack(&["check", "--rig", &rig, "--model", model, "--config", bad]);
    assert_eq!(code, 2, "{stderr}");
    assert!(stdout.is_empty(), "{stdout}");
    assert!(stderr.contains("rig 'dual_fisheye"), "{stderr}");
    assert!(stderr.contains(" segments (1 free)"), "{stderr}");
    assert_eq!(stderr.trim_end().lines().last().unwrap(), format!("omnitrack: {error}"));
    // A broken rig before a valid model: the model's summary first, the rig's error last.
    let broken = dir.path().join("broken.toml");
    std::fs::write(&broken, "name = \"broken\"\n").unwrap();
    let broken = broken.to_str().unwrap();
    let (code, _, stderr) = omnitrack(&["check", "--rig", broken, "--model", model]);
    assert_eq!(code, 2, "{stderr}");
    let lines: Vec<&str> = stderr.trim_end().lines().collect();
    assert!(lines[0].contains(" segments (1 free)"), "{stderr}");
    assert!(
        lines.len() == 2 && lines[1].starts_with("omnitrack: ") && lines[1].contains("broken.toml"),
        "{stderr}"
    );
    let (code, stdout, _) = omnitrack(&["check", "--rig", broken, "--model", model, "--json"]);
    assert_eq!(code, 2);
    let found: Vec<Value> = stdout.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(found[0]["kind"], "rig");
    assert_eq!(found[0]["ok"], false);
    assert_eq!(format!("omnitrack: {}", found[0]["error"].as_str().unwrap()), lines[1]);
    assert_eq!(
        (&found[1]["kind"], &found[1]["ok"]),
        (&Value::from("model"), &Value::Bool(true))
    );
}

/// The exit codes are where a user looks for them: `omnitrack --help`, `run --help`,
/// `check --help` and the man page's EXIT STATUS, the same four as docs/interfaces.md.
#[test]
fn the_exit_codes_are_in_the_help_and_the_man_page() {
    let doc = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/docs/interfaces.md")).unwrap();
    let table: Vec<&str> = doc
        .lines()
        .skip_while(|l| *l != "### Exit codes")
        .skip_while(|l| !l.starts_with("| --- |"))
        .skip(1)
        .take_while(|l| l.starts_with('|'))
        .filter_map(|l| l.split('|').nth(1).map(str::trim))
        .collect();
    assert_eq!(table, ["0", "1", "2", "3"], "docs/interfaces.md, Exit codes");
    for args in [&["--help"][..], &["run", "--help"], &["check", "--help"]] {
        let (code, stdout, _) = omnitrack(args);
        assert_eq!(code, 0);
        let section = stdout
            .split("Exit status:")
            .nth(1)
            .unwrap_or_else(|| panic!("{args:?}: {stdout}"));
        for c in &table {
            assert!(section.contains(&format!("\n  {c}  ")), "{args:?}: code {c}: {section}");
        }
        assert!(section.contains("3  run: ended without any pose"), "{section}");
    }
    let (code, page, _) = omnitrack(&["manpage"]);
    assert_eq!(code, 0);
    let section = page
        .split(".SH \"EXIT STATUS\"")
        .nth(1)
        .expect("an EXIT STATUS section");
    for c in &table {
        assert!(section.contains(&format!(".TP\n{c}\n")), "code {c}: {section}");
    }
    assert!(section.contains("run: ended without any pose"), "{section}");
}
