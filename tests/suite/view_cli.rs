//! `kinloop view FILE.csv`: serves a recording and says what it loaded; a file that is not a recording, or
//! one made on another scene, is refused with the reason.

use std::process::Command;

const HEADER: &str = "t_s,step,q_0,q_1,q_2,q_3,qd_0,qd_1,qd_2,qd_3,lambda_0,lambda_1,closure_error_m,users,\
                      user_id,op_x,op_y,op_theta,wrench_fx,wrench_fy,wrench_tz,constraint_count,...(user group repeated per user)\n";

fn kinloop(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_kinloop")).args(args).output().expect("kinloop runs")
}

#[test]
fn a_recording_is_served_and_a_wrong_one_is_refused_with_the_reason() {
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("ve.csv");
    let q0 = "0.7853981633974483,-1.5707963267948966,-1.2566370614359172,-1.5707963267948966";
    let rows = format!(
        "{HEADER}0.001,1,{q0},0,0,0,0,0,0,1e-12,1,1,0.02,0.03,0.1,-0.5,0,0,1\n\
         0.002,2,{q0},0,0,0,0,0,0,1e-12,1,1,0.02,0.03,0.1,-0.5,0,0,1\n"
    );
    std::fs::write(&good, rows).unwrap();
    let path = good.to_str().unwrap();
    let out = kinloop(&["view", path, "--listen", "127.0.0.1:0", "--duration", "0.2"]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
    assert!(stdout.contains("ve.csv (server recording, 2 rows, 0.001 to 0.002 s) at http://127.0.0.1:"), "{stdout}");

    let out = kinloop(&["view", path, "--scene", "watt-six-bar", "--listen", "127.0.0.1:0", "--duration", "0.2"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(stderr.contains("4 coordinates") && stderr.contains("--scene"), "{stderr}");

    let junk = dir.path().join("junk.csv");
    std::fs::write(&junk, "a,b\n1,2\n").unwrap();
    let out = kinloop(&["view", junk.to_str().unwrap(), "--listen", "127.0.0.1:0", "--duration", "0.2"]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("not a kinloop recording"));
}
