//! Output to stdout or to a file that appears only when complete.

use crate::Failure;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// Runs `body` on a buffered writer to `path` (or stdout).
///
/// A regular file (new, or existing, also behind a symlink) is written to a temporary file
/// `.NAME.partial-XXXXXX` beside it and renamed into place only when `body` and the flush
/// succeed, keeping an existing file's permissions (a new file gets 0644); a failed run leaves
/// nothing behind, and a run killed mid-write leaves only that recognisable partial file.
/// Anything else that exists at `path` (a device such as /dev/null, a FIFO) is written to
/// directly.
pub fn write_csv<F>(path: Option<&Path>, body: F) -> Result<(), Failure>
where
    F: FnOnce(&mut dyn Write) -> Result<(), Failure>,
{
    let io_fail = |what: &str, e: std::io::Error| Failure {
        code: 1,
        message: format!("{what}: {e}"),
    };
    let Some(path) = path else {
        let stdout = std::io::stdout();
        let mut w = BufWriter::new(stdout.lock());
        body(&mut w)?;
        return w.flush().map_err(|e| io_fail("stdout", e));
    };
    let shown = path.display().to_string();
    let existing = std::fs::metadata(path).ok();
    if let Some(meta) = &existing {
        if !meta.is_file() {
            // A device or a FIFO: no rename, write in place.
            let f = std::fs::OpenOptions::new()
                .write(true)
                .open(path)
                .map_err(|e| io_fail(&shown, e))?;
            let mut w = BufWriter::new(f);
            body(&mut w)?;
            return w.flush().map_err(|e| io_fail(&shown, e));
        }
    }
    // The real file behind any symlink, so the link survives.
    let target: PathBuf = match existing {
        Some(_) => std::fs::canonicalize(path).map_err(|e| io_fail(&shown, e))?,
        None => path.to_path_buf(),
    };
    let dir = match target.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let name = target
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = tempfile::Builder::new()
        .prefix(&format!(".{name}.partial-"))
        .tempfile_in(dir)
        .map_err(|e| io_fail(&shown, e))?;
    let permissions = match &existing {
        Some(meta) => meta.permissions(),
        None => {
            use std::os::unix::fs::PermissionsExt;
            std::fs::Permissions::from_mode(0o644)
        }
    };
    std::fs::set_permissions(tmp.path(), permissions).map_err(|e| io_fail(&shown, e))?;
    let mut w = BufWriter::new(tmp);
    body(&mut w)?;
    let tmp = w
        .into_inner()
        .map_err(|e| io_fail(&shown, e.into_error()))?;
    tmp.persist(&target).map_err(|e| io_fail(&shown, e.error))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt;

    fn ok(w: &mut dyn Write) -> Result<(), Failure> {
        writeln!(w, "a,b").map_err(|e| Failure {
            code: 1,
            message: e.to_string(),
        })
    }

    #[test]
    fn symlinks_permissions_and_devices() {
        let dir = tempfile::tempdir().unwrap();
        let real = dir.path().join("real.csv");
        std::fs::write(&real, "old").unwrap();
        std::fs::set_permissions(&real, std::fs::Permissions::from_mode(0o640)).unwrap();
        let link = dir.path().join("link.csv");
        std::os::unix::fs::symlink(&real, &link).unwrap();
        write_csv(Some(&link), ok).unwrap();
        assert!(std::fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink());
        assert_eq!(std::fs::read_to_string(&real).unwrap(), "a,b\n");
        assert_eq!(
            std::fs::metadata(&real).unwrap().permissions().mode() & 0o777,
            0o640
        );
        let new = dir.path().join("new.csv");
        write_csv(Some(&new), ok).unwrap();
        assert_eq!(
            std::fs::metadata(&new).unwrap().permissions().mode() & 0o777,
            0o644
        );
        write_csv(Some(Path::new("/dev/null")), ok).unwrap();
        assert!(
            !std::fs::metadata("/dev/null").unwrap().is_file(),
            "still a device"
        );
        let fail = write_csv(Some(&dir.path().join("f.csv")), |_| {
            Err(Failure {
                code: 2,
                message: "bad".into(),
            })
        });
        assert!(fail.is_err());
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names.len(), 3, "{names:?}");
    }
}
