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
