//! MuJoCo itself, for the tests: a venv with MuJoCo's Python wheel made once under `target/` (pinned
//! version), and one Python process per batch of checks (`tests/mujoco/terms.py`). Without Python or the
//! wheel the tests fail, never skip.

#![allow(dead_code)]

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Mutex;

use nalgebra::{DMatrix, DVector};
use serde_json::Value;

/// The MuJoCo release the tests compare against.
pub const MUJOCO_VERSION: &str = "3.3.7";

static VENV: Mutex<()> = Mutex::new(());

/// The workspace root.
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("the crate sits in the workspace").to_path_buf()
}

/// A model of `mjcf/tests/models`.
pub fn model(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/models").join(name)
}

fn python_ok(python: &Path) -> bool {
    Command::new(python)
        .args(["-c", &format!("import mujoco, sys; sys.exit(mujoco.__version__ != '{MUJOCO_VERSION}')")])
        .status()
        .is_ok_and(|s| s.success())
}

/// The venv's Python, made on first use (`python3 -m venv`, then `pip install mujoco==VERSION`); built
/// aside and renamed into place, so a half-made venv is never used.
pub fn python() -> PathBuf {
    let _guard = VENV.lock().unwrap_or_else(|e| e.into_inner());
    let venv = root().join("target/mujoco-venv");
    let python = venv.join("bin/python");
    if python_ok(&python) {
        return python;
    }
    let aside = root().join(format!("target/mujoco-venv.making-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&aside);
    let run = |cmd: &mut Command, what: &str| {
        let status = cmd.status().unwrap_or_else(|e| panic!("{what}: cannot start: {e}"));
        assert!(status.success(), "{what} failed ({status}): the MuJoCo checks need python3 with venv and PyPI");
    };
    run(Command::new("python3").args(["-m", "venv"]).arg(&aside), "python3 -m venv");
    run(
        Command::new(aside.join("bin/python")).args([
            "-m",
            "pip",
            "install",
            "-q",
            &format!("mujoco=={MUJOCO_VERSION}"),
        ]),
        "pip install mujoco",
    );
    let _ = std::fs::remove_dir_all(&venv);
    std::fs::rename(&aside, &venv).expect("moving the venv into place");
    assert!(python_ok(&python), "the venv at {} does not import mujoco {MUJOCO_VERSION}", venv.display());
    python
}

/// One check: a model file and a state (empty: MuJoCo's qpos0 and rest).
pub struct Check {
    /// The model file.
    pub model: PathBuf,
    /// qpos.
    pub qpos: Vec<f64>,
    /// qvel.
    pub qvel: Vec<f64>,
    /// MuJoCo steps to take from qpos0 (0: none).
    pub steps: usize,
}

/// MuJoCo's terms for each check, from one Python process.
pub fn mujoco_terms(checks: &[Check]) -> Vec<Value> {
    let python = python();
    let input: Vec<Value> = checks
        .iter()
        .map(|c| serde_json::json!({ "model": c.model, "qpos": c.qpos, "qvel": c.qvel, "steps": c.steps }))
        .collect();
    let mut child = Command::new(python)
        .arg(root().join("tests/mujoco/terms.py"))
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("starting terms.py");
    child.stdin.take().unwrap().write_all(serde_json::to_string(&input).unwrap().as_bytes()).unwrap();
    let out = child.wait_with_output().expect("terms.py");
    assert!(out.status.success(), "terms.py failed: {}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice::<Vec<Value>>(&out.stdout).expect("terms.py prints JSON")
}

/// A JSON list of numbers as a vector.
pub fn vector(v: &Value) -> DVector<f64> {
    DVector::from_vec(v.as_array().expect("a list").iter().map(|x| x.as_f64().expect("a number")).collect())
}

/// A JSON list of rows as a matrix with `cols` columns (zero rows allowed).
pub fn matrix(v: &Value, cols: usize) -> DMatrix<f64> {
    let rows: Vec<DVector<f64>> = v.as_array().expect("a list of rows").iter().map(vector).collect();
    DMatrix::from_fn(rows.len(), cols, |r, c| rows[r][c])
}

/// ‖a − b‖∞ / ‖b‖∞ (absolute when b is zero).
pub fn relative(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len(), "sizes differ");
    let scale = b.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let diff = a.iter().zip(b).fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
    if scale == 0.0 {
        diff
    } else {
        diff / scale
    }
}

/// The exact constrained acceleration from M, the forces f and the equality rows J with J̇q̇ = `jdot_qdot`:
/// M q̈ = f + Jᵀλ, J q̈ = −J̇q̇, with λ the minimum-norm multipliers (redundant rows allowed).
pub fn exact_constrained_acceleration(
    m: &DMatrix<f64>,
    f: &DVector<f64>,
    j: &DMatrix<f64>,
    jdot_qdot: &DVector<f64>,
) -> DVector<f64> {
    let chol = m.clone().cholesky().expect("M is positive definite");
    let free = chol.solve(f);
    if j.nrows() == 0 {
        return free;
    }
    let minv_jt = chol.solve(&j.transpose());
    let a = j * &minv_jt;
    let b = -jdot_qdot - j * &free;
    let svd = a.svd(true, true);
    let tol = 1e-10 * svd.singular_values.max();
    let lambda = svd.solve(&b, tol).expect("SVD solve");
    free + minv_jt * lambda
}

/// The projector onto the row space of `j` (compares two Jacobians of the same constraints written with
/// different rows).
pub fn row_space(j: &DMatrix<f64>) -> DMatrix<f64> {
    let n = j.ncols();
    if j.nrows() == 0 {
        return DMatrix::zeros(n, n);
    }
    let svd = j.clone().svd(false, true);
    let vt = svd.v_t.unwrap();
    let tol = 1e-9 * svd.singular_values.max();
    let mut p = DMatrix::zeros(n, n);
    for (k, s) in svd.singular_values.iter().enumerate() {
        if *s > tol {
            let v = vt.row(k).transpose();
            p += &v * v.transpose();
        }
    }
    p
}
