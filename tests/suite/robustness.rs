//! `kinloop experiment robustness` on a fixed small sample (seed 1's linkage, the quick grid: soft hand,
//! 0 and 300 ms, 10 s sessions): every session of the matrix runs and is judged, its summary says what the
//! sample covered, and every failure names its seed and a reason of the stated kinds.

use kinloop::experiments::robustness::{points, run_seeds};
use kinloop::experiments::Options;
use kinloop::generate::generate;
use kinloop_client::user::HandKind;

#[test]
fn a_fixed_sample_is_judged_with_its_coverage_and_seeded_failures() {
    let dir = tempfile::tempdir().expect("a temporary directory");
    let options = Options::new(dir.path()).quick();
    let options = Options { progress: false, ..options };
    let report = run_seeds(&options, 1..2).expect("the experiment runs");
    let s = &report.summary["results"];
    let linkage = generate(1, None);
    let expected = points(std::slice::from_ref(&linkage), &[HandKind::Soft], &[0, 300]).len();
    assert_eq!(s["sessions"].as_u64(), Some(expected as u64), "{s}");
    assert_eq!(s["coverage"]["linkages"].as_u64(), Some(1));
    assert_eq!(s["coverage"]["classes"][linkage.class.name()].as_u64(), Some(1));
    assert_eq!(s["coverage"]["ops"].as_u64(), Some(linkage.scene.ops.len() as u64));
    let failing = s["failing"].as_array().expect("a failure list");
    let rendering = s["rendering"].as_u64().unwrap_or(0) as usize;
    assert_eq!(rendering + failing.len(), expected, "{s}");
    for f in failing {
        assert_eq!(f["seed"].as_u64(), Some(1), "{f}");
        let reasons = f["failures"].as_array().expect("reasons");
        assert!(!reasons.is_empty(), "{f}");
        for r in reasons {
            let kind = r.as_str().unwrap_or("").split(':').next().unwrap_or("");
            let kinds = ["refused", "refused (predicted)", "unstable", "closure", "saturation", "tracking"];
            assert!(kinds.contains(&kind), "{r}");
        }
    }
    assert!(dir.path().join("robustness/summary.json").exists());
}
