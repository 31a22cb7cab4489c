//! The one reader of both records: the header says which record a file is (and for which scene kind and
//! size); every row is checked against it. Errors name the file, the line and the column.

use std::path::Path;

use kinloop_linkage::math::space::SceneKind;

use crate::axes::pose_names;
use crate::rows::{TickRecord, VeRow, VeUserRow};
use crate::schema::{kind_of, ClientSchema, VeSchema};

/// Why a record could not be read.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// The file could not be read.
    #[error("cannot read {file}: {source}")]
    Io {
        /// The file.
        file: String,
        /// Why.
        source: std::io::Error,
    },
    /// The file has no header line.
    #[error("{file}: no rows")]
    Empty {
        /// The file.
        file: String,
    },
    /// The header is neither record's.
    #[error("{file}: not a kinloop recording (the header starts with neither t_s,step nor time_s,device_)")]
    UnknownFormat {
        /// The file.
        file: String,
    },
    /// The header starts as a record's but its columns are not the record's.
    #[error("{file}:1: the header is not a {which} record's: column {column} is {found:?}, expected {expected:?}")]
    Header {
        /// The file.
        file: String,
        /// Whose record (client or server).
        which: &'static str,
        /// 1-based column.
        column: usize,
        /// The column's name in the file (empty past its end).
        found: String,
        /// The record's column there (empty past its end).
        expected: String,
    },
    /// A record of the other end or another scene kind than the reader asked for.
    #[error("{file}: {found}, not {expected}")]
    NotAsked {
        /// The file.
        file: String,
        /// What the file is.
        found: String,
        /// What was asked for.
        expected: String,
    },
    /// A field that is not a number.
    #[error("{file}:{line}: column {column}: {text:?} is not a number")]
    NotANumber {
        /// The file.
        file: String,
        /// 1-based line.
        line: usize,
        /// The column's name.
        column: String,
        /// The field.
        text: String,
    },
    /// A count (users, constraint directions) that is not a whole number in range.
    #[error("{file}:{line}: column {column}: {value} is not a count")]
    NotACount {
        /// The file.
        file: String,
        /// 1-based line.
        line: usize,
        /// The column's name.
        column: String,
        /// The number found.
        value: f64,
    },
    /// A row with too few or too many fields.
    #[error("{file}:{line}: {found} fields, expected {expected}")]
    Width {
        /// The file.
        file: String,
        /// 1-based line.
        line: usize,
        /// Fields in the row.
        found: usize,
        /// Fields its header (and, in a server's record, its user count) asks for.
        expected: usize,
    },
}

/// A record read back: which one, its schema and its rows.
#[derive(Clone, Debug, PartialEq)]
pub enum Recording {
    /// A client's record.
    Client {
        /// Its columns.
        schema: ClientSchema,
        /// One per haptic tick.
        rows: Vec<TickRecord>,
    },
    /// A server's record.
    Ve {
        /// Its columns.
        schema: VeSchema,
        /// One per VE step.
        rows: Vec<VeRow>,
    },
}

impl Recording {
    /// The scene kind it was recorded on.
    pub fn kind(&self) -> SceneKind {
        match self {
            Recording::Client { schema, .. } => schema.kind,
            Recording::Ve { schema, .. } => schema.kind,
        }
    }

    /// Its rows.
    pub fn len(&self) -> usize {
        match self {
            Recording::Client { rows, .. } => rows.len(),
            Recording::Ve { rows, .. } => rows.len(),
        }
    }

    /// Whether it has no rows.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    fn describe(&self) -> String {
        let end = if matches!(self, Recording::Client { .. }) { "client" } else { "server" };
        format!("a {end}'s record of a {:?} scene", self.kind())
    }
}

/// Reads the record at `path` (named by its path in errors).
pub fn read(path: &Path) -> Result<Recording, ReadError> {
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|source| ReadError::Io { file: file.clone(), source })?;
    parse(&text, &file)
}

/// Reads a client's record of a `kind` scene at `path`.
pub fn read_client(path: &Path, kind: SceneKind) -> Result<Vec<TickRecord>, ReadError> {
    match read(path)? {
        Recording::Client { schema, rows } if schema.kind == kind => Ok(rows),
        other => Err(not_asked(path, &other, format!("a client's record of a {kind:?} scene"))),
    }
}

/// Reads a server's record of a `kind` scene at `path`.
pub fn read_ve(path: &Path, kind: SceneKind) -> Result<(VeSchema, Vec<VeRow>), ReadError> {
    match read(path)? {
        Recording::Ve { schema, rows } if schema.kind == kind => Ok((schema, rows)),
        other => Err(not_asked(path, &other, format!("a server's record of a {kind:?} scene"))),
    }
}

fn not_asked(path: &Path, found: &Recording, expected: String) -> ReadError {
    ReadError::NotAsked { file: path.display().to_string(), found: found.describe(), expected }
}

/// Parses a record's text; `file` names it in errors. Blank lines are skipped.
pub fn parse(text: &str, file: &str) -> Result<Recording, ReadError> {
    let mut lines = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty()).map(|(i, l)| (i + 1, l));
    let Some((_, header)) = lines.next() else { return Err(ReadError::Empty { file: file.into() }) };
    let columns: Vec<&str> = header.split(',').map(str::trim).collect();
    let kind = kind_of(&columns);
    if columns.starts_with(&["t_s", "step"]) {
        let count = |prefix: &str| columns.iter().filter(|c| c.starts_with(prefix)).count();
        let schema = VeSchema { kind, nq: count("q_"), n: count("qd_"), m: count("lambda_") };
        check_header(file, "server", &columns, &schema.header())?;
        let rows = lines.map(|(line, text)| ve_row(&Fields { file, line, text }, &schema)).collect::<Result<_, _>>()?;
        Ok(Recording::Ve { schema, rows })
    } else if columns.first() == Some(&"time_s") && columns.get(1).is_some_and(|c| c.starts_with("device_")) {
        let schema = ClientSchema { kind };
        let mut names = schema.columns();
        if columns.last() != Some(&ClientSchema::SESSION_COLUMN) {
            // Written before the session column: one session throughout.
            names.pop();
        }
        check_header(file, "client", &columns, &names.join(","))?;
        let rows = lines
            .map(|(line, text)| tick_row(&Fields { file, line, text }, &schema, &names))
            .collect::<Result<_, _>>()?;
        Ok(Recording::Client { schema, rows })
    } else {
        Err(ReadError::UnknownFormat { file: file.into() })
    }
}

/// The first column where `columns` differ from `expected`'s.
fn check_header(file: &str, which: &'static str, columns: &[&str], expected: &str) -> Result<(), ReadError> {
    let expected: Vec<&str> = expected.split(',').collect();
    let at = (0..columns.len().max(expected.len())).find(|&i| columns.get(i) != expected.get(i));
    match at {
        None => Ok(()),
        Some(i) => Err(ReadError::Header {
            file: file.into(),
            which,
            column: i + 1,
            found: columns.get(i).copied().unwrap_or_default().into(),
            expected: expected.get(i).copied().unwrap_or_default().into(),
        }),
    }
}

/// One data line, for errors that name where it is.
struct Fields<'a> {
    file: &'a str,
    line: usize,
    text: &'a str,
}

impl Fields<'_> {
    /// The line's numbers; `name` names the column of the field at an index.
    fn numbers(&self, name: impl Fn(usize) -> String) -> Result<Vec<f64>, ReadError> {
        self.text
            .split(',')
            .enumerate()
            .map(|(i, field)| {
                field.trim().parse::<f64>().map_err(|_| ReadError::NotANumber {
                    file: self.file.into(),
                    line: self.line,
                    column: name(i),
                    text: field.trim().into(),
                })
            })
            .collect()
    }

    fn width(&self, found: usize, expected: usize) -> Result<(), ReadError> {
        if found == expected {
            return Ok(());
        }
        Err(ReadError::Width { file: self.file.into(), line: self.line, found, expected })
    }

    /// `value` as a whole number no larger than `max`.
    fn count(&self, value: f64, max: f64, column: impl Into<String>) -> Result<f64, ReadError> {
        if value >= 0.0 && value.fract() == 0.0 && value <= max {
            return Ok(value);
        }
        Err(ReadError::NotACount { file: self.file.into(), line: self.line, column: column.into(), value })
    }
}

fn tick_row(fields: &Fields, schema: &ClientSchema, names: &[String]) -> Result<TickRecord, ReadError> {
    let name = |i: usize| names.get(i).cloned().unwrap_or_else(|| format!("{}", i + 1));
    let v = fields.numbers(name)?;
    fields.width(v.len(), names.len())?;
    let (pose_len, k) = (pose_names(schema.kind).len(), schema.kind.op_dim());
    let mut at = 0;
    let mut take = |len: usize| {
        at += len;
        &v[at - len..at]
    };
    let mut r = TickRecord { time_s: take(1)[0], ..TickRecord::default() };
    r.device_pose[..pose_len].copy_from_slice(take(pose_len));
    r.model_pose[..pose_len].copy_from_slice(take(pose_len));
    for w in [
        &mut r.hand,
        &mut r.position_channel,
        &mut r.joint_constraint,
        &mut r.impedance,
        &mut r.contact,
        &mut r.command,
    ] {
        w[..k].copy_from_slice(take(k));
    }
    let [count, age, gain] = [take(1)[0], take(1)[0], take(1)[0]];
    r.constraint_count = fields.count(count, 6.0, "constraint_count")? as u8;
    (r.snapshot_age_s, r.gain) = (age, gain);
    r.session = match v.get(at) {
        Some(&session) => fields.count(session, f64::from(u32::MAX), ClientSchema::SESSION_COLUMN)? as u32,
        None => 1,
    };
    Ok(r)
}

fn ve_row(fields: &Fields, schema: &VeSchema) -> Result<VeRow, ReadError> {
    let v = fields.numbers(|i| schema.column_name(i))?;
    let (fixed, group) = (schema.fixed_len(), schema.group_len());
    if v.len() < fixed {
        fields.width(v.len(), fixed)?;
    }
    let users = fields.count(v[fixed - 1], f64::from(u32::MAX), "users")? as usize;
    fields.width(v.len(), fixed + users * group)?;
    let (nq, n, m, pose_len, k) = (schema.nq, schema.n, schema.m, pose_names(schema.kind).len(), schema.kind.op_dim());
    let users = v[fixed..]
        .chunks_exact(group)
        .enumerate()
        .map(|(u, g)| {
            let mut user = VeUserRow {
                user_id: fields.count(g[0], f64::from(u32::MAX), schema.column_name(fixed + u * group))? as u32,
                constraint_count: fields.count(g[group - 1], 255.0, schema.column_name(fixed + (u + 1) * group - 1))?
                    as u8,
                ..VeUserRow::default()
            };
            user.op_pose[..pose_len].copy_from_slice(&g[1..1 + pose_len]);
            user.wrench[..k].copy_from_slice(&g[1 + pose_len..1 + pose_len + k]);
            Ok(user)
        })
        .collect::<Result<_, ReadError>>()?;
    Ok(VeRow {
        t_s: v[0],
        step: fields.count(v[1], u64::MAX as f64, "step")? as u64,
        q: v[2..2 + nq].to_vec(),
        qd: v[2 + nq..2 + nq + n].to_vec(),
        lambda: v[2 + nq + n..2 + nq + n + m].to_vec(),
        closure_error: v[fixed - 2],
        users,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::write::RecordFile;

    fn tick(t: f64) -> TickRecord {
        let mut r = TickRecord {
            time_s: t,
            constraint_count: 2,
            snapshot_age_s: f64::NAN,
            gain: 0.75,
            session: 2,
            ..TickRecord::default()
        };
        r.device_pose[..3].copy_from_slice(&[1.0, 2.0, 3.0]);
        r.model_pose[..3].copy_from_slice(&[4.0, 5.0, 6.0]);
        r.command[..3].copy_from_slice(&[22.0, 23.0, 24.0]);
        r
    }

    #[test]
    fn a_written_client_record_reads_back_row_for_row() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("c.csv");
        let schema = ClientSchema { kind: SceneKind::Planar };
        let mut file = RecordFile::create(&path, &schema.header()).unwrap();
        for t in [0.0, 0.001] {
            file.write_tick(&schema, &tick(t)).unwrap();
        }
        file.finish().unwrap();
        let rows = read_client(&path, SceneKind::Planar).unwrap();
        assert_eq!(rows.len(), 2);
        let (back, sent) = (rows[1], tick(0.001));
        assert!(back.snapshot_age_s.is_nan());
        assert_eq!(TickRecord { snapshot_age_s: 0.0, ..back }, TickRecord { snapshot_age_s: 0.0, ..sent });
        let e = read_ve(&path, SceneKind::Planar).unwrap_err().to_string();
        assert!(e.contains("a client's record of a Planar scene, not a server's"), "{e}");
    }

    /// A record written before the session column reads as one session; a session that is not a whole
    /// number is refused naming the column.
    #[test]
    fn a_client_record_without_the_session_column_is_one_session() {
        let schema = ClientSchema { kind: SceneKind::Planar };
        let header = schema.header();
        let old_header = header.strip_suffix(",session").expect("session is the last column");
        let numbers = |n: usize| vec!["0.5"; n].join(",");
        let width = schema.columns().len();
        let old = format!("{old_header}\n{}\n", numbers(width - 1).replacen("0.5", "1", 26));
        let rows = match parse(&old, "old.csv").unwrap() {
            Recording::Client { rows, .. } => rows,
            other => panic!("{}", other.describe()),
        };
        assert_eq!(rows[0].session, 1);
        let bad = format!("{header}\n{}\n", numbers(width).replacen("0.5", "1", 26));
        let e = parse(&bad, "new.csv").unwrap_err().to_string();
        assert!(e.contains("session"), "{e}");
    }

    #[test]
    fn a_written_ve_record_reads_back_with_every_user() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("ve.csv");
        let schema = VeSchema { kind: SceneKind::Planar, nq: 1, n: 1, m: 1 };
        let mut file = RecordFile::create(&path, &schema.header()).unwrap();
        file.write_ve_numbers([0.001, 1.0, 0.5, 0.0, 0.0, 1e-12, 1.0, 7.0, 0.1, 0.2, 0.3, 1.0, 2.0, 3.0, 1.0]).unwrap();
        let two =
            [0.002, 2.0, 0.6, 0.1, 0.2, 2e-12, 2.0, 7.0, 0.4, 0.5, 0.6, 1.0, 2.0, 3.0, 2.0, 9.0, 1.0, 1.0, 1.0, 4.0];
        file.write_ve_numbers(two.into_iter().chain([5.0, 6.0, 1.0])).unwrap();
        file.finish().unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(
            text.ends_with("\n0.002,2,0.6,0.1,0.2,0.000000000002,2,7,0.4,0.5,0.6,1,2,3,2,9,1,1,1,4,5,6,1\n"),
            "{text}"
        );
        let (read_schema, rows) = read_ve(&path, SceneKind::Planar).unwrap();
        assert_eq!(read_schema, schema);
        assert_eq!(
            (rows[1].step, rows[1].q.clone(), rows[1].qd.clone(), rows[1].lambda.clone()),
            (2, vec![0.6], vec![0.1], vec![0.2])
        );
        assert_eq!(rows[1].closure_error, 2e-12);
        let user = rows[1].users[1];
        assert_eq!(
            (user.user_id, &user.op_pose[..3], &user.wrench[..3], user.constraint_count),
            (9, &[1.0, 1.0, 1.0][..], &[4.0, 5.0, 6.0][..], 1)
        );
    }

    fn error(text: &str) -> String {
        parse(text, "x.csv").unwrap_err().to_string()
    }

    #[test]
    fn broken_records_name_the_file_line_and_column() {
        let client = ClientSchema { kind: SceneKind::Planar }.header();
        assert_eq!(error(""), "x.csv: no rows");
        assert!(error("a,b\n1,2\n").contains("not a kinloop recording"));
        assert!(
            error(&format!("{client}\n\n0.1,2\n")).starts_with("x.csv:3: 2 fields, expected 29"),
            "{}",
            error(&format!("{client}\n0.1,2\n"))
        );
        let e = error(&format!("{client}\n0.1,x\n"));
        assert!(e.starts_with("x.csv:2: column device_x: \"x\" is not a number"), "{e}");
        let e = error("time_s,device_x,device_y,device_theta,model_x\n");
        assert!(
            e.starts_with("x.csv:1: the header is not a client record's: column 6 is \"\", expected \"model_y\""),
            "{e}"
        );
        let ve = VeSchema { kind: SceneKind::Planar, nq: 1, n: 1, m: 0 }.header();
        let e = error(&format!("{ve}\n0,1,0,0,0,1,7,0,0,0,0,0,0\n"));
        assert!(e.starts_with("x.csv:2: 13 fields, expected 14"), "{e}");
        let e = error(&format!("{ve}\n0,1,0,0,0,1,7,0,0,0,0,0,0,0.5\n"));
        assert!(e.starts_with("x.csv:2: column user 1 constraint_count: 0.5 is not a count"), "{e}");
        let e = error(&format!("{ve}\n0,1,0,0,0,-1\n"));
        assert!(e.contains("column users: -1 is not a count"), "{e}");
        let e = read(Path::new("/nonexistent/kinloop.csv")).unwrap_err();
        assert!(matches!(e, ReadError::Io { .. }), "{e}");
    }
}
