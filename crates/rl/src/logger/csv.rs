//! A CSV log of the same scalars TensorBoard gets (SB3's `progress.csv`): one row per dump,
//! one column per tag; a tag first seen later rewrites the header (the file is small).

use std::collections::BTreeMap;
use std::io::{self, Write};
use std::path::{Path, PathBuf};

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
            let mut lines = text.lines();
            if let Some(header) = lines.next() {
                logger.columns = header.split(',').map(str::to_string).collect();
                for line in lines {
                    let row = logger
                        .columns
                        .iter()
                        .zip(line.split(','))
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
        let line = self.format_row(&row);
        self.rows.push(row);
        if new_column || self.rows.len() == 1 {
            self.rewrite()
        } else {
            let mut file = std::fs::OpenOptions::new().append(true).open(&self.path)?;
            writeln!(file, "{line}")
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

    fn format_row(&self, row: &BTreeMap<String, f64>) -> String {
        self.columns
            .iter()
            .map(|c| row.get(c).map(|v| format!("{v}")).unwrap_or_default())
            .collect::<Vec<_>>()
            .join(",")
    }

    fn rewrite(&self) -> io::Result<()> {
        let mut text = self.columns.join(",");
        text.push('\n');
        for row in &self.rows {
            text.push_str(&self.format_row(row));
            text.push('\n');
        }
        crate::save_util::write_atomic(&self.path, text.as_bytes())
    }

    pub fn path(&self) -> &Path {
        &self.path
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
}
