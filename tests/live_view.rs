//! The live view (`omnitrack-view`, issue 49 item 4) on a real run: `omnitrack run` replays
//! the lab recording while the view subscribes to its services, serves a Foxglove WebSocket
//! client of this test and writes an MCAP file. Checked: the client decodes every pose sample
//! and the tracked poses; the MCAP file, read back by the `mcap` crate and by the official `mcap`
//! package from PyPI (an independent reader, in a venv in the per-user cache), has every
//! channel with its Foxglove schema and exactly the messages the run published; the images are
//! JPEGs of the sensors' size with the model and the edges drawn on them.
#![cfg(feature = "desk")]

mod common;

use base64::Engine;
use omnitrack_view::images::ImageOptions;
use omnitrack_view::{Options, Summary};
use serde_json::Value;
use std::collections::BTreeMap;
use std::net::{SocketAddr, TcpStream};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::time::{Duration, Instant};
use tungstenite::client::IntoClientRequest;
use tungstenite::Message;

/// 6 s at the recording's 5 Hz: the first search ends well within it, even on a loaded machine.
const FRAMES: usize = 30;
/// The official MCAP reader, pinned (pure Python with its compression wheels).
const MCAP_PY: &str = "1.6.0";
const READER: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tools/view/mcap_summary.py");

/// A Foxglove WebSocket client: the channels advertised (topic → id) and the messages received
/// per topic, decoded from JSON.
struct Client {
    ws: tungstenite::WebSocket<TcpStream>,
    channels: BTreeMap<String, (u64, String)>,
    by_subscription: BTreeMap<u32, String>,
    received: BTreeMap<String, Vec<(u64, Value)>>,
}

impl Client {
    fn connect(addr: SocketAddr) -> Client {
        let mut request = format!("ws://{addr}").into_client_request().unwrap();
        request
            .headers_mut()
            .insert("Sec-WebSocket-Protocol", "foxglove.websocket.v1".parse().unwrap());
        let stream = TcpStream::connect(addr).unwrap();
        stream.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
        let (ws, response) = tungstenite::client(request, stream).unwrap();
        assert_eq!(
            response.headers().get("Sec-WebSocket-Protocol").unwrap(),
            "foxglove.websocket.v1",
            "a browser refuses an answer without the subprotocol"
        );
        let mut c = Client {
            ws,
            channels: BTreeMap::new(),
            by_subscription: BTreeMap::new(),
            received: BTreeMap::new(),
        };
        let info = c.text();
        assert_eq!(info["op"], "serverInfo", "{info}");
        let advertise = c.text();
        assert_eq!(advertise["op"], "advertise", "{advertise}");
        for ch in advertise["channels"].as_array().unwrap() {
            assert_eq!(ch["encoding"], "json");
            assert_eq!(ch["schemaEncoding"], "jsonschema");
            let schema: Value = serde_json::from_str(ch["schema"].as_str().unwrap()).unwrap();
            assert_eq!(schema["title"], ch["schemaName"]);
            c.channels.insert(
                ch["topic"].as_str().unwrap().to_string(),
                (
                    ch["id"].as_u64().unwrap(),
                    ch["schemaName"].as_str().unwrap().to_string(),
                ),
            );
        }
        c
    }

    fn text(&mut self) -> Value {
        match self.ws.read().unwrap() {
            Message::Text(t) => serde_json::from_str(t.as_str()).unwrap(),
            m => panic!("expected a text message, got {m:?}"),
        }
    }

    fn subscribe(&mut self, topics: &[&str]) {
        let subs: Vec<Value> = topics
            .iter()
            .enumerate()
            .map(|(i, t)| {
                let id = 100 + i as u32;
                self.by_subscription.insert(id, t.to_string());
                serde_json::json!({"id": id, "channelId": self.channels[*t].0})
            })
            .collect();
        let request = serde_json::json!({"op": "subscribe", "subscriptions": subs});
        self.ws.send(Message::text(request.to_string())).unwrap();
    }

    /// Reads message frames until `done` says so or `timeout` passes.
    fn read_until(&mut self, timeout: Duration, done: impl Fn(&Client) -> bool) {
        let deadline = Instant::now() + timeout;
        while !done(self) && Instant::now() < deadline {
            match self.ws.read() {
                Ok(Message::Binary(b)) => {
                    assert_eq!(b[0], 1, "a message frame");
                    let sub = u32::from_le_bytes(b[1..5].try_into().unwrap());
                    let t = u64::from_le_bytes(b[5..13].try_into().unwrap());
                    let topic = self.by_subscription[&sub].clone();
                    let v: Value = serde_json::from_slice(&b[13..]).unwrap();
                    self.received.entry(topic).or_default().push((t, v));
                }
                Ok(Message::Text(t)) => panic!("the server warned: {t}"),
                Ok(_) => {}
                Err(tungstenite::Error::Io(e))
                    if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => {}
                Err(e) => panic!("{e}"),
            }
        }
    }

    fn count(&self, topic: &str) -> usize {
        self.received.get(topic).map_or(0, Vec::len)
    }
}

fn cache_dir() -> PathBuf {
    let var = |k: &str| std::env::var_os(k).map(PathBuf::from).filter(|p| p.is_absolute());
    var("OMNITRACK_CACHE")
        .or_else(|| var("XDG_CACHE_HOME").map(|p| p.join("omnitrack")))
        .or_else(|| var("HOME").map(|p| p.join(".cache/omnitrack")))
        .expect("a per-user cache: OMNITRACK_CACHE, XDG_CACHE_HOME or HOME")
}

/// Python with the official `mcap` package, in a venv made on first use.
fn mcap_python() -> PathBuf {
    let venv = cache_dir().join(format!("mcap-venv-{MCAP_PY}"));
    let python = venv.join("bin/python");
    let importable = |p: &Path| {
        Command::new(p)
            .args(["-c", "import mcap.reader"])
            .output()
            .is_ok_and(|o| o.status.success())
    };
    if !importable(&python) {
        eprintln!("installing mcap=={MCAP_PY} into {} (once)", venv.display());
        let ok = |c: &mut Command| assert!(c.status().unwrap().success(), "{c:?}");
        ok(Command::new("python3").arg("-m").arg("venv").arg(&venv));
        ok(Command::new(&python).args([
            "-m",
            "pip",
            "install",
            "--quiet",
            "--disable-pip-version-check",
            &format!("mcap=={MCAP_PY}"),
        ]));
        assert!(importable(&python), "mcap installed but not importable");
    }
    python
}

#[test]
fn a_replayed_run_is_seen_live_and_written_to_an_mcap_file_that_two_readers_read_alike() {
    let lab = common::lab_recording(FRAMES);
    let rig = omnitrack::Rig::load(&lab.rec.join("rig.toml")).unwrap();
    lab.table.save(&lab.rec.join("model.vis")).unwrap();
    let t0 = lab.truth[0].pose.translation.vector;
    let init = format!("{},{},{},1.5", t0.x + 0.5, t0.y, t0.z);
    let prefix = format!("omnitrack-test/view-{}", std::process::id());
    let mcap_path = lab.dir.path().join("run.mcap");
    let tum = lab.dir.path().join("est.tum");
    let model_path = lab.rec.join("model.obj");

    // The view, as `omnitrack-view serve --port 0 --mcap … --model … --recording …` runs it.
    let options = Options {
        pose_service: format!("{prefix}/pose"),
        status_service: format!("{prefix}/status"),
        listen: Some("127.0.0.1:0".parse().unwrap()),
        mcap: Some(mcap_path.clone()),
        model: Some(model_path.clone()),
        images: Some(ImageOptions {
            recording: lab.rec.clone(),
            every: Duration::ZERO,
            edges: true,
            quality: 80,
        }),
        count: None,
    };
    let stop = Arc::new(AtomicBool::new(false));
    let (addr_tx, addr_rx) = mpsc::channel();
    let view = {
        let stop = Arc::clone(&stop);
        std::thread::spawn(move || {
            omnitrack_view::run(&options, &stop, &mut |addr| addr_tx.send(addr.unwrap()).unwrap()).unwrap()
        })
    };
    let addr = addr_rx.recv_timeout(Duration::from_secs(60)).unwrap();
    let mut client = Client::connect(addr);
    let topics = [
        "/omnitrack/sample",
        "/omnitrack/pose",
        "/omnitrack/model",
        "/omnitrack/sensor0/image",
        "/omnitrack/sensor0/annotations",
    ];
    for t in topics.iter().chain(&["/tf", "/omnitrack/status", "/omnitrack/log"]) {
        assert!(client.channels.contains_key(*t), "{t} not advertised");
    }
    assert_eq!(client.channels["/omnitrack/pose"].1, "foxglove.PoseInFrame");
    client.subscribe(&topics);
    // The model comes at once, before any pose: a viewer that connects sees the building.
    client.read_until(Duration::from_secs(10), |c| c.count("/omnitrack/model") == 1);
    let model = &client.received["/omnitrack/model"][0].1;
    let points = model["entities"][0]["lines"][0]["points"].as_array().unwrap().len();
    assert_eq!(points, 2 * lab.model.segments.len());

    // The tracker, paced at the recording's rate (5 Hz) as a camera would deliver it.
    let out = Command::new(env!("CARGO_BIN_EXE_omnitrack"))
        .args(["run", "--model", model_path.to_str().unwrap()])
        .args(["--source", &format!("replay:{}", lab.rec.display())])
        .args(["--init", &init, "--trajectory", tum.to_str().unwrap()])
        .args(["--services", &prefix, "--realtime", "--json"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let run: Value = serde_json::from_slice(&out.stdout).unwrap();
    let published = run["samples_published"]["pose"].as_u64().unwrap() as usize;
    assert_eq!(published, FRAMES, "{run}");

    // Every sample, and the pose that follows each tracked one.
    let tracked_so_far = |c: &Client| {
        c.received
            .get("/omnitrack/sample")
            .map_or(0, |s| s.iter().filter(|(_, v)| v["status"] == "tracking").count())
    };
    client.read_until(Duration::from_secs(20), |c| {
        c.count("/omnitrack/sample") >= published && c.count("/omnitrack/pose") == tracked_so_far(c)
    });
    stop.store(true, Ordering::Relaxed);
    let summary: Summary = view.join().unwrap();
    assert_eq!(summary.poses as usize, published, "{summary:?}");
    assert_eq!(summary.poses_missed, 0);
    assert!(summary.mcap_error.is_none(), "{summary:?}");
    assert!(summary.tracking >= 5, "the run tracked: {summary:?}");
    assert!(summary.images_error.is_none(), "{summary:?}");

    // The live client: every sample, the tracked poses among them, in order.
    let samples = &client.received["/omnitrack/sample"];
    assert_eq!(samples.len(), published);
    let sequences: Vec<u64> = samples.iter().map(|(_, v)| v["sequence"].as_u64().unwrap()).collect();
    assert!(sequences.windows(2).all(|w| w[1] == w[0] + 1), "{sequences:?}");
    let tracked: Vec<&(u64, Value)> = samples.iter().filter(|(_, v)| v["status"] == "tracking").collect();
    assert_eq!(tracked.len() as u64, summary.tracking);
    let poses = &client.received["/omnitrack/pose"];
    assert_eq!(poses.len(), tracked.len());
    // Each tracked pose is the trajectory's pose of its frame (the TUM file, 1e-6 m as written).
    let est = omnitrack::trajectory::load_tum(&tum).unwrap();
    for ((t, pose), (ts, sample)) in poses.iter().zip(&tracked) {
        assert_eq!(t, ts);
        assert_eq!(pose["pose"]["position"]["x"], sample["position_m"][0]);
        let in_tum = est
            .iter()
            .find(|p| p.timestamp_ns.abs_diff(*t) < 1_000)
            .expect("a TUM line of that time");
        let x = pose["pose"]["position"]["x"].as_f64().unwrap();
        assert!((x - in_tum.pose.translation.vector.x).abs() < 1e-5, "{x} vs {in_tum:?}");
    }
    // Images: a JPEG of the sensor's size, with the model re-projected and the edges drawn.
    // At 5 Hz the images' thread is idle for every sample but those of the search's catch-up.
    let images = &client.received["/omnitrack/sensor0/image"];
    assert!(images.len() as u64 <= summary.image_sets);
    assert!(summary.image_sets >= summary.tracking, "{summary:?}");
    let jpeg = base64::engine::general_purpose::STANDARD
        .decode(images[0].1["data"].as_str().unwrap())
        .unwrap();
    let decoded = image::load_from_memory_with_format(&jpeg, image::ImageFormat::Jpeg).unwrap();
    let sensor = &rig.sensors[0];
    assert_eq!((decoded.width(), decoded.height()), (sensor.width, sensor.height));
    let annotated = client.received["/omnitrack/sensor0/annotations"]
        .iter()
        .filter(|(t, _)| tracked.iter().any(|(ts, _)| ts == t))
        .map(|(_, a)| a["points"].as_array().unwrap().clone())
        .next_back()
        .expect("annotations of a tracked frame");
    assert_eq!(annotated.len(), 2, "the model and the edges");
    for layer in &annotated {
        assert_eq!(layer["type"], 4, "a line list");
        let n = layer["points"].as_array().unwrap().len();
        assert!(n > 0 && n % 2 == 0, "{n} points");
    }

    // The MCAP file, read by the mcap crate: every channel once, with its schema, and exactly
    // what went out live.
    let bytes = std::fs::read(&mcap_path).unwrap();
    let file_summary = mcap::Summary::read(&bytes).unwrap().expect("a summary section");
    let sensors = rig.sensors.len();
    assert_eq!(file_summary.channels.len(), 8 + 2 * sensors);
    let mut counts: BTreeMap<String, (String, usize)> = BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let schema = m.channel.schema.as_ref().unwrap();
        assert_eq!(schema.encoding, "jsonschema");
        assert_eq!(m.channel.message_encoding, "json");
        let _: Value = serde_json::from_slice(&m.data).unwrap();
        counts
            .entry(m.channel.topic.clone())
            .or_insert((schema.name.clone(), 0))
            .1 += 1;
    }
    let count = |t: &str| counts.get(t).map_or(0, |c| c.1);
    assert_eq!(count("/omnitrack/sample"), published);
    assert_eq!(count("/omnitrack/pose"), tracked.len());
    assert_eq!(count("/tf"), tracked.len());
    assert_eq!(count("/omnitrack/uncertainty"), tracked.len());
    assert_eq!(count("/omnitrack/model"), 1);
    assert_eq!(count("/omnitrack/status") as u64, summary.statuses);
    assert!(summary.statuses >= 1 && count("/omnitrack/log") >= 1, "{counts:?}");
    assert!(count("/omnitrack/trajectory") >= 1, "{counts:?}");
    for k in 0..sensors {
        assert_eq!(count(&format!("/omnitrack/sensor{k}/image")) as u64, summary.image_sets);
        assert_eq!(
            count(&format!("/omnitrack/sensor{k}/annotations")) as u64,
            summary.image_sets
        );
    }
    let total: usize = counts.values().map(|c| c.1).sum();
    assert_eq!(total as u64, summary.mcap_messages);
    assert_eq!(file_summary.stats.unwrap().message_count as usize, total);
    assert_eq!(counts["/omnitrack/pose"].0, "foxglove.PoseInFrame");
    assert_eq!(counts["/tf"].0, "foxglove.FrameTransform");
    assert_eq!(counts["/omnitrack/model"].0, "foxglove.SceneUpdate");
    assert_eq!(counts["/omnitrack/log"].0, "foxglove.Log");
    assert_eq!(counts["/omnitrack/sensor0/image"].0, "foxglove.CompressedImage");
    assert_eq!(counts["/omnitrack/sensor0/annotations"].0, "foxglove.ImageAnnotations");

    // ... and by the official Python reader, which must count the same.
    let out = Command::new(mcap_python())
        .arg(READER)
        .arg(&mcap_path)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let py: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(py["summary_message_count"].as_u64().unwrap() as usize, total);
    assert_eq!(py["summary_channels"].as_u64().unwrap() as usize, 8 + 2 * sensors);
    for (topic, (schema, n)) in &counts {
        let t = &py["topics"][topic];
        assert_eq!(t["count"].as_u64().unwrap() as usize, *n, "{topic}");
        assert_eq!(t["schema"], schema.as_str(), "{topic}");
        assert_eq!(
            (t["schema_encoding"].as_str(), t["message_encoding"].as_str()),
            (Some("jsonschema"), Some("json"))
        );
    }
    let first = py["first_pose"].as_array().unwrap();
    assert_eq!(first[3].as_u64().unwrap(), tracked[0].0);
    assert_eq!(first[0], tracked[0].1["position_m"][0]);
}
