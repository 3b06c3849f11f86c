//! Output files written whole or not at all.
//!
//! Each file is written to a temporary file beside it (same directory, so the rename stays on
//! one file system), flushed, and renamed over the target only once complete. A run that fails
//! part-way (a full disk, a write error) leaves the target as it was: absent, or the previous
//! run's file. It never leaves a truncated CSV that a later `hter monitor` or `hter report`
//! would read as a shorter record, or a cut plot. The commands' error line names the target, as
//! before.

use anyhow::{Context, Result};
use std::path::{Path, PathBuf};

/// Writes `bytes` to `path`, whole or not at all.
pub fn write(path: &Path, bytes: &[u8]) -> Result<()> {
    write_with(path, |tmp| std::fs::write(tmp, bytes).with_context(|| format!("cannot write '{}'", path.display())))
}

/// Runs `fill` on a temporary path beside `path` (its name ends in `path`'s extension, for
/// writers that choose the format by it) and renames the result over `path` once `fill`
/// succeeded; on any error the temporary is removed and `path` is left as it was. `fill`'s
/// error is returned as it is (it names the target, as the caller's messages do).
///
/// The rename goes onto what `path` names: a symbolic link's target (renamed over, the link
/// itself would become a plain file), and a device, pipe or directory is written in place
/// (`--output /dev/stdout`: no rename can stand in for it, and none would be wanted).
pub fn write_with(path: &Path, fill: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
    let target = std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf());
    if std::fs::metadata(&target).is_ok_and(|m| !m.is_file()) {
        return fill(&target);
    }
    let tmp = temp_beside(&target);
    let result = fill(&tmp).and_then(|()| {
        std::fs::File::open(&tmp)
            .and_then(|f| f.sync_all())
            .and_then(|()| std::fs::rename(&tmp, &target))
            .with_context(|| format!("cannot write '{}'", path.display()))
    });
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// `dir/.name.PID.tmp.ext` for `dir/name.ext`: hidden, this process's own, and with the
/// target's extension last.
fn temp_beside(path: &Path) -> PathBuf {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let ext = path.extension().map(|e| format!(".{}", e.to_string_lossy())).unwrap_or_default();
    path.with_file_name(format!(".{name}.{}.tmp{ext}", std::process::id()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("hter-output-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn entries(d: &Path) -> Vec<String> {
        let mut v: Vec<String> =
            std::fs::read_dir(d).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
        v.sort();
        v
    }

    #[test]
    fn a_write_that_fails_part_way_leaves_the_target_as_it_was_and_no_temporary() {
        let d = dir("fail");
        let target = d.join("trace.csv");
        let half = |tmp: &Path| -> Result<()> {
            std::fs::write(tmp, "t_s,temp_c\n0,4.0\n")?;
            anyhow::bail!("cannot write '{}': no space left on device", target.display())
        };
        // No file before: none after.
        let e = write_with(&target, half).unwrap_err();
        assert_eq!(format!("{e:#}"), format!("cannot write '{}': no space left on device", target.display()));
        assert!(entries(&d).is_empty(), "{:?}", entries(&d));
        // The previous run's file: kept whole.
        write(&target, b"t_s,temp_c\n0,4.0\n10,4.1\n").unwrap();
        assert!(write_with(&target, half).is_err());
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "t_s,temp_c\n0,4.0\n10,4.1\n");
        assert_eq!(entries(&d), ["trace.csv"]);
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_complete_write_replaces_the_target_and_the_temporary_keeps_its_extension() {
        let d = dir("ok");
        let target = d.join("run.png");
        write(&target, b"old").unwrap();
        write_with(&target, |tmp| {
            assert!(tmp.extension().is_some_and(|e| e == "png"), "{}", tmp.display());
            assert_eq!(tmp.parent(), target.parent());
            Ok(std::fs::write(tmp, b"new")?)
        })
        .unwrap();
        assert_eq!(std::fs::read(&target).unwrap(), b"new");
        assert_eq!(entries(&d), ["run.png"]);
        // Through a symbolic link: the link stays a link, its target gets the new text.
        let link = d.join("latest.png");
        std::os::unix::fs::symlink(&target, &link).unwrap();
        write(&link, b"newer").unwrap();
        assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
        assert_eq!(std::fs::read(&target).unwrap(), b"newer");
        std::fs::remove_file(&link).unwrap();
        // A device is written in place: nothing is created beside it.
        write(Path::new("/dev/null"), b"x").unwrap();
        assert!(!std::fs::read_dir("/dev").unwrap().any(|e| e.unwrap().file_name().to_string_lossy().contains(".tmp")));
        // A directory that does not exist: the error names the target.
        let missing = d.join("no").join("x.csv");
        let e = write(&missing, b"x").unwrap_err();
        assert!(format!("{e:#}").starts_with(&format!("cannot write '{}': ", missing.display())), "{e:#}");
        std::fs::remove_dir_all(&d).unwrap();
    }
}
