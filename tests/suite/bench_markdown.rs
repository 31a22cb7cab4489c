//! `kinloop bench --markdown` (what docs/benchmarks.md is made of): a line naming the machine and the command,
//! then one Markdown table with a header, a separator and one row per case the JSON output names, each with
//! times that parse and a goal cell where the case has a goal.

use std::process::Command;

fn kinloop(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_kinloop")).args(args).output().expect("kinloop runs");
    let stdout = String::from_utf8(out.stdout).expect("UTF-8 output");
    assert!(out.status.success(), "kinloop {args:?}: {stdout}\n{}", String::from_utf8_lossy(&out.stderr));
    stdout
}

/// `368 ns`, `1.03 µs`, `2.10 ms` in ns.
fn parse_time(cell: &str) -> f64 {
    let (value, unit) = cell.trim().split_once(' ').unwrap_or_else(|| panic!("a time with a unit: {cell:?}"));
    let value: f64 = value.parse().unwrap_or_else(|e| panic!("{cell:?}: {e}"));
    let scale = match unit {
        "ns" => 1.0,
        "µs" => 1e3,
        "ms" => 1e6,
        other => panic!("unknown unit {other:?} in {cell:?}"),
    };
    assert!(value.is_finite() && value > 0.0, "{cell:?}");
    value * scale
}

fn cells(line: &str) -> Vec<&str> {
    let inner = line.trim().strip_prefix('|').and_then(|l| l.strip_suffix('|')).unwrap_or_else(|| panic!("{line:?}"));
    inner.split('|').map(str::trim).collect()
}

#[test]
fn the_markdown_table_has_a_row_per_case_with_times_that_parse() {
    // The testbed's cases: the core's (with goals), RK4 (without one), the client tick and the codec.
    let args = ["bench", "--filter", "testbed", "--seconds", "0.05"];
    let json = kinloop(&[&args[..], &["--json"]].concat());
    let json_names: Vec<String> = json
        .lines()
        .map(|l| {
            serde_json::from_str::<serde_json::Value>(l).expect("a JSON line")["name"].as_str().unwrap().to_owned()
        })
        .collect();
    let plain = kinloop(&args);
    let plain_names: Vec<&str> = plain.lines().filter_map(|l| l.split_whitespace().next()).collect();
    assert_eq!(plain_names, json_names, "the plain output names the same cases:\n{plain}");
    assert!(json_names.len() >= 5 && json_names.iter().all(|n| n.contains("testbed")), "{json_names:?}");

    let md = kinloop(&[&args[..], &["--markdown"]].concat());
    let mut lines = md.lines();
    let first = lines.next().expect("a first line");
    assert!(first.starts_with("Machine: ") && first.contains("logical CPU"), "{first}");
    assert!(first.contains("Command: `kinloop bench --markdown --seconds 0.05 --filter testbed`"), "{first}");
    let table: Vec<&str> = lines.skip_while(|l| l.trim().is_empty()).collect();
    assert_eq!(cells(table[0]), ["case", "median", "p10", "p90", "goal", "note"], "{md}");
    assert!(cells(table[1]).iter().all(|c| c.chars().all(|ch| ch == '-' || ch == ':') && c.contains("---")), "{md}");
    let rows = &table[2..];
    let row_names: Vec<String> = rows.iter().map(|r| cells(r)[0].trim_matches('`').to_owned()).collect();
    assert_eq!(row_names, json_names, "one row per case, in the suite's order:\n{md}");
    for row in rows {
        let c = cells(row);
        assert_eq!(c.len(), 6, "{row}");
        let (median, p10, p90) = (parse_time(c[1]), parse_time(c[2]), parse_time(c[3]));
        assert!(p10 <= median * 1.0001 && median <= p90 * 1.0001, "p10 ≤ median ≤ p90: {row}");
        let has_goal = ["ve_step/testbed", "op_space/testbed", "local_model/testbed", "client/tick_testbed"]
            .iter()
            .any(|n| c[0] == format!("`{n}`"));
        if has_goal {
            let goal = c[4].strip_prefix("≤ ").unwrap_or_else(|| panic!("a goal: {row}"));
            let (time, verdict) = goal.split_once(" (").unwrap();
            let goal = parse_time(time);
            // The cells are rounded: judge the verdict only where rounding cannot decide it.
            if (median - goal).abs() > 0.01 * goal {
                assert_eq!(verdict, if median < goal { "met)" } else { "missed)" }, "{row}");
            }
        }
    }
}
