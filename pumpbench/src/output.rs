//! Output to stdout or to a file that appears only when complete.

use crate::error::Failure;
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

/// A file named on the command line: the option that named it and its path.
pub type Named<'a> = (&'a str, &'a Path);

fn refuse(message: String) -> Failure {
    Failure { code: 2, message }
}

/// Device and inode of the file at `path` (behind any symlink), if it exists.
fn file_id(path: &Path) -> Option<(u64, u64)> {
    use std::os::unix::fs::MetadataExt;
    std::fs::metadata(path).ok().map(|m| (m.dev(), m.ino()))
}

/// Makes and removes an empty hidden file in `dir`: the only sure test that files can be made
/// there (permission bits say nothing to root, nor about read-only mounts or /proc).
fn probe(dir: &Path) -> std::io::Result<()> {
    let mut last = None;
    for k in 0..8 {
        let name = format!(".pumpbench-probe-{}-{k}", std::process::id());
        let path = dir.join(name);
        match std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&path)
        {
            Ok(f) => {
                drop(f);
                return std::fs::remove_file(&path);
            }
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => last = Some(e),
            Err(e) => return Err(e),
        }
    }
    Err(last.unwrap_or_else(|| std::io::Error::other("no free probe name")))
}

/// `dir` ("" is the current folder) exists, is a folder, and files can be made in it.
fn check_folder_writable(dir: &Path) -> Result<(), String> {
    let dir = if dir.as_os_str().is_empty() {
        Path::new(".")
    } else {
        dir
    };
    let shown = dir.display();
    match std::fs::metadata(dir) {
        Ok(meta) if meta.is_dir() => {
            probe(dir).map_err(|e| format!("its folder {shown} is not writable ({e})"))
        }
        Ok(_) => Err(format!("{shown} is not a folder")),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            Err(format!("its folder {shown} does not exist"))
        }
        Err(e) => Err(format!("its folder {shown}: {e}")),
    }
}

/// Whether [`write_csv`] can write `path`: a new file (or a dangling symlink) needs a
/// writable folder; an existing regular file too (the folder of the real file behind any
/// symlink: the new file is renamed over it); a device or FIFO must be writable itself; a
/// folder is refused.
fn check_writable(path: &Path) -> Result<(), String> {
    use std::os::unix::ffi::OsStrExt;
    if path.as_os_str().as_bytes().ends_with(b"/") {
        return Err("names a folder (ends with /): give a file name".into());
    }
    let parent = |p: &Path| p.parent().map(Path::to_path_buf).unwrap_or_default();
    match std::fs::metadata(path) {
        Ok(meta) if meta.is_dir() => Err("is a folder: give a file name".into()),
        Ok(meta) if meta.is_file() => {
            let real = std::fs::canonicalize(path).map_err(|e| e.to_string())?;
            check_folder_writable(&parent(&real))
        }
        Ok(_) => {
            use nix::unistd::{access, AccessFlags};
            access(path, AccessFlags::W_OK).map_err(|e| format!("not writable ({})", e.desc()))
        }
        Err(e) => {
            check_folder_writable(&parent(path))?;
            if e.kind() == std::io::ErrorKind::NotFound {
                Ok(())
            } else {
                Err(e.to_string())
            }
        }
    }
}

/// Refuses (exit code 2, one line) an output that is the same file as an input (the same
/// device and inode: another spelling of the path, a symlink or a hard link), so an input is
/// never replaced by an output. An output that does not exist yet is no input.
pub fn check_not_an_input(inputs: &[Named], outputs: &[Named]) -> Result<(), Failure> {
    for (out_option, out) in outputs {
        let Some(id) = file_id(out) else { continue };
        for (in_option, input) in inputs {
            if file_id(input) == Some(id) {
                return Err(refuse(format!(
                    "{out_option} {} is the same file as {in_option} {}: writing it would \
                     destroy the input; choose another output",
                    out.display(),
                    input.display()
                )));
            }
        }
    }
    Ok(())
}

/// Checks every output before any input is read or anything computed: it is none of the
/// inputs ([`check_not_an_input`]) and it can be written (its folder exists and is writable,
/// it is not a folder). Exit code 2 and one line naming the output otherwise.
pub fn check_outputs(inputs: &[Named], outputs: &[Named]) -> Result<(), Failure> {
    check_not_an_input(inputs, outputs)?;
    for (option, path) in outputs {
        check_writable(path).map_err(|m| {
            refuse(format!(
                "{option} {}: cannot be written: {m}",
                path.display()
            ))
        })?;
    }
    Ok(())
}

/// [`check_outputs`] for files `names` written into the folder `dir` (named by `option`),
/// which is created if missing: it must be a writable folder, or its nearest existing
/// ancestor must be.
pub fn check_outputs_in_folder(
    inputs: &[Named],
    option: &str,
    dir: &Path,
    names: &[&str],
) -> Result<(), Failure> {
    let shown = dir.display();
    let fail = |m: String| refuse(format!("{option} {shown}: cannot be written: {m}"));
    match std::fs::metadata(dir) {
        Ok(meta) if meta.is_dir() => check_folder_writable(dir).map_err(fail)?,
        Ok(_) => return Err(fail("it is not a folder".into())),
        Err(_) => {
            // Created with its missing parents: the nearest existing ancestor must take them.
            let existing = dir
                .ancestors()
                .skip(1)
                .find(|a| a.as_os_str().is_empty() || std::fs::symlink_metadata(a).is_ok())
                .unwrap_or(Path::new("."));
            return check_folder_writable(existing).map_err(|m| {
                refuse(format!(
                    "{option} {shown}: cannot create the folder: {}",
                    m.replacen("its folder", "folder", 1)
                ))
            });
        }
    }
    let paths: Vec<PathBuf> = names.iter().map(|n| dir.join(n)).collect();
    let outputs: Vec<Named> = paths.iter().map(|p| (option, p.as_path())).collect();
    check_outputs(inputs, &outputs)
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

    #[test]
    fn an_output_that_is_an_input_is_found_however_it_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let input = d.join("in.csv");
        std::fs::write(&input, "x").unwrap();
        std::os::unix::fs::symlink(&input, d.join("link.csv")).unwrap();
        std::fs::hard_link(&input, d.join("hard.csv")).unwrap();
        std::fs::create_dir(d.join("sub")).unwrap();
        let inputs = [("--input", input.as_path())];
        for same in [
            input.clone(),
            d.join("sub").join("..").join("in.csv"),
            d.join(".").join("in.csv"),
            d.join("link.csv"),
            d.join("hard.csv"),
        ] {
            let e = check_outputs(&inputs, &[("--output", &same)]).unwrap_err();
            assert_eq!(e.code, 2);
            assert!(
                e.message.contains("is the same file as --input"),
                "{}",
                e.message
            );
        }
        for other in [d.join("new.csv"), d.join("sub").join("in.csv")] {
            check_outputs(&inputs, &[("--output", &other)]).unwrap();
        }
        // A missing input is no output (reading it fails later, with its own message).
        check_outputs(
            &[("--input", &d.join("missing.csv"))],
            &[("--output", &d.join("missing2.csv"))],
        )
        .unwrap();
    }

    #[test]
    fn outputs_that_cannot_be_written_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let file = d.join("a_file");
        std::fs::write(&file, "").unwrap();
        let message = |p: &Path| {
            check_outputs(&[], &[("--output", p)])
                .unwrap_err()
                .message
                .replace(&d.display().to_string(), "D")
        };
        assert_eq!(
            message(&d.join("no").join("x.csv")),
            "--output D/no/x.csv: cannot be written: its folder D/no does not exist"
        );
        assert_eq!(
            message(&file.join("x.csv")),
            "--output D/a_file/x.csv: cannot be written: D/a_file is not a folder"
        );
        assert_eq!(
            message(d),
            "--output D: cannot be written: is a folder: give a file name"
        );
        assert_eq!(
            message(&d.join("new/")),
            "--output D/new/: cannot be written: names a folder (ends with /): give a file name"
        );
        // Files cannot be made in /proc, not even by root (whom permission bits do not stop).
        assert_eq!(
            message(Path::new("/proc/x.csv")),
            "--output /proc/x.csv: cannot be written: its folder /proc is not writable (No such \
             file or directory (os error 2))"
        );
        check_outputs(&[], &[("--output", &file)]).unwrap();
        check_outputs(&[], &[("--output", Path::new("/dev/null"))]).unwrap();
        check_outputs(&[], &[("--output", Path::new("relative-new.csv"))]).unwrap();
        // A folder of outputs: created if missing (with its parents), checked file by file.
        let names = ["m.json", "t.md"];
        check_outputs_in_folder(&[], "--out", &d.join("x").join("y"), &names).unwrap();
        let e = check_outputs_in_folder(&[], "--out", &file.join("y"), &names).unwrap_err();
        assert!(
            e.message.ends_with(
                "cannot create the folder: D/a_file is not a folder"
                    .replace('D', &d.display().to_string())
                    .as_str()
            ),
            "{}",
            e.message
        );
        std::fs::create_dir(d.join("t.md")).unwrap();
        let e = check_outputs_in_folder(&[], "--out", d, &names).unwrap_err();
        assert!(
            e.message
                .ends_with("t.md: cannot be written: is a folder: give a file name"),
            "{}",
            e.message
        );
        let e =
            check_outputs_in_folder(&[("--static", &file)], "--out", d, &["a_file"]).unwrap_err();
        assert!(
            e.message.contains("is the same file as --static"),
            "{}",
            e.message
        );
    }
}
