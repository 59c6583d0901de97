//! Bad floor plans: one line naming the file, the feature and the problem; never a panic.

use super::*;

#[track_caller]
fn assert_error(geojson: &str, place: &str, words: &[&str]) {
    let e = extrude(geojson, "bad.geojson").expect_err("bad input was accepted");
    let message = e.to_string();
    assert!(!message.contains('\n'), "not one line: {message}");
    assert!(message.starts_with("bad.geojson: "), "no file name: {message}");
    assert!(message.contains(place), "does not name {place:?}: {message}");
    for w in words {
        assert!(message.contains(w), "does not say {w:?}: {message}");
    }
}

fn wall(coordinates: &str) -> String {
    feature("wall", "", "LineString", coordinates)
}

#[test]
fn not_geojson() {
    assert_error("walls: 3", "", &["not GeoJSON", "invalid JSON"]);
    assert_error("[1, 2]", "", &["not GeoJSON"]);
    assert_error(r#"{"type": "Feature"}"#, "", &["FeatureCollection", "\"Feature\""]);
    assert_error(r#"{"type": "FeatureCollection"}"#, "", &["\"features\""]);
    assert_error(
        &plan(r#"{"type": "Feature", "geometry": null}"#),
        "features[0] (?)",
        &["properties"],
    );
}

#[test]
fn unknown_kind() {
    assert_error(
        &plan(&feature("stair", "", "LineString", "[[0, 0], [1, 0]]")),
        "features[0] (stair)",
        &["unknown kind \"stair\""],
    );
    assert_error(
        &plan(
            &[
                wall("[[0, 0], [1, 0]]"),
                feature("wal", "", "LineString", "[[0, 0], [1, 0]]"),
            ]
            .join(","),
        ),
        "features[1] (wal)",
        &["unknown kind"],
    );
}

#[test]
fn wrong_geometry_type() {
    assert_error(
        &plan(&feature("wall", "", "Polygon", "[[[0, 0], [1, 0], [1, 1], [0, 0]]]")),
        "features[0] (wall)",
        &["wrong geometry type", "LineString", "Polygon"],
    );
    assert_error(
        &plan(&feature("room", "", "LineString", "[[0, 0], [1, 0]]")),
        "features[0] (room)",
        &["wrong geometry type", "needs a Polygon"],
    );
    assert_error(
        &plan(
            &[
                wall("[[0, 0], [4, 0]]"),
                feature("door", "", "LineString", "[[1, 0], [2, 0], [3, 0]]"),
            ]
            .join(","),
        ),
        "features[1] (door)",
        &["exactly 2 points"],
    );
    assert_error(
        &plan(&wall("[[0, 0]]")),
        "features[0] (wall)",
        &["at least 2 distinct points"],
    );
    assert_error(
        &plan(&wall("[[0, 0], [\"a\", 1]]")),
        "features[0] (wall)",
        &["not a number"],
    );
}

#[test]
fn opening_not_on_a_wall() {
    assert_error(
        &plan(
            &[
                wall("[[0, 0], [4, 0]]"),
                feature("window", "", "LineString", "[[1, 0.5], [2, 0.5]]"),
            ]
            .join(","),
        ),
        "features[1] (window)",
        &["not on any wall"],
    );
    // On the axis line but past the wall's end.
    assert_error(
        &plan(
            &[
                wall("[[0, 0], [4, 0]]"),
                feature("door", "", "LineString", "[[3.5, 0], [4.5, 0]]"),
            ]
            .join(","),
        ),
        "features[1] (door)",
        &["not on any wall"],
    );
    assert_error(
        &plan(
            &[
                wall("[[0, 0], [4, 0]]"),
                feature("door", "", "LineString", "[[3.2, 0], [4, 0]]"),
            ]
            .join(","),
        ),
        "features[1] (door)",
        &["reaches past the end of features[0] (wall)"],
    );
}

#[test]
fn overlapping_openings() {
    assert_error(
        &plan(
            &[
                wall("[[0, 0], [6, 0]]"),
                feature("door", "", "LineString", "[[1, 0], [2, 0]]"),
                feature("window", "", "LineString", "[[3, 0], [1.5, 0]]"),
            ]
            .join(","),
        ),
        "features[2] (window)",
        &["overlaps", "features[1] (door)", "features[0] (wall)"],
    );
}

#[test]
fn head_below_sill_and_above_the_wall() {
    assert_error(
        &plan(
            &[
                wall("[[0, 0], [4, 0]]"),
                feature(
                    "window",
                    r#", "sill_height_m": 1.2, "head_height_m": 1.0"#,
                    "LineString",
                    "[[1, 0], [2, 0]]",
                ),
            ]
            .join(","),
        ),
        "features[1] (window)",
        &["head_height_m 1 is not above sill_height_m 1.2"],
    );
    assert_error(
        &plan(
            &[
                feature("wall", r#", "height_m": 2.0"#, "LineString", "[[0, 0], [4, 0]]"),
                feature("door", r#", "head_height_m": 2.1"#, "LineString", "[[1, 0], [2, 0]]"),
            ]
            .join(","),
        ),
        "features[1] (door)",
        &["head_height_m 2.1 is above the height 2 of features[0] (wall)"],
    );
}

#[test]
fn non_finite_and_out_of_range_numbers() {
    // JSON cannot spell NaN or infinity; a literal too large for f64 is a JSON error.
    assert_error(
        &plan(&feature(
            "wall",
            r#", "height_m": 1e999"#,
            "LineString",
            "[[0, 0], [4, 0]]",
        )),
        "",
        &["invalid JSON", "out of range"],
    );
    assert_error(
        &plan(&feature(
            "wall",
            r#", "height_m": 1e300"#,
            "LineString",
            "[[0, 0], [4, 0]]",
        )),
        "features[0] (wall)",
        &["height_m", "out of range"],
    );
    assert_error(
        &plan(&wall("[[0, 0], [4e300, 0]]")),
        "features[0] (wall)",
        &["coordinate", "out of range"],
    );
    assert_error(
        &plan(&feature(
            "wall",
            r#", "height_m": "tall""#,
            "LineString",
            "[[0, 0], [4, 0]]",
        )),
        "features[0] (wall)",
        &["height_m must be a number"],
    );
}

#[test]
fn negative_thickness() {
    assert_error(
        &plan(&feature(
            "wall",
            r#", "thickness_m": -0.1"#,
            "LineString",
            "[[0, 0], [4, 0]]",
        )),
        "features[0] (wall)",
        &["negative thickness"],
    );
    let top = r#"{"type": "FeatureCollection", "properties": {"wall_thickness_m": -1}, "features": []}"#;
    assert_error(top, "top-level properties", &["negative thickness"]);
}

#[test]
fn bad_polygons() {
    assert_error(
        &plan(&feature("room", "", "Polygon", "[[[0, 0], [1, 0], [0, 0]]]")),
        "features[0] (room)",
        &["fewer than 3 distinct points"],
    );
    assert_error(
        &plan(&feature("room", "", "Polygon", "[[[0, 0], [1, 0], [2, 0], [0, 0]]]")),
        "features[0] (room)",
        &["no area"],
    );
    assert_error(
        &plan(&feature(
            "room",
            "",
            "Polygon",
            "[[[0, 0], [4, 0], [4, 4], [0, 4], [0, 0]], [[1, 1], [2, 1], [2, 2], [1, 1]]]",
        )),
        "features[0] (room)",
        &["holes"],
    );
    assert_error(
        &plan(&feature(
            "room",
            r#", "ceiling_m": 0"#,
            "Polygon",
            "[[[0, 0], [1, 0], [1, 1], [0, 0]]]",
        )),
        "features[0] (room)",
        &["ceiling_m 0 is not above floor_m 0"],
    );
}

#[test]
fn misspelt_length_and_bad_joins() {
    assert_error(
        &plan(&feature(
            "wall",
            r#", "thicknes_m": 0.2"#,
            "LineString",
            "[[0, 0], [4, 0]]",
        )),
        "features[0] (wall)",
        &["unknown property \"thicknes_m\""],
    );
    // Other properties (names, styling) are fine.
    assert!(extrude(
        &plan(&feature(
            "wall",
            r#", "stroke": "red", "name": "x""#,
            "LineString",
            "[[0, 0], [4, 0]]"
        )),
        "ok"
    )
    .is_ok());
    // A thick wall doubling back, and two thick walls meeting end to end.
    assert_error(
        &plan(&feature(
            "wall",
            r#", "thickness_m": 0.2"#,
            "LineString",
            "[[0, 0], [4, 0], [2, 0]]",
        )),
        "features[0] (wall)",
        &["turns back"],
    );
    assert_error(
        &plan(
            &[
                feature("wall", r#", "thickness_m": 0.2"#, "LineString", "[[0, 0], [4, 0]]"),
                feature("wall", r#", "thickness_m": 0.2"#, "LineString", "[[4, 0], [4, 3]]"),
            ]
            .join(","),
        ),
        "features[0] (wall)",
        &["end or corner of features[1] (wall)", "one LineString"],
    );
    // Thin walls meeting end to end are fine: their panels simply meet.
    let model = load(&plan(&[wall("[[0, 0], [4, 0]]"), wall("[[4, 0], [4, 3]]")].join(",")));
    assert_segment(&model, p(4.0, 0.0, 0.0), p(4.0, 0.0, 2.5));
    assert_eq!(model.segments.len(), 7);
}
