//! A hand wrench replayed from a CSV file, linearly interpolated in time and held after the last row.
//!
//! The file has a header; the time column is `time_s` (or `t`), the wrench columns are the wrench axis names
//! with or without a `hand_` prefix (`hand_fx,hand_fy,hand_tz` planar; `fx,fy,fz,tx,ty,tz` spatial). A file
//! written by `kinloop-client --record` has these columns, so a recorded session replays as is.

use std::path::{Path, PathBuf};
use std::time::Duration;

use kinloop_linkage::math::space::{Space, VecOps};

use super::SimulatedUser;
use crate::axes::wrench_names;
use crate::device::DeviceState;

/// Why a replay file could not be used.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// The file could not be read.
    #[error("cannot read replay file {file}: {source}")]
    Read {
        /// The file.
        file: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A column is missing from the header.
    #[error("replay file {file}: no column {column:?} (header: {header})")]
    MissingColumn {
        /// The file.
        file: PathBuf,
        /// Which column.
        column: String,
        /// The header found.
        header: String,
    },
    /// A row does not parse.
    #[error("replay file {file}, line {line}: {what}")]
    BadRow {
        /// The file.
        file: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        what: String,
    },
    /// The file has a header and no rows.
    #[error("replay file {file} has no samples")]
    Empty {
        /// The file.
        file: PathBuf,
    },
}

/// A recorded wrench played back.
#[derive(Clone, Debug)]
pub struct ReplayedWrench<S: Space> {
    samples: Vec<(f64, S::OpVec)>,
    cursor: usize,
}

impl<S: Space> ReplayedWrench<S> {
    /// Reads and checks the whole file.
    pub fn load(file: &Path) -> Result<Self, ReplayError> {
        let text = std::fs::read_to_string(file).map_err(|source| ReplayError::Read { file: file.into(), source })?;
        Self::parse(&text, file)
    }

    /// Parses CSV text (`file` names it in errors).
    pub fn parse(text: &str, file: &Path) -> Result<Self, ReplayError> {
        let mut lines = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty());
        let header_line = lines.next().map(|(_, l)| l).unwrap_or("");
        let header: Vec<&str> = header_line.split(',').map(str::trim).collect();
        let find = |names: &[&str]| header.iter().position(|h| names.contains(h));
        let missing = |column: &str| ReplayError::MissingColumn {
            file: file.into(),
            column: column.into(),
            header: header_line.into(),
        };
        let time_column = find(&["time_s", "t"]).ok_or_else(|| missing("time_s"))?;
        let mut wrench_columns = [0usize; 6];
        for (i, name) in wrench_names(S::KIND).iter().enumerate() {
            let prefixed = format!("hand_{name}");
            wrench_columns[i] = find(&[prefixed.as_str(), name]).ok_or_else(|| missing(&prefixed))?;
        }
        let mut samples = Vec::new();
        for (index, line) in lines {
            let bad = |what: String| ReplayError::BadRow { file: file.into(), line: index + 1, what };
            let cells: Vec<&str> = line.split(',').map(str::trim).collect();
            let number = |c: usize| -> Result<f64, ReplayError> {
                let cell =
                    cells.get(c).ok_or_else(|| bad(format!("has {} cells, expected column {}", cells.len(), c + 1)))?;
                cell.parse::<f64>()
                    .ok()
                    .filter(|x| x.is_finite())
                    .ok_or_else(|| bad(format!("{cell:?} is not a finite number")))
            };
            let t = number(time_column)?;
            if samples.last().is_some_and(|(last, _)| t < *last) {
                return Err(bad(format!("time {t} goes backwards")));
            }
            let mut w = S::OpVec::zero();
            for i in 0..S::DIM {
                w[i] = number(wrench_columns[i])?;
            }
            samples.push((t, w));
        }
        if samples.is_empty() {
            return Err(ReplayError::Empty { file: file.into() });
        }
        Ok(ReplayedWrench { samples, cursor: 0 })
    }

    /// The wrench at `t_s`: interpolated between samples, held before the first and after the last.
    pub fn at(&mut self, t_s: f64) -> S::OpVec {
        if self.cursor > 0 && t_s < self.samples[self.cursor].0 {
            self.cursor = 0;
        }
        while self.cursor + 1 < self.samples.len() && self.samples[self.cursor + 1].0 <= t_s {
            self.cursor += 1;
        }
        let (t0, w0) = self.samples[self.cursor];
        match self.samples.get(self.cursor + 1) {
            Some((t1, w1)) if t_s > t0 && t1 > &t0 => w0 + (*w1 - w0) * ((t_s - t0) / (t1 - t0)),
            _ => w0,
        }
    }
}

impl<S: Space> SimulatedUser<S> for ReplayedWrench<S> {
    fn wrench(&mut self, now: Duration, _device: &DeviceState<S>) -> S::OpVec {
        self.at(now.as_secs_f64())
    }
}
