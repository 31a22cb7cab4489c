//! The one writer of both records: a header line, then rows of numbers, each printed as its column's
//! [`Format`] says.

use std::fmt::Write as _;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use crate::axes::pose_names;
use crate::rows::TickRecord;
use crate::schema::{ClientSchema, Format, VeSchema};

/// Why a record file could not be started.
#[derive(Debug, thiserror::Error)]
#[error("cannot record to {path}: {source}")]
pub struct RecordError {
    /// The file.
    pub path: PathBuf,
    /// Why.
    pub source: std::io::Error,
}

/// Appends `value` to `line` as `format` says.
pub fn push_number(line: &mut String, value: f64, format: Format) {
    // Writing to a String cannot fail.
    let _ = match format {
        Format::Fixed(decimals) => write!(line, "{value:.decimals$}"),
        Format::Shortest if value.fract() == 0.0 && value.abs() < 1e15 => write!(line, "{}", value as i64),
        Format::Shortest => write!(line, "{value}"),
    };
}

/// A record file being written: its header is written on creation, its rows one call each.
pub struct RecordFile {
    out: BufWriter<File>,
    /// The row being formatted (kept to reuse its allocation).
    line: String,
}

impl RecordFile {
    /// Creates `path` and writes `header`.
    pub fn create(path: &Path, header: &str) -> Result<RecordFile, RecordError> {
        let error = |source| RecordError { path: path.to_owned(), source };
        let mut out = BufWriter::new(File::create(path).map_err(error)?);
        writeln!(out, "{header}").map_err(error)?;
        Ok(RecordFile { out, line: String::new() })
    }

    /// Writes one row of numbers, each with its format.
    pub fn write_row(&mut self, numbers: impl IntoIterator<Item = (f64, Format)>) -> std::io::Result<()> {
        self.line.clear();
        for (i, (value, format)) in numbers.into_iter().enumerate() {
            if i > 0 {
                self.line.push(',');
            }
            push_number(&mut self.line, value, format);
        }
        self.line.push('\n');
        self.out.write_all(self.line.as_bytes())
    }

    /// Writes one haptic tick of a client's record.
    pub fn write_tick(&mut self, schema: &ClientSchema, r: &TickRecord) -> std::io::Result<()> {
        let (pose_len, k) = (pose_names(schema.kind).len(), schema.kind.op_dim());
        let time = [(r.time_s, ClientSchema::TIME)];
        let poses = r.device_pose[..pose_len].iter().chain(&r.model_pose[..pose_len]).map(|&v| (v, ClientSchema::POSE));
        let wrenches = [&r.hand, &r.position_channel, &r.joint_constraint, &r.impedance, &r.contact, &r.command];
        let wrenches = wrenches.into_iter().flat_map(|w| w[..k].iter().map(|&v| (v, ClientSchema::WRENCH)));
        let tail = [
            (f64::from(r.constraint_count), ClientSchema::COUNT),
            (r.snapshot_age_s, ClientSchema::AGE),
            (r.gain, ClientSchema::GAIN),
            (f64::from(r.session), ClientSchema::SESSION),
        ];
        self.write_row(time.into_iter().chain(poses).chain(wrenches).chain(tail))
    }

    /// Writes one VE step of a server's record from its numbers in file order.
    pub fn write_ve_numbers(&mut self, numbers: impl IntoIterator<Item = f64>) -> std::io::Result<()> {
        self.write_row(numbers.into_iter().map(|v| (v, VeSchema::NUMBER)))
    }

    /// Flushes what is buffered to the file.
    pub fn finish(mut self) -> std::io::Result<()> {
        self.out.flush()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn text(value: f64, format: Format) -> String {
        let mut line = String::new();
        push_number(&mut line, value, format);
        line
    }

    #[test]
    fn numbers_print_as_their_format_says() {
        assert_eq!(text(0.5, Format::Fixed(4)), "0.5000");
        assert_eq!(text(f64::NAN, Format::Fixed(6)), "NaN");
        assert_eq!(text(3.0, Format::Shortest), "3");
        assert_eq!(text(-0.0, Format::Shortest), "0");
        assert_eq!(text(0.1, Format::Shortest), "0.1");
        assert_eq!(text(1e20, Format::Shortest), "100000000000000000000");
        assert_eq!(text(f64::INFINITY, Format::Shortest), "inf");
    }
}
