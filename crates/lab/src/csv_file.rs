//! The one CSV writer of the commands (`table1`, `fit-time`, `bench`, `chart`, `stability`),
//! on the `csv` crate.
//!
//! Every file has a header line naming its columns (documented in docs/paper.md,
//! docs/performance.md and each command's `--csv` help) and one record per line; a field that
//! holds a comma, a quote or a line break is quoted as RFC 4180 says (`"a ""b"", c"`), every
//! other field is written as is. Numbers are formatted by the caller, so each command keeps its
//! own precision per column. Read the files back with any CSV reader (`csv::Reader` in the tests),
//! never by splitting lines on commas.

use std::path::{Path, PathBuf};
use sublevel_core::{Error, Result};

/// A CSV file being written: header first, then [`CsvFile::record`] per line, then
/// [`CsvFile::finish`].
pub struct CsvFile {
    /// The `csv` crate's writer over the created file (buffered; flushed by `finish`).
    writer: csv::Writer<std::fs::File>,
    /// Where the file is, for messages.
    path: PathBuf,
}

/// A `csv` crate error as the crate's [`Error::Io`] (the writer only fails on I/O).
fn csv_error(e: csv::Error) -> Error {
    Error::Io(e.into())
}

impl CsvFile {
    /// Creates `path` (and its missing parent folders) and writes the `header` record.
    ///
    /// # Errors
    /// [`Error::Io`] when the folder or the file cannot be created or written.
    pub fn create(path: &Path, header: &[&str]) -> Result<Self> {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir)?;
        }
        let mut writer = csv::Writer::from_path(path).map_err(csv_error)?;
        writer.write_record(header).map_err(csv_error)?;
        Ok(Self { writer, path: path.to_path_buf() })
    }

    /// Writes one record; its fields are quoted only when they need it.
    ///
    /// # Errors
    /// [`Error::Io`] when the write fails.
    pub fn record<I, T>(&mut self, fields: I) -> Result<()>
    where
        I: IntoIterator<Item = T>,
        T: AsRef<[u8]>,
    {
        self.writer.write_record(fields).map_err(csv_error)
    }

    /// Flushes the file to disk and returns its path.
    ///
    /// # Errors
    /// [`Error::Io`] when the flush fails.
    pub fn finish(mut self) -> Result<PathBuf> {
        self.writer.flush()?;
        Ok(self.path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Fields with commas and quotes round-trip through the `csv` reader; plain fields are not
    /// quoted.
    #[test]
    fn fields_round_trip_and_plain_fields_stay_plain() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sub/t.csv");
        let mut f = CsvFile::create(&path, &["a", "b", "c"]).unwrap();
        f.record(["1.5", "x, \"y\"", ""]).unwrap();
        assert_eq!(f.finish().unwrap(), path);
        let text = std::fs::read_to_string(&path).unwrap();
        assert_eq!(text, "a,b,c\n1.5,\"x, \"\"y\"\"\",\n");
        let mut reader = csv::Reader::from_path(&path).unwrap();
        let headers = reader.headers().unwrap().clone();
        assert_eq!(headers.iter().collect::<Vec<_>>(), ["a", "b", "c"]);
        let rows: Vec<csv::StringRecord> = reader.records().map(|r| r.unwrap()).collect();
        assert_eq!(rows.len(), 1);
        assert_eq!(rows[0].iter().collect::<Vec<_>>(), ["1.5", "x, \"y\"", ""]);
    }
}
