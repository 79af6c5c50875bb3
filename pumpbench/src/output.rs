//! Output to stdout or to a file that appears only when complete.

use crate::Failure;
use std::io::{BufWriter, Write};
use std::path::Path;

/// Runs `body` on a buffered writer to `path` (or stdout). A file is written to a temporary
/// file beside it and renamed into place only when `body` and the flush succeed.
pub fn write_csv<F>(path: Option<&Path>, body: F) -> Result<(), Failure>
where
    F: FnOnce(&mut dyn Write) -> Result<(), Failure>,
{
    let io_fail = |what: &str, e: std::io::Error| Failure {
        code: 1,
        message: format!("{what}: {e}"),
    };
    match path {
        None => {
            let stdout = std::io::stdout();
            let mut w = BufWriter::new(stdout.lock());
            body(&mut w)?;
            w.flush().map_err(|e| io_fail("stdout", e))
        }
        Some(path) => {
            let dir = match path.parent() {
                Some(d) if !d.as_os_str().is_empty() => d,
                _ => Path::new("."),
            };
            let shown = path.display().to_string();
            let tmp = tempfile::NamedTempFile::new_in(dir).map_err(|e| io_fail(&shown, e))?;
            let mut w = BufWriter::new(tmp);
            body(&mut w)?;
            let tmp = w
                .into_inner()
                .map_err(|e| io_fail(&shown, e.into_error()))?;
            tmp.persist(path).map_err(|e| io_fail(&shown, e.error))?;
            Ok(())
        }
    }
}
