//! A CSV log of the same scalars TensorBoard gets (SB3's `progress.csv`): one row per dump,
//! one column per tag; a tag first seen later rewrites the header (the file is small).
//! [`ProgressLog`] reads such a file back, strictly (for plotting and benchmarks). Both go
//! through the `csv` crate, so a tag with a comma or a quote in it is quoted, as pandas and
//! SB3's reader expect.

use std::collections::BTreeMap;
use std::io::{self, Write};
use std::path::{Path, PathBuf};

/// One CSV record (no line end quirks: `\n` terminators, fields quoted only where needed).
fn record<I: IntoIterator<Item = T>, T: AsRef<[u8]>>(fields: I) -> io::Result<Vec<u8>> {
    let mut writer = csv::WriterBuilder::new()
        .terminator(csv::Terminator::Any(b'\n'))
        .from_writer(Vec::new());
    writer.write_record(fields).map_err(io::Error::other)?;
    writer
        .into_inner()
        .map_err(|e| io::Error::other(e.to_string()))
}

/// The records of a CSV text, each with its line number, lengths left to the caller.
fn records(text: &str) -> impl Iterator<Item = (usize, Result<csv::StringRecord, csv::Error>)> {
    csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .from_reader(text.as_bytes())
        .into_records()
        .map(|r| {
            let line = match &r {
                Ok(record) => record.position().map_or(0, |p| p.line() as usize),
                Err(e) => e.position().map_or(0, |p| p.line() as usize),
            };
            (line, r)
        })
}

/// Writes a run's `progress.csv`, keeping its rows in memory to rewrite the file when a
/// column is added.
pub struct CsvLogger {
    path: PathBuf,
    columns: Vec<String>,
    rows: Vec<BTreeMap<String, f64>>,
}

impl CsvLogger {
    /// Starts (or, when resuming, continues) `progress.csv` in `dir`.
    pub fn open(dir: &Path) -> io::Result<Self> {
        std::fs::create_dir_all(dir)?;
        let path = dir.join("progress.csv");
        let mut logger = Self {
            path,
            columns: Vec::new(),
            rows: Vec::new(),
        };
        if let Ok(text) = std::fs::read_to_string(&logger.path) {
            let mut rows = records(&text).filter_map(|(_, r)| r.ok());
            if let Some(header) = rows.next() {
                logger.columns = header.iter().map(str::to_string).collect();
                for cells in rows {
                    let row = (logger.columns.iter())
                        .zip(cells.iter())
                        .filter_map(|(c, v)| v.parse::<f64>().ok().map(|v| (c.clone(), v)))
                        .collect();
                    logger.rows.push(row);
                }
            }
        }
        Ok(logger)
    }

    /// Appends a row.
    pub fn write_row(&mut self, values: &[(&str, f64)]) -> io::Result<()> {
        let mut new_column = false;
        for (tag, _) in values {
            if !self.columns.iter().any(|c| c == tag) {
                self.columns.push(tag.to_string());
                new_column = true;
            }
        }
        let row: BTreeMap<String, f64> = values.iter().map(|(k, v)| (k.to_string(), *v)).collect();
        let line = self.format_row(&row)?;
        self.rows.push(row);
        if new_column || self.rows.len() == 1 {
            self.rewrite()
        } else {
            let mut file = std::fs::OpenOptions::new().append(true).open(&self.path)?;
            file.write_all(&line)
        }
    }

    /// Drops the rows whose `column` is above `value` (a resumed run discards what the
    /// interrupted attempt logged after its last checkpoint).
    pub fn truncate_after(&mut self, column: &str, value: f64) -> io::Result<()> {
        let before = self.rows.len();
        self.rows
            .retain(|row| row.get(column).is_none_or(|v| *v <= value));
        if self.rows.len() != before {
            self.rewrite()?;
        }
        Ok(())
    }

    fn format_row(&self, row: &BTreeMap<String, f64>) -> io::Result<Vec<u8>> {
        record(
            (self.columns.iter()).map(|c| row.get(c).map(|v| format!("{v}")).unwrap_or_default()),
        )
    }

    fn rewrite(&self) -> io::Result<()> {
        let mut text = record(&self.columns)?;
        for row in &self.rows {
            text.extend(self.format_row(row)?);
        }
        fairgrasp_env::atomic::write(&self.path, &text)
    }

    /// The file written.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

/// A `progress.csv` read back: its columns and, per row, each column's value (`None` where the
/// cell is empty, as it is for every tag not logged in that row).
#[derive(Clone, Debug, PartialEq)]
pub struct ProgressLog {
    /// The header's column names (the tags), in file order.
    pub columns: Vec<String>,
    /// One entry per column in each row.
    pub rows: Vec<Vec<Option<f64>>>,
}

/// Why a `progress.csv` cannot be read; each names the file and, where it applies, the line.
#[derive(Debug, thiserror::Error)]
pub enum ProgressError {
    /// The file cannot be read.
    #[error("cannot read {}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: io::Error,
    },
    /// The file has no header line.
    #[error("{}: empty file (no header line)", path.display())]
    Empty {
        /// The file.
        path: PathBuf,
    },
    /// A line that does not parse: a bad header, a wrong number of cells, a non-number.
    #[error("{}:{line}: {problem}", path.display())]
    Garbled {
        /// The file.
        path: PathBuf,
        /// The line's number (1-based).
        line: usize,
        /// What is wrong with it.
        problem: String,
    },
}

impl ProgressLog {
    /// Reads `path` (a run directory's `progress.csv`).
    pub fn read(path: &Path) -> Result<Self, ProgressError> {
        let text = std::fs::read_to_string(path).map_err(|source| ProgressError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::parse(&text, path)
    }

    /// Parses the text of a `progress.csv`; `path` only names the file in errors.
    pub fn parse(text: &str, path: &Path) -> Result<Self, ProgressError> {
        let garbled = |line: usize, problem: String| ProgressError::Garbled {
            path: path.to_path_buf(),
            line,
            problem,
        };
        let mut lines = records(text).filter(|(_, r)| {
            // A blank line reads as one empty field.
            !matches!(r, Ok(rec) if rec.len() == 1 && rec[0].trim().is_empty())
        });
        let (header_line, header) = lines.next().ok_or_else(|| ProgressError::Empty {
            path: path.to_path_buf(),
        })?;
        let header = header.map_err(|e| garbled(header_line, e.to_string()))?;
        let columns: Vec<String> = header.iter().map(|c| c.trim().to_string()).collect();
        for (i, name) in columns.iter().enumerate() {
            if name.is_empty() {
                return Err(garbled(
                    header_line,
                    format!("column {} has no name", i + 1),
                ));
            }
            if columns[..i].contains(name) {
                return Err(garbled(
                    header_line,
                    format!("column `{name}` appears twice"),
                ));
            }
        }
        // The logger appends while a run trains: a last line without its newline may be a row
        // still being written, so it is dropped rather than reported.
        let unfinished_tail = !text.ends_with('\n');
        let last_line = text.lines().count();
        let mut rows = Vec::new();
        for (number, record) in lines {
            let row = record
                .map_err(|e| e.to_string())
                .and_then(|cells| Self::parse_row(&cells, &columns));
            match row {
                Ok(row) => rows.push(row),
                Err(_) if unfinished_tail && number == last_line => {}
                Err(problem) => return Err(garbled(number, problem)),
            }
        }
        Ok(Self { columns, rows })
    }

    fn parse_row(
        cells: &csv::StringRecord,
        columns: &[String],
    ) -> Result<Vec<Option<f64>>, String> {
        if cells.len() != columns.len() {
            return Err(format!(
                "{} cells, but the header has {} columns",
                cells.len(),
                columns.len()
            ));
        }
        cells
            .iter()
            .zip(columns)
            .map(|(cell, column)| {
                let cell = cell.trim();
                if cell.is_empty() {
                    return Ok(None);
                }
                cell.parse::<f64>()
                    .map(Some)
                    .map_err(|_| format!("`{cell}` in column `{column}` is not a number"))
            })
            .collect()
    }

    /// The index of the column named `name`.
    pub fn column(&self, name: &str) -> Option<usize> {
        self.columns.iter().position(|c| c == name)
    }

    /// The values of column `name`, one per row (all `None` if there is no such column).
    pub fn values<'a>(&'a self, name: &str) -> impl Iterator<Item = Option<f64>> + use<'a> {
        let index = self.column(name);
        self.rows.iter().map(move |row| index.and_then(|i| row[i]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_with_new_columns_keep_earlier_rows_aligned() {
        let dir = tempfile::tempdir().unwrap();
        let mut log = CsvLogger::open(dir.path()).unwrap();
        log.write_row(&[
            ("time/total_timesteps", 100.0),
            ("rollout/ep_rew_mean", 1.5),
        ])
        .unwrap();
        log.write_row(&[("time/total_timesteps", 200.0), ("eval/success_rate", 0.5)])
            .unwrap();
        log.write_row(&[
            ("time/total_timesteps", 300.0),
            ("rollout/ep_rew_mean", 2.0),
        ])
        .unwrap();
        let text = std::fs::read_to_string(log.path()).unwrap();
        assert_eq!(
            text,
            "time/total_timesteps,rollout/ep_rew_mean,eval/success_rate\n100,1.5,\n200,,0.5\n300,2,\n"
        );
        // Reopening (resume) keeps the rows.
        let mut again = CsvLogger::open(dir.path()).unwrap();
        again.write_row(&[("time/total_timesteps", 400.0)]).unwrap();
        assert!(
            std::fs::read_to_string(again.path())
                .unwrap()
                .ends_with("300,2,\n400,,\n")
        );
    }

    #[test]
    fn tags_with_commas_and_quotes_are_quoted_and_read_back() {
        let dir = tempfile::tempdir().unwrap();
        let mut log = CsvLogger::open(dir.path()).unwrap();
        let odd = "eval/extras/a,b \"c\"";
        log.write_row(&[("time/total_timesteps", 1.0), (odd, 0.5)])
            .unwrap();
        log.write_row(&[("time/total_timesteps", 2.0), (odd, 0.25)])
            .unwrap();
        let text = std::fs::read_to_string(log.path()).unwrap();
        assert_eq!(
            text,
            "time/total_timesteps,\"eval/extras/a,b \"\"c\"\"\"\n1,0.5\n2,0.25\n"
        );
        let read = ProgressLog::read(log.path()).unwrap();
        assert_eq!(read.columns, ["time/total_timesteps", odd]);
        assert_eq!(
            read.values(odd).collect::<Vec<_>>(),
            [Some(0.5), Some(0.25)]
        );
        let again = CsvLogger::open(dir.path()).unwrap();
        assert_eq!(again.columns, ["time/total_timesteps", odd]);
        assert_eq!(again.rows.len(), 2);
    }

    #[test]
    fn a_progress_log_reads_back_with_empty_cells_as_none() {
        let text = "time/total_timesteps,rollout/ep_rew_mean,eval/success_rate\n\
                    100,1.5,\n200,,0.5\n300,2,\n";
        let log = ProgressLog::parse(text, Path::new("p.csv")).unwrap();
        assert_eq!(log.rows.len(), 3);
        assert_eq!(
            log.values("eval/success_rate").collect::<Vec<_>>(),
            [None, Some(0.5), None]
        );
        assert_eq!(
            log.values("rollout/ep_rew_mean").collect::<Vec<_>>(),
            [Some(1.5), None, Some(2.0)]
        );
        assert!(log.values("missing").all(|v| v.is_none()));
    }

    #[test]
    fn garbled_progress_names_the_file_and_line() {
        let path = Path::new("runs/x/progress.csv");
        let err = ProgressLog::parse("a,b\n1,2\n3,oops\n", path).unwrap_err();
        assert_eq!(
            err.to_string(),
            "runs/x/progress.csv:3: `oops` in column `b` is not a number"
        );
        let err = ProgressLog::parse("a,b\n1,2,3\n4,5\n", path).unwrap_err();
        assert!(
            err.to_string()
                .starts_with("runs/x/progress.csv:2: 3 cells"),
            "{err}"
        );
        let err = ProgressLog::parse("a,a\n", path).unwrap_err();
        assert!(
            err.to_string().contains(":1: column `a` appears twice"),
            "{err}"
        );
        let err = ProgressLog::parse("\n", path).unwrap_err();
        assert!(matches!(err, ProgressError::Empty { .. }), "{err}");
        let err = ProgressLog::read(Path::new("/nonexistent/progress.csv")).unwrap_err();
        assert!(
            err.to_string()
                .starts_with("cannot read /nonexistent/progress.csv")
        );
    }

    #[test]
    fn a_row_still_being_written_is_dropped() {
        let log = ProgressLog::parse("a,b\n1,2\n3,", Path::new("p.csv")).unwrap();
        assert_eq!(
            log.rows,
            [vec![Some(1.0), Some(2.0)], vec![Some(3.0), None]]
        );
        let log = ProgressLog::parse("a,b\n1,2\n3", Path::new("p.csv")).unwrap();
        assert_eq!(log.rows, [vec![Some(1.0), Some(2.0)]]);
    }
}
