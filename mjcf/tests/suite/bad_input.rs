//! Bad models: each error names the file, the line and what is wrong; unknown elements and what kinloop
//! cannot use are listed in the one warning, not fatal; a model that fails is never half used.

use std::path::Path;

use kinloop_mjcf::load::load;
use kinloop_mjcf::{import_str, MjcfError};

const GOOD_BODY: &str = r#"<body name="crank"><joint name="pivot" axis="0 0 1"/><geom type="capsule" fromto="0 0 0 0.1 0 0" size="0.01"/><site name="tip" pos="0.1 0 0"/></body>"#;

fn model(worldbody: &str, rest: &str) -> String {
    format!("<mujoco model=\"m\">\n{rest}\n<worldbody>\n{worldbody}\n</worldbody>\n</mujoco>\n")
}

fn error(text: &str) -> String {
    import_str(text, "bad.xml", Path::new(".")).expect_err("the model is refused").to_string()
}

#[test]
fn malformed_xml_names_the_file_and_line() {
    let message = error("<mujoco>\n<worldbody>\n<body name=\"a\">\n</worldbody>\n</mujoco>\n");
    assert!(message.starts_with("bad.xml:4:"), "{message}");
}

#[test]
fn unsupported_items_name_the_file_line_and_problem() {
    let cases = [
        (model("<body name=\"b\">\n<freejoint/>\n<geom size=\"0.1\"/>\n</body>", ""), "bad.xml:5:", "free joint"),
        (model(GOOD_BODY, "<compiler angle=\"grad\"/>"), "bad.xml:2:", "expected degree or radian"),
        (model("<body name=\"b\">\n<joint/>\n</body>", ""), "bad.xml:4:", "no mass"),
        (model(&GOOD_BODY.replace("0 0 0 0.1 0 0", "0 0 0 x 0 0"), ""), "bad.xml:4:", "'x' is not a finite number"),
        (
            model(GOOD_BODY, "<equality><connect body1=\"crank\" body2=\"nowhere\" anchor=\"0 0 0\"/></equality>"),
            "bad.xml:2:",
            "no body named 'nowhere'",
        ),
        (
            model(&GOOD_BODY.replace("<joint", "<joint class=\"nope\""), ""),
            "bad.xml:4:",
            "unknown default class 'nope'",
        ),
        (model(GOOD_BODY, "<actuator><position joint=\"elbow\"/></actuator>"), "bad.xml:2:", "no joint named 'elbow'"),
        (model(&GOOD_BODY.replace("axis=\"0 0 1\"", "axis=\"0 0 0\""), ""), "bad.xml:4:", "zero vector"),
    ];
    for (text, at, what) in cases {
        let message = error(&text);
        assert!(message.starts_with(at) && message.contains(what), "expected {at} … {what}: {message}");
    }
}

#[test]
fn unknown_and_unusable_items_are_listed_in_one_warning() {
    let text = model(
        &format!("{GOOD_BODY}\n<gizmo/>"),
        "<tendon><fixed name=\"t1\"/></tendon>\n<actuator><motor name=\"m1\" joint=\"pivot\"/></actuator>\n<sprocket/>",
    );
    let import = import_str(&text, "warn.xml", Path::new(".")).expect("the model imports");
    let message = import.warnings.message("warn.xml").expect("a warning");
    for item in ["tendon 't1'", "<motor> actuator 'm1'", "<gizmo> at line 7", "<sprocket> at line 4"] {
        assert!(message.contains(item), "{item} missing from: {message}");
    }
    assert_eq!(import.scene.bodies.len(), 1);
}

#[test]
fn a_failed_model_is_never_half_used() {
    let dir = tempfile::tempdir().unwrap();
    // The first body is fine; the second is not: the whole load fails, no scene comes back.
    let path = dir.path().join("half.xml");
    std::fs::write(&path, model(&format!("{GOOD_BODY}\n<body name=\"b\"><joint type=\"free\"/></body>"), "")).unwrap();
    let err = load(path.to_str().unwrap()).expect_err("refused");
    assert!(err.to_string().contains("half.xml:"), "{err}");
    // A missing include names the including file and line.
    let path = dir.path().join("inc.xml");
    std::fs::write(&path, "<mujoco>\n<worldbody>\n<include file=\"missing.xml\"/>\n</worldbody>\n</mujoco>\n").unwrap();
    match kinloop_mjcf::import_file(&path) {
        Err(MjcfError::Invalid { line: 3, problem, .. }) => assert!(problem.contains("missing.xml"), "{problem}"),
        other => panic!("expected an error at line 3, got {other:?}"),
    }
}

/// A model that looks planar but is not stays spatial, and says why: in its one warning when its hinges are
/// all parallel (a slide along them), only in the reduction's description when they are not.
#[test]
fn a_model_that_is_not_planar_stays_spatial_and_says_why() {
    let lift =
        r#"<body name="lift" pos="0.3 0 0"><joint name="up" type="slide" axis="0 0 1"/><geom size="0.02"/></body>"#;
    let import = import_str(&model(&format!("{GOOD_BODY}\n{lift}"), ""), "lift.xml", Path::new(".")).unwrap();
    assert_eq!(import.scene.kind, kinloop_linkage::math::space::SceneKind::Spatial);
    let message = import.warnings.message("lift.xml").expect("a warning");
    assert!(message.contains("kept spatial: slide 'up' moves along the hinges' axis"), "{message}");
    let tilted = GOOD_BODY.replace("name=\"crank\"", "name=\"other\"").replace("pivot", "tilt").replace("tip", "t2");
    let tilted = tilted.replace("axis=\"0 0 1\"", "axis=\"1 0 0\"");
    let import = import_str(&model(&format!("{GOOD_BODY}\n{tilted}"), ""), "t.xml", Path::new(".")).unwrap();
    assert_eq!(import.warnings.message("t.xml"), None);
    assert_eq!(import.reduction.describe(), "kept spatial: hinge 'tilt' is not parallel to hinge 'pivot'");
    let import = import_str(&model(GOOD_BODY, ""), "one.xml", Path::new(".")).unwrap();
    assert_eq!(import.scene.kind, kinloop_linkage::math::space::SceneKind::Planar);
}
