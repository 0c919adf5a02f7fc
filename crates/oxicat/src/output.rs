//! Where a verb's output goes. `-` (or no `-o`) is standard output, as for other Unix tools;
//! a file is written to a temporary file in the same directory and renamed over the target
//! only when it is complete, so a verb that fails (bad arguments, a slave that stops
//! answering, Ctrl-C) never leaves a user's file empty or half written.

use std::io::Write;
use std::path::{Path, PathBuf};

use oxicat_master::MasterError;

use crate::{CliError, UsageError};

/// Whether `path` means standard output (`-`).
pub fn is_stdout(path: &Path) -> bool {
    path.as_os_str() == "-"
}

/// A file being written: a temporary file beside `dest`, renamed over it by
/// [`AtomicFile::commit`]; dropped without commit, the temporary file is removed and `dest`
/// is untouched.
pub struct AtomicFile {
    dest: PathBuf,
    tmp: PathBuf,
    file: Option<std::io::BufWriter<std::fs::File>>,
}

impl AtomicFile {
    /// Creates the temporary file for `dest` (in `dest`'s directory, so the rename stays on
    /// one file system).
    pub fn create(dest: &Path) -> Result<Self, CliError> {
        let name = dest
            .file_name()
            .ok_or_else(|| UsageError::NotAFileName(dest.to_path_buf()))?;
        let dir = match dest.parent() {
            Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let mut tmp_name = std::ffi::OsString::from(".");
        tmp_name.push(name);
        tmp_name.push(format!(".oxicat-{}.tmp", std::process::id()));
        let tmp = dir.join(tmp_name);
        let file = std::fs::OpenOptions::new()
            .write(true)
            .create(true)
            .truncate(true)
            .open(&tmp)
            .map_err(|e| MasterError::File(dest.to_path_buf(), e))?;
        Ok(Self {
            dest: dest.to_path_buf(),
            tmp,
            file: Some(std::io::BufWriter::new(file)),
        })
    }

    /// The file the output ends up in.
    pub fn dest(&self) -> &Path {
        &self.dest
    }

    /// Flushes the temporary file and renames it over the target.
    pub fn commit(mut self) -> Result<(), MasterError> {
        let err = |e| MasterError::File(self.dest.clone(), e);
        if let Some(f) = self.file.take() {
            let f = f.into_inner().map_err(|e| err(e.into_error()))?;
            f.sync_all().map_err(err)?;
        }
        std::fs::rename(&self.tmp, &self.dest).map_err(err)
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        match &mut self.file {
            Some(f) => f.write(buf),
            None => Err(std::io::Error::other("file already committed")),
        }
    }

    fn flush(&mut self) -> std::io::Result<()> {
        match &mut self.file {
            Some(f) => f.flush(),
            None => Ok(()),
        }
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if self.file.take().is_some() {
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

/// Writes `bytes` to `dest` through a temporary file (see [`AtomicFile`]); `-` is standard
/// output.
pub fn write_file(dest: &Path, bytes: &[u8]) -> Result<(), CliError> {
    if is_stdout(dest) {
        return Ok(write_stdout(&mut std::io::stdout().lock(), bytes)?);
    }
    let mut f = AtomicFile::create(dest)?;
    f.write_all(bytes)
        .map_err(|e| MasterError::File(dest.to_path_buf(), e))?;
    Ok(f.commit()?)
}

/// Writes `bytes` to the file `output` (see [`write_file`]) or, without one or for `-`, to
/// `out`.
pub fn write_output(
    output: Option<&Path>,
    bytes: &[u8],
    out: &mut dyn Write,
) -> Result<(), CliError> {
    match output {
        Some(p) if !is_stdout(p) => write_file(p, bytes),
        _ => Ok(write_stdout(out, bytes)?),
    }
}

fn write_stdout(out: &mut dyn Write, bytes: &[u8]) -> Result<(), MasterError> {
    out.write_all(bytes)
        .and_then(|()| out.flush())
        .map_err(MasterError::Output)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("oxicat-output-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).expect("temp dir");
        d
    }

    #[test]
    fn an_uncommitted_file_leaves_the_old_one_and_no_temporary() {
        let d = dir("drop");
        let keep = d.join("keep.csv");
        std::fs::write(&keep, "old data\n").expect("write");
        {
            let mut f = AtomicFile::create(&keep).expect("create");
            f.write_all(b"half").expect("write");
        }
        assert_eq!(std::fs::read_to_string(&keep).expect("read"), "old data\n");
        assert_eq!(std::fs::read_dir(&d).expect("dir").count(), 1);
        write_file(&keep, b"new data\n").expect("write_file");
        assert_eq!(std::fs::read_to_string(&keep).expect("read"), "new data\n");
        assert_eq!(std::fs::read_dir(&d).expect("dir").count(), 1);
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn dash_is_standard_output() {
        let mut out = Vec::new();
        write_output(Some(Path::new("-")), b"to stdout", &mut out).expect("write");
        assert_eq!(out, b"to stdout");
        assert!(!Path::new("-").exists());
    }

    #[test]
    fn an_unwritable_place_names_the_path() {
        let e = write_file(Path::new("/nonexistent-dir/x.csv"), b"x").expect_err("no dir");
        assert!(e.to_string().contains("/nonexistent-dir/x.csv"), "{e}");
    }
}

/// Recording format of the experiments (`--format`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// CSV only.
    Csv,
    /// Apache Parquet only.
    Parquet,
    /// Both.
    Both,
}

impl Format {
    /// Whether the CSV is written.
    pub fn csv(self) -> bool {
        matches!(self, Format::Csv | Format::Both)
    }

    /// Whether the Parquet file is written.
    pub fn parquet(self) -> bool {
        matches!(self, Format::Parquet | Format::Both)
    }
}

/// Writes a recording (`csv`: the CSV text, header first) as `<dir>/<stem>.csv` and/or
/// `<dir>/<stem>.parquet` per `format`; returns the paths written.
pub fn write_recording(
    dir: &Path,
    stem: &str,
    csv: &str,
    format: Format,
) -> Result<Vec<std::path::PathBuf>, CliError> {
    let mut files = Vec::new();
    if format.csv() {
        let p = dir.join(format!("{stem}.csv"));
        write_file(&p, csv.as_bytes())?;
        files.push(p);
    }
    if format.parquet() {
        let p = dir.join(format!("{stem}.parquet"));
        crate::parquet_out::csv_to_parquet(csv, &p)?;
        files.push(p);
    }
    Ok(files)
}

/// `s` as a JSON string literal (quotes, backslashes and control characters escaped).
pub fn json_string(s: &str) -> String {
    let mut o = String::from("\"");
    for c in s.chars() {
        match c {
            '"' => o.push_str("\\\""),
            '\\' => o.push_str("\\\\"),
            c if (c as u32) < 0x20 => o.push_str(&format!("\\u{:04x}", c as u32)),
            c => o.push(c),
        }
    }
    o.push('"');
    o
}
