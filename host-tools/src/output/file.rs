//! Output files written whole or not at all, and output paths checked before a run.
//!
//! Every file `pe` and board-sim write (nodes CSVs, reports, ParaView frames, images,
//! manifests) goes through [`AtomicFile`] or [`write_atomic`]: the bytes go to a temporary
//! file beside the target (same directory, so the final rename is atomic on one file
//! system), which is renamed over the target only once complete. Two runs writing the same
//! file leave one of the two complete files, never a splice of both; a run that fails
//! leaves the previous file (or none), never a half-written one. [`check_file`] and
//! [`check_dir`] find a typo in an output path before a long run instead of after it.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use anyhow::{bail, Context, Result};

/// A distinct temporary name beside `path`: `.NAME.PID.N.tmp`.
fn temporary_beside(path: &Path) -> PathBuf {
    static NEXT: AtomicU64 = AtomicU64::new(0);
    let n = NEXT.fetch_add(1, Ordering::Relaxed);
    let name = path
        .file_name()
        .map(|f| f.to_string_lossy().into_owned())
        .unwrap_or_else(|| "output".into());
    path.with_file_name(format!(".{name}.{}.{n}.tmp", std::process::id()))
}

/// A file being written under a temporary name; [`AtomicFile::commit`] renames it to its
/// path. Dropped without a commit (an error on the way), the temporary is removed.
pub struct AtomicFile {
    path: PathBuf,
    temporary: PathBuf,
    file: Option<BufWriter<File>>,
}

impl AtomicFile {
    /// Starts writing `path` (under a temporary name in its directory).
    pub fn create(path: &Path) -> Result<AtomicFile> {
        let temporary = temporary_beside(path);
        let file = File::create(&temporary).with_context(|| {
            format!("creating {} (for {})", temporary.display(), path.display())
        })?;
        Ok(AtomicFile {
            path: path.to_path_buf(),
            temporary,
            file: Some(BufWriter::new(file)),
        })
    }

    /// Flushes the bytes and renames the file to its path (readers see the earlier file
    /// or this one, whole; no `fsync`: the aim is whole files, not durability at a power
    /// cut).
    pub fn commit(mut self) -> Result<()> {
        let context = || format!("writing {}", self.path.display());
        let file = self.file.take().context("the file was already committed")?;
        let file = file
            .into_inner()
            .map_err(|e| e.into_error())
            .with_context(context)?;
        drop(file);
        std::fs::rename(&self.temporary, &self.path).with_context(context)
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        match &mut self.file {
            Some(f) => f.write(buf),
            None => Err(std::io::Error::other("the file was already committed")),
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
            let _ = std::fs::remove_file(&self.temporary);
        }
    }
}

/// Writes `bytes` to `path` whole or not at all (see [`AtomicFile`]), with the error
/// naming the path.
pub fn write_atomic(path: &Path, bytes: impl AsRef<[u8]>) -> Result<()> {
    write_bytes(path, bytes.as_ref()).with_context(|| format!("writing {}", path.display()))
}

/// [`write_atomic`] with the bare I/O error (for writers with their own error type).
pub fn write_bytes(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let temporary = temporary_beside(path);
    let written =
        std::fs::write(&temporary, bytes).and_then(|()| std::fs::rename(&temporary, path));
    if written.is_err() {
        let _ = std::fs::remove_file(&temporary);
    }
    written
}

/// Checks, before a run, that `path` (given with `flag`, e.g. `--output-nodes`) can be
/// written: its directory exists and takes a new file, and the path is not a directory.
pub fn check_file(path: &Path, flag: &str) -> Result<()> {
    if path.is_dir() {
        bail!("{flag} {}: is a directory, not a file", path.display());
    }
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    if !dir.is_dir() {
        bail!(
            "{flag} {}: the directory {} does not exist",
            path.display(),
            dir.display()
        );
    }
    probe(dir).with_context(|| format!("{flag} {}: cannot write there", path.display()))
}

/// Checks, before a run, that `dir` (given with `flag`, e.g. `--vtk`) is or can be made a
/// directory that takes new files; creates it.
pub fn check_dir(dir: &Path, flag: &str) -> Result<()> {
    if dir.exists() && !dir.is_dir() {
        bail!("{flag} {}: is a file, not a directory", dir.display());
    }
    std::fs::create_dir_all(dir)
        .with_context(|| format!("{flag} {}: cannot create the directory", dir.display()))?;
    probe(dir).with_context(|| format!("{flag} {}: cannot write there", dir.display()))
}

/// Creates and removes a temporary file in `dir`.
fn probe(dir: &Path) -> Result<()> {
    let p = temporary_beside(&dir.join("probe"));
    File::create(&p).with_context(|| format!("creating {}", p.display()))?;
    std::fs::remove_file(&p).with_context(|| format!("removing {}", p.display()))
}

/// Removes from `dir` the files an earlier run left whose names this run's writer owns
/// (`owned(name)`), so a reused directory holds only this run's files; returns how many
/// were removed. Other files are left alone.
pub fn remove_owned(dir: &Path, owned: impl Fn(&str) -> bool) -> Result<usize> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Ok(0);
    };
    let mut removed = 0;
    for e in entries {
        let e = e.with_context(|| format!("listing {}", dir.display()))?;
        let name = e.file_name().to_string_lossy().into_owned();
        if e.file_type().is_ok_and(|t| t.is_file()) && owned(&name) {
            std::fs::remove_file(e.path())
                .with_context(|| format!("removing the earlier {}", e.path().display()))?;
            removed += 1;
        }
    }
    Ok(removed)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("pe-file-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// The target holds nothing until the commit, then all the bytes; a dropped file
    /// leaves the earlier content and no temporary behind.
    #[test]
    fn a_file_appears_whole_at_its_commit_or_not_at_all() {
        let d = dir("commit");
        let p = d.join("out.csv");
        std::fs::write(&p, "earlier\n").unwrap();
        let mut f = AtomicFile::create(&p).unwrap();
        f.write_all(&[b'x'; 100_000]).unwrap();
        assert_eq!(
            std::fs::read(&p).unwrap(),
            b"earlier\n",
            "not before the commit"
        );
        f.commit().unwrap();
        assert_eq!(std::fs::read(&p).unwrap().len(), 100_000);
        let mut g = AtomicFile::create(&p).unwrap();
        g.write_all(b"half").unwrap();
        drop(g);
        assert_eq!(
            std::fs::read(&p).unwrap().len(),
            100_000,
            "a dropped file changes nothing"
        );
        let left: Vec<_> = std::fs::read_dir(&d).unwrap().collect();
        assert_eq!(left.len(), 1, "no temporary left: {left:?}");
        let _ = std::fs::remove_dir_all(&d);
    }

    /// A missing directory, a directory given as a file and a file given as a directory
    /// are named before any work.
    #[test]
    fn bad_output_paths_are_named() {
        let d = dir("check");
        assert!(check_file(&d.join("a.csv"), "--output-nodes").is_ok());
        let e = check_file(&d.join("typo/a.csv"), "--output-nodes")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("--output-nodes") && e.contains("does not exist"),
            "{e}"
        );
        let e = check_file(&d, "--report").unwrap_err().to_string();
        assert!(e.contains("is a directory"), "{e}");
        std::fs::write(d.join("f"), "").unwrap();
        let e = check_dir(&d.join("f"), "--vtk").unwrap_err().to_string();
        assert!(e.contains("--vtk") && e.contains("is a file"), "{e}");
        assert!(check_dir(&d.join("new/frames"), "--vtk").is_ok());
        assert!(d.join("new/frames").is_dir());
        let _ = std::fs::remove_dir_all(&d);
    }
}
