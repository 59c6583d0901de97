//! The channels of the view and their schemas: Foxglove's well-known message types where one
//! fits (the viewer draws them without configuration), omnitrack's own samples where none does,
//! all JSON-encoded with JSON Schema definitions.
//!
//! In: nothing. Out: [`Channel`]s (topic, schema name, schema text), shared by the MCAP file and
//! the WebSocket server so that both carry the same channels under the same names.
//!
//! JSON rather than protobuf or CDR: MCAP's and the Foxglove protocol's `json` encoding needs no
//! code generator and no schema compiler, Foxglove's panels read the `foxglove.*` types in JSON as
//! in protobuf (the schema name is what they match on), and any reader decodes a message with a
//! JSON parser. Byte fields (image data) are base64 strings, marked `contentEncoding: base64` as
//! Foxglove's own JSON schemas mark them.

use serde_json::{json, Value};

/// The model's frame: the parent of every pose.
pub const WORLD_FRAME: &str = "world";
/// The rig's frame (REP-103 body frame, docs/interfaces.md).
pub const RIG_FRAME: &str = "rig";

/// One channel of the view.
#[derive(Debug, Clone, PartialEq)]
pub struct Channel {
    pub topic: String,
    pub schema_name: &'static str,
    /// JSON Schema of the messages, as text.
    pub schema: String,
}

/// Topics of the fixed channels.
pub mod topic {
    /// `foxglove.PoseInFrame`: the rig's pose in the world, while tracking.
    pub const POSE: &str = "/omnitrack/pose";
    /// `foxglove.FrameTransform`: world → rig, while tracking (the 3D panel's frame tree).
    pub const TF: &str = "/tf";
    /// `omnitrack.PoseSample`: every pose sample as published, covariance and status included.
    pub const SAMPLE: &str = "/omnitrack/sample";
    /// `foxglove.SceneUpdate`: the position's 3σ ellipsoid.
    pub const UNCERTAINTY: &str = "/omnitrack/uncertainty";
    /// `foxglove.SceneUpdate`: the trajectory so far, one line-strip piece a second.
    pub const TRAJECTORY: &str = "/omnitrack/trajectory";
    /// `foxglove.SceneUpdate`: the model's segments, once.
    pub const MODEL: &str = "/omnitrack/model";
    /// `omnitrack.StatusSample`: every status sample.
    pub const STATUS: &str = "/omnitrack/status";
    /// `foxglove.Log`: the tracker's state changes, as lines.
    pub const LOG: &str = "/omnitrack/log";
}

/// The image channels of sensor `k`: `foxglove.CompressedImage` and `foxglove.ImageAnnotations`.
pub fn image_topics(k: usize) -> (String, String) {
    (
        format!("/omnitrack/sensor{k}/image"),
        format!("/omnitrack/sensor{k}/annotations"),
    )
}

/// Every channel: the fixed ones, and the image channels of `sensors` sensors.
pub fn channels(sensors: usize) -> Vec<Channel> {
    let mut c = vec![
        channel(topic::POSE, "foxglove.PoseInFrame", pose_in_frame()),
        channel(topic::TF, "foxglove.FrameTransform", frame_transform()),
        channel(topic::SAMPLE, "omnitrack.PoseSample", pose_sample()),
        channel(topic::UNCERTAINTY, "foxglove.SceneUpdate", scene_update()),
        channel(topic::TRAJECTORY, "foxglove.SceneUpdate", scene_update()),
        channel(topic::MODEL, "foxglove.SceneUpdate", scene_update()),
        channel(topic::STATUS, "omnitrack.StatusSample", status_sample()),
        channel(topic::LOG, "foxglove.Log", log()),
    ];
    for k in 0..sensors {
        let (image, annotations) = image_topics(k);
        c.push(channel(&image, "foxglove.CompressedImage", compressed_image()));
        c.push(channel(&annotations, "foxglove.ImageAnnotations", image_annotations()));
    }
    c
}

fn channel(topic: &str, schema_name: &'static str, schema: Value) -> Channel {
    Channel {
        topic: topic.to_string(),
        schema_name,
        schema: schema.to_string(),
    }
}

fn object(title: &str, properties: Value) -> Value {
    json!({"title": title, "type": "object", "properties": properties})
}

fn number() -> Value {
    json!({"type": "number"})
}

fn integer() -> Value {
    json!({"type": "integer"})
}

fn string() -> Value {
    json!({"type": "string"})
}

fn array_of(items: Value) -> Value {
    json!({"type": "array", "items": items})
}

fn time() -> Value {
    object("time", json!({"sec": integer(), "nsec": integer()}))
}

fn vector3() -> Value {
    object("foxglove.Vector3", json!({"x": number(), "y": number(), "z": number()}))
}

fn point3() -> Value {
    object("foxglove.Point3", json!({"x": number(), "y": number(), "z": number()}))
}

fn point2() -> Value {
    object("foxglove.Point2", json!({"x": number(), "y": number()}))
}

fn quaternion() -> Value {
    object(
        "foxglove.Quaternion",
        json!({"x": number(), "y": number(), "z": number(), "w": number()}),
    )
}

fn color() -> Value {
    object(
        "foxglove.Color",
        json!({"r": number(), "g": number(), "b": number(), "a": number()}),
    )
}

fn pose() -> Value {
    object(
        "foxglove.Pose",
        json!({"position": vector3(), "orientation": quaternion()}),
    )
}

fn pose_in_frame() -> Value {
    object(
        "foxglove.PoseInFrame",
        json!({"timestamp": time(), "frame_id": string(), "pose": pose()}),
    )
}

fn frame_transform() -> Value {
    object(
        "foxglove.FrameTransform",
        json!({
            "timestamp": time(), "parent_frame_id": string(), "child_frame_id": string(),
            "translation": vector3(), "rotation": quaternion()
        }),
    )
}

fn line_primitive() -> Value {
    object(
        "foxglove.LinePrimitive",
        json!({
            // 0 LINE_STRIP, 1 LINE_LOOP, 2 LINE_LIST
            "type": {"type": "integer", "enum": [0, 1, 2]},
            "pose": pose(), "thickness": number(), "scale_invariant": {"type": "boolean"},
            "points": array_of(point3()), "color": color(), "colors": array_of(color()),
            "indices": array_of(integer())
        }),
    )
}

fn sphere_primitive() -> Value {
    object(
        "foxglove.SpherePrimitive",
        json!({"pose": pose(), "size": vector3(), "color": color()}),
    )
}

fn scene_update() -> Value {
    let entity = object(
        "foxglove.SceneEntity",
        json!({
            "timestamp": time(), "frame_id": string(), "id": string(), "lifetime": time(),
            "frame_locked": {"type": "boolean"},
            "metadata": array_of(object("foxglove.KeyValuePair", json!({"key": string(), "value": string()}))),
            "arrows": array_of(json!({"type": "object"})), "cubes": array_of(json!({"type": "object"})),
            "spheres": array_of(sphere_primitive()), "cylinders": array_of(json!({"type": "object"})),
            "lines": array_of(line_primitive()), "triangles": array_of(json!({"type": "object"})),
            "texts": array_of(json!({"type": "object"})), "models": array_of(json!({"type": "object"}))
        }),
    );
    let deletion = object(
        "foxglove.SceneEntityDeletion",
        json!({"timestamp": time(), "type": {"type": "integer", "enum": [0, 1]}, "id": string()}),
    );
    object(
        "foxglove.SceneUpdate",
        json!({"deletions": array_of(deletion), "entities": array_of(entity)}),
    )
}

fn log() -> Value {
    object(
        "foxglove.Log",
        json!({
            "timestamp": time(),
            // 0 UNKNOWN, 1 DEBUG, 2 INFO, 3 WARNING, 4 ERROR, 5 FATAL
            "level": {"type": "integer", "enum": [0, 1, 2, 3, 4, 5]},
            "message": string(), "name": string(), "file": string(), "line": integer()
        }),
    )
}

fn compressed_image() -> Value {
    object(
        "foxglove.CompressedImage",
        json!({
            "timestamp": time(), "frame_id": string(),
            "data": {"type": "string", "contentEncoding": "base64"},
            "format": string()
        }),
    )
}

fn image_annotations() -> Value {
    let points = object(
        "foxglove.PointsAnnotation",
        json!({
            "timestamp": time(),
            // 0 UNKNOWN, 1 POINTS, 2 LINE_LOOP, 3 LINE_STRIP, 4 LINE_LIST
            "type": {"type": "integer", "enum": [0, 1, 2, 3, 4]},
            "points": array_of(point2()), "outline_color": color(), "outline_colors": array_of(color()),
            "fill_color": color(), "thickness": number()
        }),
    );
    object(
        "foxglove.ImageAnnotations",
        json!({
            "circles": array_of(json!({"type": "object"})), "points": array_of(points),
            "texts": array_of(json!({"type": "object"}))
        }),
    )
}

fn pose_sample() -> Value {
    object(
        "omnitrack.PoseSample",
        json!({
            "timestamp_ns": integer(), "sequence": integer(),
            "status": {"type": "string", "enum": ["initializing", "tracking", "lost", "unknown"]},
            "position_m": array_of(number()), "rotation_wxyz": array_of(number()),
            "covariance": array_of(number()), "position_sigma_m": array_of(number()),
            "rotation_sigma_deg": array_of(number()), "inliers": integer(), "xi_rad2": number()
        }),
    )
}

fn status_sample() -> Value {
    object(
        "omnitrack.StatusSample",
        json!({
            "timestamp_ns": integer(), "sequence": integer(), "state": string(), "searching": string(),
            "search": string(), "source": string(), "pid": integer(),
            "frame_rate_hz": array_of(number()), "frames_dropped": array_of(integer()),
            "stage_p50_us": object("stages", json!({})), "stage_p99_us": object("stages", json!({}))
        }),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_channel_has_its_own_topic_and_a_schema_that_parses_and_names_its_type() {
        let c = channels(6);
        assert_eq!(c.len(), 8 + 12);
        let mut topics: Vec<_> = c.iter().map(|c| c.topic.as_str()).collect();
        topics.sort();
        topics.dedup();
        assert_eq!(topics.len(), c.len(), "a topic is used twice");
        for ch in &c {
            let v: Value = serde_json::from_str(&ch.schema).unwrap();
            assert_eq!(v["title"], ch.schema_name, "{}", ch.topic);
            assert_eq!(v["type"], "object");
        }
    }
}
